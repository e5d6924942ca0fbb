"""Sensors of Mitsuba scene files: the ``<sensor>`` (perspective, thin lens or orthographic
camera, its field of view, a thin lens's aperture and focus) with its ``<film>`` (size, crop window), ``<rfilter>`` (pixel filter) and
``<sampler>`` (sample count and seed)."""

from __future__ import annotations

import math
import re
from typing import Dict

import torch

from ..scene import Camera
from .transforms import transform
from .xml import Node, Reader


def load_sensor(ctx: Reader, node: Node) -> Camera:
    kind = node.attrs.get("type")
    if kind not in ("perspective", "thinlens", "orthographic"):
        ctx.fail(node, f"unsupported sensor type '{kind}' (supported: perspective, thinlens, "
                       "orthographic)")
    props, nested = ctx.properties(node)
    width, height, rfilter, fparam, crop = 768, 576, "gaussian", 0.5, None
    for child in nested:
        if child.tag == "film":
            width, height, rfilter, fparam, crop = load_film(ctx, child)
        elif child.tag == "sampler":
            load_sampler(ctx, child)
        else:
            ctx.fail(child, "unexpected element inside <sensor> (supported: film, sampler)")
    to_world = transform(ctx, props.pop("to_world")) if "to_world" in props else \
        torch.eye(4, dtype=torch.float64)
    if float(torch.linalg.det(to_world[:3, :3])) <= 0:
        ctx.fail(node, "to_world mirrors the image (negative determinant, e.g. a negative "
                       "scale): not supported")
    if kind == "thinlens":
        lens = load_thin_lens(ctx, node, props)
    for name in ("near_clip", "far_clip"):  # edgepath clips nothing
        if name in props:
            ctx.float_value(props.pop(name))
    if kind == "perspective" and "focus_distance" in props:  # a pinhole: Mitsuba ignores it
        if not ctx.float_value(props.pop("focus_distance")) > 0:
            ctx.fail(node, "focus_distance must be > 0")
    filter_args = {"filter_radius": fparam} if rfilter == "tent" else {"filter_stddev": fparam}
    camera = Camera(to_world=to_world.to(torch.float32), resolution=(height, width),
                    camera_type=kind, pixel_filter=rfilter, crop_window=crop, **filter_args)
    if kind in ("perspective", "thinlens"):
        fov = field_of_view(ctx, node, props, width / height)
        camera.fov = torch.tensor(fov, dtype=torch.float32)
    if kind == "thinlens":
        camera.aperture_radius, camera.focus_distance = lens
    else:
        sx, sy = (float(to_world[:3, i].norm()) for i in (0, 1))
        if abs(sx - sy) > 1e-6 * max(sx, sy):
            ctx.fail(node, f"to_world scales x and y differently ({sx:g}, {sy:g}): not "
                           "supported for orthographic sensors")
        camera.ortho_scale = sx
    ctx.leftovers(node, props, "sensor")
    return camera


def load_thin_lens(ctx: Reader, node: Node, props: Dict[str, Node]):
    """(aperture_radius, focus_distance) of a ``thinlens`` sensor, as 0-d float32 tensors. As
    Mitsuba: the aperture radius is required; the focus distance defaults to ``far_clip``."""
    if "aperture_radius" not in props:
        ctx.fail(node, "thinlens: aperture_radius is required")
    radius = ctx.float_value(props.pop("aperture_radius"))
    if not 0 <= radius < math.inf:
        ctx.fail(node, f"aperture_radius {radius}: must be >= 0")
    far_clip = ctx.float_value(props["far_clip"]) if "far_clip" in props else 1e4
    focus = ctx.float_value(props.pop("focus_distance")) if "focus_distance" in props else far_clip
    if not 0 < focus < math.inf:
        ctx.fail(node, f"focus_distance {focus}: must be > 0")
    return (torch.tensor(radius, dtype=torch.float32), torch.tensor(focus, dtype=torch.float32))


def field_of_view(ctx: Reader, node: Node, props: Dict[str, Node], aspect: float) -> float:
    axis = ctx.string_value(props.pop("fov_axis")) if "fov_axis" in props else "x"
    if "fov" in props and "focal_length" in props:
        ctx.fail(node, "give fov or focal_length, not both")
    if "fov" in props:
        fov = ctx.float_value(props.pop("fov"))
    else:
        text = ctx.string_value(props.pop("focal_length")) if "focal_length" in props else "50mm"
        m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(mm)?\s*", text)
        if not m or float(m.group(1)) <= 0:
            ctx.fail(node, f"focal_length {text!r}: expected a length in mm, e.g. '50mm'")
        fov = math.degrees(2 * math.atan(math.hypot(36, 24) / (2 * float(m.group(1)))))
        axis = "diagonal"
    if not 0 < fov < 180:
        ctx.fail(node, f"fov {fov}: must be in (0, 180) degrees")
    t = math.tan(math.radians(fov) / 2)
    if axis == "smaller":
        axis = "x" if aspect <= 1 else "y"
    elif axis == "larger":
        axis = "x" if aspect >= 1 else "y"
    if axis == "y":
        t *= aspect
    elif axis == "diagonal":
        t *= aspect / math.sqrt(aspect * aspect + 1)
    elif axis != "x":
        ctx.fail(node, f"fov_axis '{axis}': expected x, y, diagonal, smaller or larger")
    return math.degrees(2 * math.atan(t))


def load_film(ctx: Reader, node: Node):
    if node.attrs.get("type") != "hdrfilm":
        ctx.fail(node, f"unsupported film type '{node.attrs.get('type')}' (supported: hdrfilm)")
    props, nested = ctx.properties(node)
    width = ctx.int_value(props.pop("width")) if "width" in props else 768
    height = ctx.int_value(props.pop("height")) if "height" in props else 576
    if width < 1 or height < 1:
        ctx.fail(node, f"film size {width}x{height}: must be positive")
    rfilter, fparam = "gaussian", 0.5
    for child in nested:
        if child.tag != "rfilter":
            ctx.fail(child, "unexpected element inside <film> (supported: rfilter)")
        rfilter, fparam = load_rfilter(ctx, child)
    crop = None
    keys = ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")
    if any(k in props for k in keys):
        x = ctx.int_value(props.pop(keys[0])) if keys[0] in props else 0
        y = ctx.int_value(props.pop(keys[1])) if keys[1] in props else 0
        w = ctx.int_value(props.pop(keys[2])) if keys[2] in props else width
        h = ctx.int_value(props.pop(keys[3])) if keys[3] in props else height
        if x < 0 or y < 0 or w < 1 or h < 1 or x + w > width or y + h > height:
            ctx.fail(node, f"crop window ({x}, {y}, {w}, {h}) outside the {width}x{height} film")
        crop = (x, y, w, h)
    for name in ("pixel_format", "component_format", "file_format"):  # output only
        if name in props:
            ctx.string_value(props.pop(name))
    if "sample_border" in props:
        ctx.bool_value(props.pop("sample_border"))
    ctx.leftovers(node, props, "film")
    return width, height, rfilter, fparam, crop


def load_rfilter(ctx: Reader, node: Node):
    """(type, parameter): the Gaussian's stddev, the tent's radius (box: 0.5)."""
    kind = node.attrs.get("type")
    props, nested = ctx.properties(node)
    if nested:
        ctx.fail(nested[0], "unexpected element inside <rfilter>")
    if kind == "box":
        if "radius" in props and abs(ctx.float_value(props.pop("radius")) - 0.5) > 1e-9:
            ctx.fail(node, "box filters of a radius other than 0.5 px are not supported")
        ctx.leftovers(node, props, "rfilter")
        return "box", 0.5
    if kind == "gaussian":
        stddev = ctx.float_value(props.pop("stddev")) if "stddev" in props else 0.5
        if not stddev > 0:
            ctx.fail(node, f"stddev {stddev}: must be > 0")
        ctx.leftovers(node, props, "rfilter")
        return "gaussian", stddev
    if kind == "tent":
        radius = ctx.float_value(props.pop("radius")) if "radius" in props else 1.0
        if not 0.5 <= radius < 100:
            ctx.fail(node, f"radius {radius}: must be in [0.5, 100) pixels")
        ctx.leftovers(node, props, "rfilter")
        return "tent", radius
    ctx.fail(node, f"unsupported rfilter type '{kind}' (supported: box, gaussian, tent)")


def load_sampler(ctx: Reader, node: Node) -> None:
    kind = node.attrs.get("type")
    if kind not in ("independent", "stratified", "multijitter", "orthogonal", "ldsampler"):
        ctx.fail(node, f"unsupported sampler type '{kind}'")
    props, nested = ctx.properties(node)
    if nested:
        ctx.fail(nested[0], "unexpected element inside <sampler>")
    if "sample_count" in props:
        ctx.result.spp = ctx.int_value(props.pop("sample_count"))
        if ctx.result.spp < 1:
            ctx.fail(node, f"sample_count {ctx.result.spp}: must be >= 1")
    if "seed" in props:
        ctx.result.seed = ctx.int_value(props.pop("seed"))
    if "jitter" in props:  # edgepath's own sample pattern
        ctx.bool_value(props.pop("jitter"))
    ctx.leftovers(node, props, "sampler")
