"""Shapes of Mitsuba scene files: OBJ and PLY meshes, and the analytic shapes (rectangle,
cube, sphere, disk) tessellated; each with its transform, BSDF and area emitter."""

from __future__ import annotations

import math
from typing import List

import torch

from ..io import load_obj, load_ply
from ..scene import Material, Mesh
from .emitters import load_area
from .materials import load_bsdf
from .transforms import transform
from .xml import Node, Reader

SPHERE_RINGS = 64        # tessellation of analytic spheres: rings (pole to pole) ...
SPHERE_SEGMENTS = 128    # ... and segments around the z axis
DISK_SEGMENTS = 128      # triangles of an analytic disk


def load_shape(ctx: Reader, node: Node, index: int) -> Mesh:
    kind = node.attrs.get("type")
    if kind not in ("obj", "ply", "rectangle", "cube", "sphere", "disk"):
        ctx.fail(node, f"unsupported shape type '{kind}' (supported: obj, ply, rectangle, "
                       "cube, sphere, disk)")
    sid = node.attrs.get("id", f"shape_{index}")
    if sid in ctx.result.shapes:
        ctx.fail(node, f"shape id '{sid}' used twice")
    props, nested = ctx.properties(node)
    for name, p in list(props.items()):
        if p.tag in ("ref", "bsdf", "emitter"):
            props.pop(name)
            if p not in nested:
                nested.append(p)
    material, emission = None, None
    for child in nested:
        target = ctx.deref(child, ("bsdf", "emitter"))
        if target.tag == "bsdf":
            if material is not None:
                ctx.fail(child, "a shape takes one BSDF")
            material = load_bsdf(ctx, target)
        elif target.tag == "emitter":
            if emission is not None:
                ctx.fail(child, "a shape takes one emitter")
            emission = load_area(ctx, target)
        else:
            ctx.fail(child, "unexpected element inside <shape> (supported: bsdf, emitter, ref)")
    to_world = transform(ctx, props.pop("to_world")) if "to_world" in props else \
        torch.eye(4, dtype=torch.float64)
    flip = ctx.bool_value(props.pop("flip_normals")) if "flip_normals" in props else False

    normals = None
    smooth = False
    if kind in ("obj", "ply"):
        if "filename" not in props:
            ctx.fail(node, "missing <string name=\"filename\">")
        filename = ctx.file(props["filename"], ctx.string_value(props.pop("filename")))
        face_normals = ctx.bool_value(props.pop("face_normals")) \
            if "face_normals" in props else False
        flip_uv = True
        if kind == "obj" and "flip_tex_coords" in props:
            flip_uv = ctx.bool_value(props.pop("flip_tex_coords"))
        try:
            mesh = _merge(load_obj(filename)) if kind == "obj" else load_ply(filename)
        except (ValueError, OSError) as error:
            ctx.fail(node, str(error))
        vertices = mesh.vertices.to(torch.float64)
        indices, uvs, uv_indices = mesh.indices, mesh.uvs, mesh.uv_indices
        if uvs is not None and not flip_uv:
            uvs = torch.stack([uvs[:, 0], 1 - uvs[:, 1]], 1)
        normal_indices = None
        if not face_normals:
            smooth = True
            if mesh.normals is not None:
                normals = mesh.normals.to(torch.float64)
                normal_indices = mesh.normal_indices
    else:
        if kind == "sphere":
            center = ctx.vector_value(props.pop("center")) if "center" in props else [0, 0, 0]
            radius = ctx.float_value(props.pop("radius")) if "radius" in props else 1.0
            if not radius > 0:
                ctx.fail(node, f"radius {radius}: must be > 0")
            local = torch.eye(4, dtype=torch.float64)
            local[:3, :3] *= radius
            local[:3, 3] = torch.tensor(center, dtype=torch.float64)
            to_world = to_world @ local
            vertices, indices, uvs, normals = _sphere()
            smooth = True
        else:
            vertices, indices, uvs = {"rectangle": _rectangle, "cube": _cube,
                                      "disk": _disk}[kind]()
        uv_indices = normal_indices = None
    ctx.leftovers(node, props, "shape")

    vertices = vertices @ to_world[:3, :3].T + to_world[:3, 3]
    if normals is not None:
        inverse, singular = torch.linalg.inv_ex(to_world[:3, :3])
        if singular:
            ctx.fail(node, "to_world is singular (a zero scale?): the normals have no transform")
        normals = normals @ inverse
        normals = normals / normals.norm(dim=1, keepdim=True)
    elif smooth:
        normals = _vertex_normals(vertices, indices)
    if flip:
        indices = indices[:, [0, 2, 1]].contiguous()
        if uv_indices is not None:
            uv_indices = uv_indices[:, [0, 2, 1]].contiguous()
        if normal_indices is not None:
            normal_indices = normal_indices[:, [0, 2, 1]].contiguous()
        if normals is not None:
            normals = -normals
    if material is None:
        material = Material(diffuse=torch.full((3,), 0.0 if emission is not None else 0.5))
    mesh = Mesh(vertices=vertices.to(torch.float32), indices=indices, uvs=uvs,
                normals=None if normals is None else normals.to(torch.float32),
                uv_indices=uv_indices, normal_indices=normal_indices, material=material,
                emission=emission)
    ctx.result.shapes[sid] = mesh
    ctx.result.shape_ids.append(sid)
    return mesh


def _rectangle():
    """[-1, 1]^2 in z = 0, face normal +z, uv = ((x + 1) / 2, (y + 1) / 2)."""
    v = torch.tensor([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
                     dtype=torch.float64)
    f = torch.tensor([[0, 1, 3], [0, 3, 2]], dtype=torch.int32)
    return v, f, ((v[:, :2] + 1.0) * 0.5).to(torch.float32)


def _cube():
    """[-1, 1]^3, outward faces of 4 vertices each, uv over each face."""
    vertices, uvs, faces = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = [0.0, 0.0, 0.0]
            normal[axis] = sign
            # two tangents (u, v) with cross(u, v) = normal
            u = [0.0, 0.0, 0.0]
            u[(axis + 1) % 3] = 1.0
            v = [0.0, 0.0, 0.0]
            v[(axis + 2) % 3] = sign
            base = len(vertices)
            for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                vertices.append([normal[i] + s * u[i] + t * v[i] for i in range(3)])
                uvs.append([(s + 1) / 2, (t + 1) / 2])
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return (torch.tensor(vertices, dtype=torch.float64), torch.tensor(faces, dtype=torch.int32),
            torch.tensor(uvs, dtype=torch.float32))


def _disk():
    """The unit disk in z = 0 facing +z, a fan of DISK_SEGMENTS triangles; uv = (r, phi / 2 pi)
    with r in {0, 1} (a seam at phi = 0)."""
    n = DISK_SEGMENTS
    phi = torch.arange(n + 1, dtype=torch.float64) * (2 * math.pi / n)
    rim = torch.stack([torch.cos(phi), torch.sin(phi), torch.zeros_like(phi)], 1)
    vertices = torch.cat([torch.zeros(n, 3, dtype=torch.float64), rim])  # a centre per wedge
    uvs = torch.cat([torch.stack([torch.zeros(n), (torch.arange(n) + 0.5) / n], 1),
                     torch.stack([torch.ones(n + 1), torch.arange(n + 1) / n], 1)])
    i = torch.arange(n)
    faces = torch.stack([i, n + i, n + i + 1], 1).to(torch.int32)
    return vertices, faces, uvs.to(torch.float32)


def _sphere():
    """The unit sphere with Mitsuba's parametrisation: p = (sin t cos p, sin t sin p, cos t),
    uv = (p / 2 pi, t / pi); outward smooth normals."""
    rings, segments = SPHERE_RINGS, SPHERE_SEGMENTS
    theta = torch.linspace(0, math.pi, rings + 1, dtype=torch.float64)
    phi = torch.linspace(0, 2 * math.pi, segments + 1, dtype=torch.float64)
    t, p = torch.meshgrid(theta, phi, indexing="ij")
    n = torch.stack([torch.sin(t) * torch.cos(p), torch.sin(t) * torch.sin(p), torch.cos(t)], -1)
    n = n.reshape(-1, 3)
    uvs = torch.stack([p / (2 * math.pi), t / math.pi], -1).reshape(-1, 2).to(torch.float32)
    w = segments + 1
    r, s = torch.meshgrid(torch.arange(rings), torch.arange(segments), indexing="ij")
    a, b = r * w + s, r * w + s + 1
    c, d = a + w, b + w
    # counter-clockwise seen from outside; skip the triangles that degenerate at the poles
    upper = torch.stack([a, d, b], -1)[1:].reshape(-1, 3)
    lower = torch.stack([a, c, d], -1)[:-1].reshape(-1, 3)
    faces = torch.cat([upper, lower]).to(torch.int32)
    return n.clone(), faces, uvs, n


def _vertex_normals(vertices: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """Angle-weighted vertex normals (as Mitsuba computes for meshes without normals)."""
    idx = indices.long()
    p = [vertices[idx[:, k]] for k in range(3)]
    fn = torch.linalg.cross(p[1] - p[0], p[2] - p[0])
    fn = fn / fn.norm(dim=1, keepdim=True).clamp_min(1e-300)
    out = torch.zeros_like(vertices)
    for k in range(3):
        d0 = p[(k + 1) % 3] - p[k]
        d1 = p[(k + 2) % 3] - p[k]
        cos = (d0 * d1).sum(1) / (d0.norm(dim=1) * d1.norm(dim=1)).clamp_min(1e-300)
        angle = torch.acos(cos.clamp(-1, 1))
        out.index_add_(0, idx[:, k], fn * angle[:, None])
    norm = out.norm(dim=1, keepdim=True)
    return torch.where(norm > 0, out / norm.clamp_min(1e-300), torch.tensor([0.0, 0.0, 1.0],
                                                                            dtype=out.dtype))


def _merge(meshes: List[Mesh]) -> Mesh:
    """One mesh from the per-material meshes of an OBJ file (Mitsuba ignores its materials)."""
    if len(meshes) == 1:
        return meshes[0]
    if not meshes:
        raise ValueError("no faces")
    for attr in ("uvs", "normals"):
        if len({getattr(m, attr) is None for m in meshes}) > 1:
            raise ValueError(f"some material groups have {attr} and some do not")

    def cat(values, index_attr):
        if values[0] is None:
            return None, None
        idx, total = [], 0
        for m, val in zip(meshes, values):
            idx.append(getattr(m, index_attr).long() + total)
            total += val.shape[0]
        return torch.cat(values), torch.cat(idx).to(torch.int32)

    vertices, indices = cat([m.vertices for m in meshes], "indices")
    uvs, uv_indices = (None, None)
    if meshes[0].uvs is not None:
        uvs, uv_indices = cat([m.uvs for m in meshes],
                              "uv_indices" if meshes[0].uv_indices is not None else "indices")
    normals, normal_indices = (None, None)
    if meshes[0].normals is not None:
        normals, normal_indices = cat([m.normals for m in meshes],
                                      "normal_indices" if meshes[0].normal_indices is not None
                                      else "indices")
    return Mesh(vertices=vertices, indices=indices, uvs=uvs, normals=normals,
                uv_indices=uv_indices, normal_indices=normal_indices)
