"""Emitters of Mitsuba scene files: area lights inside a ``<shape>``, the environment
(``constant`` or ``envmap``), ``directional`` suns and ``point`` lights at the top level."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Union

import torch

from ..io import _texture_rgb
from ..lights import sphere_light, sun
from ..scene import EnvironmentMap, Mesh
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
                   "directional, point)")


@dataclass
class Sun:
    """A ``directional`` emitter, until the scene's bounds are known."""
    sid: str
    direction: torch.Tensor  # towards the sun
    irradiance: torch.Tensor
    angular_diameter: float


@dataclass
class PointLight:
    """A ``point`` emitter, until the scene's bounds are known (for a default radius)."""
    sid: str
    position: torch.Tensor
    intensity: torch.Tensor
    radius: Optional[float]


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


def load_point(ctx: Reader, node: Node, index: int) -> PointLight:
    """Mitsuba's ``point`` (``intensity``, default 1; ``position`` or the translation of a
    ``to_world``) with edgepath's ``radius`` (default ``POINT_RADIUS`` times the scene's)."""
    props, position, intensity = _placed_emitter(ctx, node, "position", 3, "intensity")
    radius = ctx.float_value(props.pop("radius")) if "radius" in props else None
    if radius is not None and not 0 < radius < math.inf:
        ctx.fail(node, f"radius {radius}: must be positive (edgepath has no point lights of "
                       "radius 0)")
    ctx.leftovers(node, props, "emitter")
    return PointLight(node.attrs.get("id", f"point_{index}"), position, intensity, radius)


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


def place_lights(ctx: Reader, lights: List[Union[Sun, PointLight]], meshes: List[Mesh]) -> List[Mesh]:
    """The meshes of suns and point lights, placed and sized for the bounds of ``meshes``."""
    if not lights:
        return []
    points = torch.cat([m.vertices.detach().reshape(-1, 3).double() for m in meshes])
    lo, hi = points.min(0).values, points.max(0).values
    center, radius = (lo + hi) / 2, max(float((hi - lo).norm()) / 2, 1e-6)
    out = []
    for s in lights:
        if isinstance(s, Sun):
            mesh = sun(s.direction, s.irradiance, s.angular_diameter, center=center.tolist(),
                       scene_radius=radius)
        else:
            mesh = sphere_light(s.position, s.intensity,
                                s.radius if s.radius is not None else POINT_RADIUS * radius)
        ctx.result.shapes[s.sid] = mesh
        ctx.result.shape_ids.append(s.sid)
        out.append(mesh)
    return out
