"""Procedural meshes: tensors for ``edgepath.Mesh``.

Each function returns ``(vertices, indices, uvs, normals)`` (float32 / int32 tensors; uvs and
normals indexed like the vertices), counter-clockwise seen from the side the normals point to.
"""

from __future__ import annotations

import math
from typing import Sequence, Tuple

import torch

MeshTensors = Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]


def sphere(center: Sequence[float] = (0.0, 0.0, 0.0), radius: float = 1.0, rings: int = 32,
           segments: int = 64) -> MeshTensors:
    """A latitude-longitude sphere with outward smooth normals; uv = (longitude, latitude)
    in [0, 1] with a seam (duplicated vertices) at longitude 0."""
    if rings < 2 or segments < 3:
        raise ValueError(f"sphere: needs rings >= 2 and segments >= 3, got {rings}, {segments}")
    theta = torch.linspace(0, math.pi, rings + 1, dtype=torch.float64)
    phi = torch.linspace(0, 2 * math.pi, segments + 1, dtype=torch.float64)
    # The seam's two columns and each pole's copies must be the same positions exactly (the
    # edges are found by welding equal positions): sin(pi) and sin(2 pi) are not zero in floating
    # point, so they are set.
    sin_t, cos_t = torch.sin(theta), torch.cos(theta)
    sin_t[0] = sin_t[-1] = 0.0
    cos_t[0], cos_t[-1] = 1.0, -1.0
    sin_p, cos_p = torch.sin(phi), torch.cos(phi)
    sin_p[-1], cos_p[-1] = sin_p[0], cos_p[0]
    t, p = torch.meshgrid(theta, phi, indexing="ij")
    st, ct = sin_t[:, None], cos_t[:, None]
    sp, cp = sin_p[None, :], cos_p[None, :]
    n = torch.stack([st * sp, ct.expand_as(t), st * cp], -1)
    n = n.reshape(-1, 3)
    vertices = torch.tensor(center, dtype=torch.float64) + radius * n
    uvs = torch.stack([p / (2 * math.pi), t / math.pi], -1).reshape(-1, 2)
    idx = []
    w = segments + 1
    for r in range(rings):
        for s in range(segments):
            a, b = r * w + s, r * w + s + 1
            c, d = a + w, b + w
            if r > 0:
                idx.append([a, c, b])
            if r < rings - 1:
                idx.append([b, c, d])
    return (vertices.float(), torch.tensor(idx, dtype=torch.int32), uvs.float(), n.float())


def grid(size: Tuple[float, float] = (2.0, 2.0), resolution: Tuple[int, int] = (1, 1),
         center: Sequence[float] = (0.0, 0.0, 0.0)) -> MeshTensors:
    """A rectangle in the plane y = center.y facing +y, ``size`` (x, z), split into
    ``resolution`` (x, z) quads of two triangles; uv = (x, z) across it in [0, 1]."""
    nx, nz = resolution
    if nx < 1 or nz < 1:
        raise ValueError(f"grid: resolution must be >= 1, got {resolution}")
    u = torch.linspace(0, 1, nx + 1, dtype=torch.float64)
    v = torch.linspace(0, 1, nz + 1, dtype=torch.float64)
    uu, vv = torch.meshgrid(u, v, indexing="xy")  # rows: z, columns: x
    x = center[0] + (uu - 0.5) * size[0]
    z = center[2] + (vv - 0.5) * size[1]
    vertices = torch.stack([x, torch.full_like(x, center[1]), z], -1).reshape(-1, 3)
    uvs = torch.stack([uu, vv], -1).reshape(-1, 2)
    idx = []
    w = nx + 1
    for j in range(nz):
        for i in range(nx):
            a = j * w + i
            b, c, d = a + 1, a + w, a + w + 1
            idx += [[a, c, d], [a, d, b]]
    normals = torch.tensor([[0.0, 1.0, 0.0]]).expand(vertices.shape[0], 3).contiguous()
    return vertices.float(), torch.tensor(idx, dtype=torch.int32), uvs.float(), normals


def quad(corners: Sequence[Sequence[float]]) -> Tuple[torch.Tensor, torch.Tensor]:
    """Vertices and indices of a quad given by 4 corners in order; the face normal follows
    the right-hand rule around them."""
    return (torch.tensor(corners, dtype=torch.float32),
            torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32))


def box(center: Sequence[float] = (0.0, 0.0, 0.0),
        half: Sequence[float] = (0.5, 0.5, 0.5)) -> Tuple[torch.Tensor, torch.Tensor]:
    """A box with half-extents ``half`` about ``center``: 8 corners (corner ``4 ix + 2 iy + iz``
    at ``center + (±hx, ±hy, ±hz)``, minus first) and 12 outward-facing triangles, flat (no uvs
    or normals). Returns ``(vertices, indices)``."""
    vertices = torch.tensor([[c + s * h for c, s, h in zip(center, signs, half)]
                             for signs in [(sx, sy, sz) for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)
                                           for sz in (-1.0, 1.0)]])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    indices = [tri for a, b, c, d in faces for tri in ([a, b, c], [a, c, d])]
    return vertices, torch.tensor(indices, dtype=torch.int32)
