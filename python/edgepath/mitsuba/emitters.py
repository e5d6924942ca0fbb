"""Emitters of Mitsuba scene files: area lights inside a ``<shape>``, the environment
(``constant`` or ``envmap``), ``directional`` suns, ``point`` and ``spot`` lights at the top
level."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple, Union

import torch

from ..io import _texture_rgb
from ..lights import point_light, sphere_light, spot_light, sun
from ..scene import EnvironmentMap, Mesh, PointLight as DeltaLight
from .textures import colour
from .transforms import transform
from .xml import Node, Reader


def load_area(ctx: Reader, node: Node) -> torch.Tensor:
    if node.attrs.get("type") != "area":
        ctx.fail(node, f"unsupported emitter type '{node.attrs.get('type')}' inside a shape "
                       "(supported: area)")
    props, nested = ctx.properties(node)
    if "radiance" not in props:
        ctx.fail(node, "missing radiance")
    radiance = colour(ctx, props.pop("radiance"))
    for child in nested:
        if child.attrs.get("name") != "radiance":
            ctx.fail(child, "unexpected element inside <emitter>")
    ctx.leftovers(node, props, "emitter")
    return radiance


def load_environment(ctx: Reader, node: Node) -> EnvironmentMap:
    kind = node.attrs.get("type")
    props, nested = ctx.properties(node)
    for child in nested:
        if child.attrs.get("name") != "radiance":
            ctx.fail(child, "unexpected element inside <emitter>")
    if kind == "constant":
        radiance = colour(ctx, props.pop("radiance")) if "radiance" in props else \
            torch.ones(3)
        if radiance.dim() != 1:
            ctx.fail(node, "a constant emitter's radiance must be a constant, not a texture")
        ctx.leftovers(node, props, "emitter")
        return EnvironmentMap(values=radiance.reshape(1, 1, 3).contiguous())
    if kind == "envmap":
        if "filename" not in props:
            ctx.fail(node, "missing <string name=\"filename\">")
        filename = ctx.file(props["filename"], ctx.string_value(props.pop("filename")))
        scale = ctx.float_value(props.pop("scale")) if "scale" in props else 1.0
        to_world = None
        if "to_world" in props:
            m = transform(ctx, props.pop("to_world"))
            r = m[:3, :3]
            if not torch.allclose(r.T @ r, torch.eye(3, dtype=torch.float64), atol=1e-6) \
                    or float(torch.linalg.det(r)) < 0:
                ctx.fail(node, "an envmap's to_world must be a rotation")
            to_world = m.to(torch.float32)
        ctx.leftovers(node, props, "emitter")
        return EnvironmentMap(values=_texture_rgb(filename), to_world=to_world, scale=scale)
    if kind == "area":
        ctx.fail(node, "area emitters belong inside a <shape>")
    ctx.fail(node, f"unsupported emitter type '{kind}' (supported: area, constant, envmap, "
                   "directional, point, spot)")


@dataclass
class Sun:
    """A ``directional`` emitter, until the scene's bounds are known."""
    sid: str
    direction: torch.Tensor  # towards the sun
    irradiance: torch.Tensor
    angular_diameter: float


@dataclass
class PointLight:
    """A ``point`` or ``spot`` emitter, until the scene's bounds are known (for a default
    radius). ``spot``: (direction, cutoff_angle, beam_width) of a spot, else None."""
    sid: str
    position: torch.Tensor
    intensity: torch.Tensor
    radius: Optional[float]
    spot: Optional[tuple] = None


def _placed_emitter(ctx: Reader, node: Node, vector: str, column: int, power: str):
    """(the other properties, the vector property ``vector`` or column ``column`` of a
    ``to_world`` (default: +z, or the origin for column 3), the constant colour ``power``
    (default 1)) of a point or directional emitter."""
    props, nested = ctx.properties(node)
    for child in nested:
        if child.attrs.get("name") != power:
            ctx.fail(child, "unexpected element inside <emitter>")
    if vector in props and "to_world" in props:
        ctx.fail(node, f"give {vector} or to_world, not both")
    value = torch.tensor([0.0, 0.0, 0.0 if column == 3 else 1.0], dtype=torch.float64)
    if vector in props:
        value = torch.tensor(ctx.vector_value(props.pop(vector)), dtype=torch.float64)
    elif "to_world" in props:
        value = transform(ctx, props.pop("to_world"))[:3, column]
    colour_value = colour(ctx, props.pop(power)) if power in props else torch.ones(3)
    if colour_value.dim() != 1 or bool((colour_value < 0).any()):
        ctx.fail(node, f"a {node.attrs.get('type')} emitter's {power} must be a constant >= 0")
    return props, value, colour_value


# A point light's radius where the file gives none, in units of the scene's radius.
POINT_RADIUS = 1e-3


def _radius(ctx: Reader, node: Node, props) -> Optional[float]:
    radius = ctx.float_value(props.pop("radius")) if "radius" in props else None
    if radius is not None and not 0 <= radius < math.inf:
        ctx.fail(node, f"radius {radius}: must be finite and >= 0")
    return radius


def load_point(ctx: Reader, node: Node, index: int) -> PointLight:
    """Mitsuba's ``point`` (``intensity``, default 1; ``position`` or the translation of a
    ``to_world``) with edgepath's ``radius`` (default ``POINT_RADIUS`` times the scene's; 0: a
    delta light)."""
    props, position, intensity = _placed_emitter(ctx, node, "position", 3, "intensity")
    radius = _radius(ctx, node, props)
    ctx.leftovers(node, props, "emitter")
    return PointLight(node.attrs.get("id", f"point_{index}"), position, intensity, radius)


def load_spot(ctx: Reader, node: Node, index: int) -> PointLight:
    """Mitsuba's ``spot`` (``intensity``, default 1; ``cutoff_angle``, default 20 degrees;
    ``beam_width``, default three quarters of it; at the origin shining along +z, placed by
    ``to_world``) with edgepath's ``radius`` (as ``point``'s)."""
    props, nested = ctx.properties(node)
    if "position" in props:
        ctx.fail(node, "a spot is placed by to_world (a position is not a spot's property)")
    m = transform(ctx, props.pop("to_world")) if "to_world" in props else \
        torch.eye(4, dtype=torch.float64)
    for child in nested:
        if child.attrs.get("name") != "intensity":
            ctx.fail(child, "unexpected element inside <emitter>")
    intensity = colour(ctx, props.pop("intensity")) if "intensity" in props else torch.ones(3)
    if intensity.dim() != 1 or bool((intensity < 0).any()):
        ctx.fail(node, "a spot emitter's intensity must be a constant >= 0")
    cutoff = ctx.float_value(props.pop("cutoff_angle")) if "cutoff_angle" in props else 20.0
    beam = ctx.float_value(props.pop("beam_width")) if "beam_width" in props else cutoff * 0.75
    if not 0 < cutoff <= 180:
        ctx.fail(node, f"cutoff_angle {cutoff}: must be in (0, 180] degrees")
    if not 0 <= beam < cutoff:
        ctx.fail(node, f"beam_width {beam}: must be in [0, cutoff_angle) degrees")
    direction = m[:3, 2]
    if not bool(torch.isfinite(direction).all()) or float(direction.norm()) == 0:
        ctx.fail(node, "to_world has a zero z axis (the spot's direction)")
    radius = _radius(ctx, node, props)
    ctx.leftovers(node, props, "emitter")
    return PointLight(node.attrs.get("id", f"spot_{index}"), m[:3, 3].clone(), intensity, radius,
                      (direction.clone(), torch.tensor(cutoff, dtype=torch.float64),
                       torch.tensor(beam, dtype=torch.float64)))


def load_directional(ctx: Reader, node: Node, index: int) -> Sun:
    """Mitsuba's ``directional`` (``irradiance``, default 1; ``direction`` of travel or a
    ``to_world`` whose z axis it is, default +z) with edgepath's ``angular_diameter`` (degrees,
    default 0.5): edgepath has no delta lights."""
    props, travel, irradiance = _placed_emitter(ctx, node, "direction", 2, "irradiance")
    if not bool(torch.isfinite(travel).all()) or float(travel.norm()) == 0:
        ctx.fail(node, "the direction is zero")
    diameter = ctx.float_value(props.pop("angular_diameter")) if "angular_diameter" in props \
        else 0.5
    if not 0 < diameter < 90:
        ctx.fail(node, f"angular_diameter {diameter}: must be in (0, 90) degrees")
    ctx.leftovers(node, props, "emitter")
    sid = node.attrs.get("id", f"sun_{index}")
    return Sun(sid, -travel / travel.norm(), irradiance, diameter)


def place_lights(ctx: Reader, lights: List[Union[Sun, PointLight]],
                 meshes: List[Mesh]) -> Tuple[List[Mesh], List[DeltaLight]]:
    """The meshes of suns and of point and spot lights with a radius, placed and sized for the
    bounds of ``meshes``; and the delta lights (radius 0)."""
    if not lights:
        return [], []
    points = torch.cat([m.vertices.detach().reshape(-1, 3).double() for m in meshes])
    lo, hi = points.min(0).values, points.max(0).values
    center, radius = (lo + hi) / 2, max(float((hi - lo).norm()) / 2, 1e-6)
    out, deltas = [], []
    for s in lights:
        if isinstance(s, Sun):
            mesh = sun(s.direction, s.irradiance, s.angular_diameter, center=center.tolist(),
                       scene_radius=radius)
        else:
            r = s.radius if s.radius is not None else POINT_RADIUS * radius
            if s.spot is None:
                mesh = point_light(s.position, s.intensity, r)
            else:
                direction, cutoff, beam = s.spot
                mesh = spot_light(s.position, direction, s.intensity, cutoff, beam, r)
            if isinstance(mesh, DeltaLight):
                ctx.result.point_lights[s.sid] = mesh
                deltas.append(mesh)
                continue
        ctx.result.shapes[s.sid] = mesh
        ctx.result.shape_ids.append(s.sid)
        out.append(mesh)
    return out, deltas
