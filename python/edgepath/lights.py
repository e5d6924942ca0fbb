"""Lights built from emissive meshes, so that they take part in everything area lights do
(next-event estimation, multiple importance sampling, the boundary terms of their shadows and
of their own outline).

``sun``: a directional light with an angular diameter, as a distant emitting disk.
``sphere_light``: a point light with a radius, as a small emitting sphere.
``point_light`` and ``spot_light``: a light at a point (radius 0: a ``PointLight``, for the
scene's ``point_lights``) or, with a radius, a small sphere (a ``Mesh``, for its ``meshes``)."""

from __future__ import annotations

import math
from typing import Sequence, Union

import torch

from .scene import Material, Mesh, PointLight, Spot

Number = Union[float, torch.Tensor]

# How far the sun's disk lies from the scene, in units of the scene's radius. Its direction
# seen from two points of the scene differs by at most 1 / SUN_DISTANCE radians (1e-4: 2% of
# the radius of a 0.5 degree sun); float32 vertices there still place the disk's outline to
# about 1e-6 of its radius.
SUN_DISTANCE = 1e4
SUN_SEGMENTS = 32


def sun(direction: Sequence[float] | torch.Tensor, irradiance: Number | Sequence[float] = 1.0,
        angular_diameter: Number = 0.5, center: Sequence[float] = (0.0, 0.0, 0.0),
        scene_radius: float = 1.0, segments: int = SUN_SEGMENTS) -> Mesh:
    """A sun: a disk of angular diameter ``angular_diameter`` (degrees) in ``direction`` (towards
    the sun, any length), seen from ``center`` at ``SUN_DISTANCE * scene_radius``, emitting
    towards the scene a constant radiance such that a surface facing the sun receives
    ``irradiance`` (a number or 3 values; Mitsuba's ``directional`` has the same parameter).
    ``center`` and ``scene_radius`` should bound the scene. The disk is a polygon of
    ``segments`` sides.

    ``direction``, ``irradiance`` and ``angular_diameter`` may be tensors with
    ``requires_grad``: the returned mesh's vertices and emission are computed from them, so
    gradients reach them, including the boundary terms of the shadows the sun casts (its
    outline's edges, seen from a shading point, are sampled like any area light's)."""
    if segments < 3:
        raise ValueError(f"sun: segments must be at least 3, got {segments}")
    if not scene_radius > 0 or not math.isfinite(scene_radius):
        raise ValueError(f"sun: scene_radius must be positive, got {scene_radius}")
    d = torch.as_tensor(direction, dtype=torch.float64)
    diameter = torch.as_tensor(angular_diameter, dtype=torch.float64)
    e = torch.as_tensor(irradiance, dtype=torch.float64).reshape(-1)
    dd, de = d.detach(), e.detach()
    if d.shape != (3,) or not bool(torch.isfinite(dd).all()) or float(dd.norm()) == 0:
        raise ValueError(f"sun: direction must be 3 finite numbers, not all zero, got "
                         f"{direction!r}")
    if diameter.numel() != 1 or not 0 < float(diameter.detach()) < 90:
        raise ValueError(f"sun: angular_diameter must be in (0, 90) degrees, got "
                         f"{angular_diameter!r}")
    if e.numel() not in (1, 3) or not bool(torch.isfinite(de).all()) or bool((de < 0).any()):
        raise ValueError(f"sun: irradiance must be 1 or 3 finite numbers >= 0, got "
                         f"{irradiance!r}")
    d = d / d.norm()
    # A frame (u, v, -d): the fan's triangles face the scene.
    helper = torch.tensor([1.0, 0, 0] if abs(float(dd[1] / dd.norm())) > 0.9 else [0, 1.0, 0],
                          dtype=torch.float64)
    u = torch.linalg.cross(helper, d)
    u = u / u.norm()
    v = torch.linalg.cross(d, u)
    distance = SUN_DISTANCE * scene_radius
    half = torch.deg2rad(diameter.reshape(())) / 2
    radius = distance * torch.tan(half)
    phi = torch.arange(segments, dtype=torch.float64) * (2 * math.pi / segments)
    centre = torch.as_tensor(center, dtype=torch.float64) + distance * d
    rim = centre + radius * (torch.cos(phi)[:, None] * u + torch.sin(phi)[:, None] * v)
    vertices = torch.cat([centre[None], rim])
    k = torch.arange(segments, dtype=torch.int32)
    indices = torch.stack([torch.zeros_like(k), 1 + (k + 1) % segments, 1 + k], -1)
    # The polygon's solid angle from the centre (its area over the distance squared, to within
    # the square of its angular radius): radiance times it is the irradiance.
    solid_angle = 0.5 * segments * math.sin(2 * math.pi / segments) * (radius / distance) ** 2
    radiance = (e / solid_angle).expand(3)
    return Mesh(vertices=vertices.float(), indices=indices, emission=radiance.float(),
                material=Material(diffuse=0.0, specular=0.0))


def _icosphere(subdivisions: int):
    """A geodesic unit sphere: an icosahedron whose faces are split in four ``subdivisions``
    times, vertices pushed onto the sphere (faces of nearly equal size and shape; outward
    counter-clockwise winding). Float64 vertices, int32 indices."""
    g = (1 + math.sqrt(5)) / 2
    v = [(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g),
         (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    vertices = [tuple(c / math.sqrt(1 + g * g) for c in p) for p in v]
    for _ in range(subdivisions):
        middle = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in middle:
                p = [(x + y) / 2 for x, y in zip(vertices[a], vertices[b])]
                n = math.sqrt(sum(c * c for c in p))
                vertices.append(tuple(c / n for c in p))
                middle[key] = len(vertices) - 1
            return middle[key]
        split = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            split += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = split
    return (torch.tensor(vertices, dtype=torch.float64), torch.tensor(faces, dtype=torch.int32))


def sphere_light(position: Sequence[float] | torch.Tensor, intensity: Number | Sequence[float] = 1.0,
                 radius: Number = 0.01, subdivisions: int = 1, spot: Spot | None = None) -> Mesh:
    """A point light with a radius: a sphere of ``radius`` around ``position`` (a geodesic
    sphere, an icosahedron split ``subdivisions`` times: 80 faces by default) emitting a
    constant radiance outwards, such that its radiant intensity (W/sr, a number or 3 values;
    Mitsuba's ``point`` has the same parameter) averaged over directions is ``intensity``: seen
    from outside, as a point light of that intensity, within the polyhedron's departure from a
    sphere (its projected area varies with the direction by a few percent). ``radius`` must be
    positive: ``point_light`` with radius 0 gives a delta light, whose shadows have no
    boundary terms (as in Mitsuba). The tessellation is coarse on purpose: the derivative of the
    light's position comes from its outline's edges seen from the lit surfaces, and today's side
    rays bias it more the finer the outline (docs/gradients.md).

    Light samples find it by solid angle (``light_sampling="solid_angle"``): uniformly in the
    cone of directions it subtends, so that they land on the side it shows.

    ``position``, ``intensity`` and ``radius`` may be tensors with ``requires_grad``; as for
    ``sun``, gradients reach them, and its shadows have boundary terms. ``spot``: a ``Spot``
    profile scaling the radiance by the direction it leaves in (see ``spot_light``)."""
    p = torch.as_tensor(position, dtype=torch.float64)
    r = torch.as_tensor(radius, dtype=torch.float64)
    i = torch.as_tensor(intensity, dtype=torch.float64).reshape(-1)
    if p.shape != (3,) or not bool(torch.isfinite(p.detach()).all()):
        raise ValueError(f"sphere_light: position must be 3 finite numbers, got {position!r}")
    if r.numel() != 1 or not 0 < float(r.detach()) < math.inf:
        raise ValueError(f"sphere_light: radius must be positive and finite, got {radius!r}")
    if i.numel() not in (1, 3) or not bool(torch.isfinite(i.detach()).all()) or \
            bool((i.detach() < 0).any()):
        raise ValueError(f"sphere_light: intensity must be 1 or 3 finite numbers >= 0, got "
                         f"{intensity!r}")
    if not 0 <= subdivisions <= 4:
        raise ValueError(f"sphere_light: subdivisions must be in 0..4, got {subdivisions}")
    unit, indices = _icosphere(subdivisions)
    vertices = p + r.reshape(()) * unit
    # Mean projected area of a convex body: a quarter of its surface area (Cauchy).
    t = unit[indices.long()]
    area = float(torch.linalg.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]).norm(dim=-1).sum()) / 2
    radiance = (i / (area / 4 * r.reshape(()) ** 2)).expand(3)
    return Mesh(vertices=vertices.float(), indices=indices, emission=radiance.float(),
                material=Material(diffuse=0.0, specular=0.0), spot=spot,
                light_sampling="solid_angle")


def _is_zero(radius: Number, name: str) -> bool:
    r = torch.as_tensor(radius, dtype=torch.float64)
    if r.numel() != 1 or not 0 <= float(r.detach()) < math.inf:
        raise ValueError(f"{name}: radius must be a finite number >= 0, got {radius!r}")
    return float(r.detach()) == 0


def point_light(position: Sequence[float] | torch.Tensor, intensity: Number | Sequence[float] = 1.0,
                radius: Number = 0.0, subdivisions: int = 1) -> PointLight | Mesh:
    """Mitsuba's ``point``: radiant ``intensity`` (W/sr, a number or 3 values) from ``position``.
    With ``radius`` 0, a ``PointLight`` (for ``Scene(point_lights=...)``): a delta light, whose
    shadows have no boundary terms (as in Mitsuba); with a radius, ``sphere_light`` (a ``Mesh``
    for ``Scene(meshes=...)``), whose shadows do. Tensors with ``requires_grad`` get gradients."""
    if _is_zero(radius, "point_light"):
        return PointLight(position=_vector(position, "point_light: position"),
                          intensity=_intensity(intensity, "point_light"))
    return sphere_light(position, intensity, radius, subdivisions)


def spot_light(position: Sequence[float] | torch.Tensor, direction: Sequence[float] | torch.Tensor,
               intensity: Number | Sequence[float] = 1.0, cutoff_angle: Number = 20.0,
               beam_width: Number | None = None, radius: Number = 0.0,
               subdivisions: int = 1) -> PointLight | Mesh:
    """Mitsuba's ``spot``: radiant ``intensity`` (W/sr, a number or 3 values) from ``position``
    along ``direction`` (any length), full within ``beam_width`` degrees of it (default: three
    quarters of ``cutoff_angle``), none beyond ``cutoff_angle`` degrees, falling linearly with
    the angle between (``Spot``). With ``radius`` 0, a ``PointLight`` (for
    ``Scene(point_lights=...)``): a delta light, whose shadows have no boundary terms (as in
    Mitsuba). With a radius, a small emitting sphere (``sphere_light``, a ``Mesh`` for
    ``Scene(meshes=...)``) whose radiance has the profile in the direction it leaves in: seen
    from afar, the same light; its shadows are soft and have boundary terms. Every value may be
    a tensor with ``requires_grad``."""
    spot = Spot(direction=_vector(direction, "spot_light: direction"), cutoff_angle=cutoff_angle,
                beam_width=beam_width)
    if _is_zero(radius, "spot_light"):
        return PointLight(position=_vector(position, "spot_light: position"),
                          intensity=_intensity(intensity, "spot_light"), spot=spot)
    return sphere_light(position, intensity, radius, subdivisions, spot=spot)


def _vector(value, name: str) -> torch.Tensor:
    t = value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float32)
    if t.shape != (3,) or not bool(torch.isfinite(t.detach()).all()):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return t


def _intensity(value, name: str):
    """``value`` checked (1 or 3 numbers >= 0) and returned as given: a tensor stays the one the
    light holds, to optimise."""
    t = torch.as_tensor(value).detach().reshape(-1).double()
    if t.numel() not in (1, 3) or not bool(torch.isfinite(t).all()) or bool((t < 0).any()):
        raise ValueError(f"{name}: intensity must be 1 or 3 finite numbers >= 0, got {value!r}")
    return value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float32)
