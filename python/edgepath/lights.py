"""Lights built from emissive meshes, so that they take part in everything area lights do
(next-event estimation, multiple importance sampling, the boundary terms of their shadows and
of their own outline).

``sun``: a directional light with an angular diameter, as a distant emitting disk."""

from __future__ import annotations

import math
from typing import Sequence, Union

import torch

from .scene import Material, Mesh

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
