"""Mitsuba 3 conformance scenes for edgepath tests.

The reference data (tiny Mitsuba 3 scenes, each with a primal image and a finite-difference
derivative image) lives in ``shared/conformance/mitsuba3`` beside the repository root; its
``configs.json`` describes every scene exactly and ``README.md`` the conventions. This module
turns each config into an ``edgepath.Scene``, applies the config's scalar parameter theta,
loads the reference images and computes Mitsuba's image metric.

    scene, param = build("diffuse_albedo", theta=0.0)
    image = ep.render(scene, spp=256, max_bounces=param.max_bounces)
    mean_err, max_err = image_error(image, load_ref("diffuse_albedo", "primal"), PRIMAL_FLOOR)

``theta`` may be a float or a 0-d tensor with ``requires_grad``: every scene tensor that
depends on theta is computed from it with torch operations, so a render's gradient reaches it,
and a central finite difference is ``(render(build(n, +eps/2)) - render(build(n, -eps/2))) / eps``.

Mapping of Mitsuba's shapes (see the README):
- ``rectangle``: the square [-1, 1]^2 in z = 0 as two triangles, counter-clockwise seen from +z
  (so the face normal is +z), uv = ((x + 1) / 2, (y + 1) / 2).
- ``sphere``: the tessellated unit sphere ``meshes/sphere.obj`` (32512 triangles) with its
  smooth vertex normals. It is not the analytic sphere, but close: no face plane lies more
  than 0.00038 radii inside it (0.02 px on the 128 px images here).
- OBJ meshes load through ``edgepath.load_obj`` (uv v flipped as Mitsuba does). With
  ``face_normals`` the file normals are dropped (flat shading).
Vertices are transformed by the shape's ``to_world``; normals by its inverse transpose.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import torch

import edgepath as ep

DATA_DIR = Path(__file__).resolve().parents[3] / "shared" / "conformance" / "mitsuba3"
CONFIGS_FILE = DATA_DIR / "configs.json"

PRIMAL_FLOOR = 0.02    # denominators floor of the primal image check
GRADIENT_FLOOR = 0.2   # ... and of the derivative image check

Theta = Union[float, torch.Tensor]


def data_available() -> bool:
    return CONFIGS_FILE.is_file()


def missing_data_reason() -> str:
    return (f"Mitsuba 3 conformance data not found: expected {CONFIGS_FILE} (a folder "
            f"'shared/conformance/mitsuba3' beside the repository root)")


# ---- configs and reference images ----------------------------------------------------------

@lru_cache(maxsize=1)
def _all_configs() -> Dict[str, dict]:
    with open(CONFIGS_FILE) as f:
        data = json.load(f)
    return {c["name"]: c for c in data["configs"]}


def config(name: str) -> dict:
    return _all_configs()[name]


def config_names(include_inactive: bool = True) -> List[str]:
    """Configs whose reference images are present, in the order of configs.json; with
    ``include_inactive`` also those Mitsuba no longer runs (the legacy translate_camera)."""
    names = []
    for name, c in _all_configs().items():
        files = c.get("files", {})
        has_refs = bool(files) and all((DATA_DIR / p).is_file() for p in files.values())
        if has_refs and (c["status"] == "active" or include_inactive):
            names.append(name)
    return names


def load_ref(name: str, kind: str = "primal", corrected: bool = True) -> torch.Tensor:
    """Reference image (H, W, 3) float32: ``kind`` "primal" or "fwd" (d image / d theta as
    Mitsuba's finite difference computed it). ``corrected``: scale a fwd image by
    ``FWD_REF_SCALE`` where the file is known to hold a multiple of the derivative."""
    image = ep.imread(DATA_DIR / config(name)["files"][kind])[:, :, :3].contiguous()
    if kind == "fwd" and corrected and name in FWD_REF_SCALE:
        image = image * FWD_REF_SCALE[name]
    return image


def image_error(image: torch.Tensor, ref: torch.Tensor, floor: float) -> Tuple[float, float]:
    """Mitsuba's image metric over all H*W*3 values: err = |image - ref| / max(|ref|, floor);
    returns (mean(err), max(err)). A check fails if either exceeds its threshold."""
    if image.shape != ref.shape:
        raise ValueError(f"image shape {tuple(image.shape)} differs from the reference's "
                         f"{tuple(ref.shape)}")
    x = image.detach().to(torch.float64)
    r = ref.detach().to(torch.float64)
    err = (x - r).abs() / r.abs().clamp_min(floor)
    return float(err.mean()), float(err.max())


def block_means(image: torch.Tensor, k: int) -> torch.Tensor:
    """The means of an (H, W, 3) image's k x k blocks, (H / k, W / k, 3): Mitsuba's scene tests
    compare images so."""
    return torch.nn.functional.avg_pool2d(image.permute(2, 0, 1)[None], k)[0].permute(1, 2, 0)


def relative_l1(image: torch.Tensor, reference: torch.Tensor) -> float:
    """sum |image - reference| / sum |reference|."""
    return float((image - reference).abs().sum() / reference.abs().sum())


def assert_matches_finite_difference(d_image: torch.Tensor, fd_image: torch.Tensor, label: str,
                                     least_change: float, l1: float = 0.3, sum_tol: float = 0.05) -> None:
    """A derivative image against a finite difference image: the latter changes (mean |.| above
    `least_change`), their relative L1 distance is below `l1` and their sums agree within
    `sum_tol`."""
    error = relative_l1(d_image, fd_image)
    ratio = float(d_image.sum() / fd_image.sum())
    print(f"{label}: relative L1 {error:.4f}, sum ratio {ratio:.4f}")
    assert float(fd_image.abs().mean()) > least_change  # the image does change with the parameter
    assert error < l1
    assert abs(ratio - 1.0) <= sum_tol


def assert_matches_reference_image(image: torch.Tensor, ref: torch.Tensor, label: str, k: int = 4,
                                   mean_max: float = 0.04, max_max: float = 0.4, means: float = 0.02) -> None:
    """An image against another renderer's: the mean of each channel within `means` (relative),
    and Mitsuba's metric (image_error, floor 0.02) on k x k blocks of pixels (averaging the noise
    of both renders) below `mean_max` on average and `max_max` at worst."""
    relative = image.mean((0, 1)) / ref.mean((0, 1)) - 1
    mean_err, max_err = image_error(block_means(image, k), block_means(ref, k), 0.02)
    print(label, "channel means", relative.tolist(), "blocks", (mean_err, max_err))
    assert float(relative.abs().max()) < means
    assert mean_err < mean_max and max_err < max_max


def descend(param: torch.Tensor, loss, lr: float, steps: int) -> List[float]:
    """Adam on ``loss(seed)`` (a fresh seed each step) for ``steps`` steps at ``lr``, a fifth of
    it over the last 40%, with less momentum than the default (beta1 0.5): the parameter's
    values after each step. Adam's default momentum at a constant rate swings the parameter
    past the optimum and back over tens of steps, so where a fixed number of steps stops
    depends on the noise; this settles it."""
    optimizer = torch.optim.Adam([param], lr=lr, betas=(0.5, 0.999))
    schedule = torch.optim.lr_scheduler.MultiStepLR(optimizer, [int(0.6 * steps)], 0.2)
    history = []
    for step in range(steps):
        optimizer.zero_grad()
        loss(step).backward()
        optimizer.step()
        schedule.step()
        history.append(float(param.detach()))
    return history


def fit_roughness(render, target: torch.Tensor, start: float, steps: int, floor: float) -> float:
    """Inverse rendering of one roughness: Adam (learning rate 0.03, decayed by 0.95 a step, to
    settle in the noise) on the mean square difference between render(roughness, seed=step) and
    `target`, from `start`, the roughness kept at `floor` or above. Returns the roughness found."""
    roughness = torch.tensor(start, requires_grad=True)
    optimizer = torch.optim.Adam([roughness], lr=0.03)
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=0.95)
    for it in range(steps):
        optimizer.zero_grad()
        ((render(roughness, it) - target) ** 2).mean().backward()
        optimizer.step()
        schedule.step()
        with torch.no_grad():
            roughness.clamp_(min=floor)
    print("recovered roughness", roughness.item())
    return roughness.item()


def error_map(image: torch.Tensor, ref: torch.Tensor, floor: float) -> torch.Tensor:
    """Per-value err = |image - ref| / max(|ref|, floor), shape (H, W, 3)."""
    r = ref.detach().to(torch.float64)
    return (image.detach().to(torch.float64) - r).abs() / r.abs().clamp_min(floor)


def thresholds(name: str) -> dict:
    return dict(config(name)["thresholds"])


def max_bounces(name: str) -> int:
    """edgepath's max_bounces = Mitsuba's max_depth - 1."""
    return int(config(name)["integrator"]["max_depth"]) - 1


# ---- theta ---------------------------------------------------------------------------------

@dataclass
class Parameter:
    """The scalar parameter theta of a config, as configs.json describes it.

    ``kind`` is one of
    - "albedo_offset":   material diffuse reflectance += theta (all channels) of ``objects``
    - "emission_offset": area-emitter radiance += theta (all channels) of ``objects``
    - "envmap_offset":   constant environment radiance += theta (all channels)
    - "translate":       world-space vertices p -> p + theta * ``direction`` of ``objects``
    - "scale":           world-space vertices p -> p * (1 + theta) of ``objects``
    - "rotate_normals":  shading normals n -> R(axis ``direction``, theta DEGREES) n
    - "camera_translate": camera to_world -> to_world @ translate(theta * ``direction``)
      (``direction`` in camera-local coordinates; local +x is the image's LEFT)

    ``tensors`` maps a field name (e.g. "meshes[1].vertices", "meshes[0].material.diffuse",
    "camera.to_world") to the scene tensor that theta enters; ``mesh_index`` maps shape ids to
    their index in ``scene.meshes``.
    """
    name: str
    mitsuba_key: str
    kind: str
    objects: Tuple[str, ...]
    direction: Optional[Tuple[float, float, float]]
    units: str
    epsilon: float
    theta_enters: str
    theta: Theta
    max_bounces: int
    tensors: Dict[str, torch.Tensor] = field(default_factory=dict)
    mesh_index: Dict[str, int] = field(default_factory=dict)


_POSITIONS_KEY = re.compile(r"^(\w+)\.positions$")
_TRANSLATE_RULE = re.compile(r"p\s*->\s*p\s*\+\s*\(([^)]*)\)")
_SCALE_RULE = re.compile(r"p\s*->\s*p\s*\*\s*\(\s*1\s*\+\s*theta\s*\)")


def _parse_parameter(c: dict) -> Tuple[str, Tuple[str, ...], Optional[Tuple[float, float, float]]]:
    """(kind, objects, direction) of a config's differentiated_parameter."""
    dp = c["differentiated_parameter"]
    key, enters = dp["mitsuba_key"], dp["theta_enters"]
    keys = [k.strip() for k in key.split(" AND ")]
    if all(_POSITIONS_KEY.match(k) for k in keys):
        objects = tuple(_POSITIONS_KEY.match(k).group(1) for k in keys)
        m = _TRANSLATE_RULE.search(enters)
        if m:
            parts = [s.strip() for s in m.group(1).split(",")]
            if len(parts) != 3 or any(s not in ("0", "theta") for s in parts):
                raise ValueError(f"{c['name']}: cannot read translation {enters!r}")
            return "translate", objects, tuple(1.0 if s == "theta" else 0.0 for s in parts)
        if _SCALE_RULE.search(enters):
            return "scale", objects, None
        raise ValueError(f"{c['name']}: cannot read position update {enters!r}")
    if len(keys) != 1:
        raise ValueError(f"{c['name']}: unsupported parameter {key!r}")
    parts = key.split(".")
    if parts[1:] == ["bsdf", "reflectance", "value"]:
        return "albedo_offset", (parts[0],), None
    if parts[1:] == ["emitter", "radiance", "value"]:
        return "emission_offset", (parts[0],), None
    constant_env = c["scene"]["environment"]["type"].startswith("constant")
    if parts[1:] == ["radiance", "value"] and constant_env:
        return "envmap_offset", (), None
    if parts[1:] == ["normals"]:
        if "R_y(theta)" not in enters or "DEGREES" not in enters:
            raise ValueError(f"{c['name']}: cannot read normal rotation {enters!r}")
        return "rotate_normals", (parts[0],), (0.0, 1.0, 0.0)
    if key == "sensor.to_world":
        if "to_world @ translate(theta, 0, 0)" not in enters:
            raise ValueError(f"{c['name']}: cannot read camera update {enters!r}")
        return "camera_translate", (), (1.0, 0.0, 0.0)
    raise ValueError(f"{c['name']}: unsupported parameter {key!r}")


# ---- geometry helpers ----------------------------------------------------------------------

def _matrix(rows) -> torch.Tensor:
    return torch.tensor(rows, dtype=torch.float64)


def _transform_points(m: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    return p @ m[:3, :3].T + m[:3, 3]


def _transform_normals(m: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
    n = n @ torch.linalg.inv(m[:3, :3])  # rows: (M^-T n)^T = n^T M^-1
    return n / n.norm(dim=1, keepdim=True)


def _rotation(axis: Sequence[float], degrees: Theta) -> torch.Tensor:
    """3x3 right-handed rotation about ``axis`` (float64), differentiable in ``degrees``."""
    a = torch.tensor(axis, dtype=torch.float64)
    a = a / a.norm()
    angle = torch.as_tensor(degrees, dtype=torch.float64) * (math.pi / 180.0)
    k = torch.zeros(3, 3, dtype=torch.float64)
    k[0, 1], k[0, 2], k[1, 0], k[1, 2], k[2, 0], k[2, 1] = -a[2], a[1], a[2], -a[0], -a[1], a[0]
    eye = torch.eye(3, dtype=torch.float64)
    return eye + torch.sin(angle) * k + (1.0 - torch.cos(angle)) * (k @ k)


@dataclass
class _Geometry:
    vertices: torch.Tensor            # object space, float64
    indices: torch.Tensor
    uvs: Optional[torch.Tensor] = None
    uv_indices: Optional[torch.Tensor] = None
    normals: Optional[torch.Tensor] = None  # object space, float64
    normal_indices: Optional[torch.Tensor] = None


def _rectangle() -> _Geometry:
    v = torch.tensor([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
                     dtype=torch.float64)
    f = torch.tensor([[0, 1, 3], [0, 3, 2]], dtype=torch.int32)
    uv = (v[:, :2] + 1.0) * 0.5
    return _Geometry(vertices=v, indices=f, uvs=uv)


@lru_cache(maxsize=None)
def _obj(relative_path: str) -> _Geometry:
    meshes = ep.load_obj(DATA_DIR / relative_path)
    if len(meshes) != 1:
        raise ValueError(f"{relative_path}: expected one mesh, got {len(meshes)}")
    m = meshes[0]

    def f64(t):
        return None if t is None else t.to(torch.float64)

    return _Geometry(vertices=f64(m.vertices), indices=m.indices, uvs=m.uvs,
                     uv_indices=m.uv_indices, normals=f64(m.normals),
                     normal_indices=m.normal_indices)


def _shape_geometry(shape: dict) -> Tuple[_Geometry, bool]:
    """Object-space geometry of a shape, and whether it has smooth shading normals."""
    kind = shape["type"]
    if kind.startswith("rectangle"):
        return _rectangle(), False
    if kind.startswith("sphere"):
        g = _obj("meshes/sphere.obj")
        if g.normals is None:
            raise ValueError("meshes/sphere.obj: expected vertex normals")
        return g, True
    if kind.startswith("triangle mesh"):
        g = _obj(shape["mesh_file"])
        smooth = not shape.get("face_normals", True)
        return g, smooth
    raise ValueError(f"shape {shape['id']}: unsupported type {kind!r}")


# ---- textures and colours ------------------------------------------------------------------

@lru_cache(maxsize=None)
def _texture(relative_path: str) -> torch.Tensor:
    image = ep.imread(DATA_DIR / relative_path)
    if image.shape[2] <= 2:  # grey (+ alpha): Mitsuba's rgb variants spread Y over R, G, B
        image = image[:, :, :1].expand(-1, -1, 3)
    return image[:, :, :3].contiguous()


def _colour(value, what: str) -> torch.Tensor:
    """A (3,) float64 tensor from a scalar or an rgb list, or a (H, W, 3) texture from a
    bitmap description."""
    if isinstance(value, dict):
        if value.get("type") != "bitmap":
            raise ValueError(f"{what}: unsupported texture {value!r}")
        # Wrap modes: edgepath textures repeat. The only clamped bitmap here (gradient.jpg)
        # has a black border all round, which makes repeat and clamp identical.
        return _texture(value["file"]).to(torch.float64)
    if isinstance(value, (int, float)):
        return torch.full((3,), float(value), dtype=torch.float64)
    if isinstance(value, list) and len(value) == 3:
        return torch.tensor(value, dtype=torch.float64)
    raise ValueError(f"{what}: unsupported value {value!r}")


def _f32(t: torch.Tensor) -> torch.Tensor:
    return t.to(torch.float32).contiguous()


# ---- the scene -----------------------------------------------------------------------------

# Where the reference images contradict configs.json, the scene that rendered them wins (the
# test compares against the images). Each entry says why.
SCENE_CORRECTIONS: Dict[str, dict] = {
    "crop_window": {
        "drop_shapes": ("sphere",),
        "reason": "configs.json lists the diffuse_albedo sphere (radius 0.25 at the origin), but "
                  "the reference has none: the film pixels where its right half and its contact "
                  "shadow would be (crop columns 0-6, rows 6-18) are a flat 0.500 +- 0.0005, "
                  "while a render with the sphere dips to 0.36 there. Mitsuba's CropWindowConfig "
                  "(test_ad_integrators.py) is a plane under a constant emitter, no sphere.",
    },
}

# Known defects of reference images, for tests that use them (see configs.json notes).
FWD_REF_SCALE: Dict[str, float] = {
    # The FD update composed with the already-moved camera: the file holds half the derivative.
    # Confirmed here: doubled, its per-row silhouette sums (3.0-4.6, noisy) match our own central
    # differences (3.4-3.6 at 8192 spp, step 0.02) and the analytic 0.5 jump x 6.97 px = 3.49.
    "translate_camera": 2.0,
}
BIASED_REFERENCES: Dict[str, str] = {
    "translate_plane_under_textured_area_emitter":
        "rendered before Mitsuba fixed textured-emitter sampling: primal 0.4-1.6% low "
        "(translate_textured_area_emitter_illuminating_plane has the same scene, rendered after)",
}


def build(name: str, theta: Theta = 0.0, corrected: bool = True) -> Tuple[ep.Scene, Parameter]:
    """The edgepath scene of config ``name`` with its parameter set to ``theta`` (0: the
    primal scene), and a description of that parameter. Render it with
    ``max_bounces=param.max_bounces``. ``corrected``: apply ``SCENE_CORRECTIONS`` (the scene
    the reference images show); False builds configs.json literally."""
    c = config(name)
    drop = SCENE_CORRECTIONS.get(name, {}).get("drop_shapes", ()) if corrected else ()
    kind, objects, direction = _parse_parameter(c)
    dp = c["differentiated_parameter"]
    param = Parameter(name=name, mitsuba_key=dp["mitsuba_key"], kind=kind, objects=objects,
                      direction=direction, units=dp.get("units", ""),
                      epsilon=float(c["finite_difference"]["epsilon"]),
                      theta_enters=dp["theta_enters"], theta=theta, max_bounces=max_bounces(name))
    t = torch.as_tensor(theta, dtype=torch.float64)

    ids = [s["id"] for s in c["scene"]["shapes"]]
    for o in objects:
        if o not in ids:
            raise ValueError(f"{name}: parameter object {o!r} is not a shape ({ids})")

    meshes = []
    for shape in c["scene"]["shapes"]:
        sid = shape["id"]
        if sid in drop:
            continue
        i = len(meshes)
        param.mesh_index[sid] = i
        moved = sid in objects
        g, smooth = _shape_geometry(shape)
        m = _matrix(shape["to_world"]["matrix_row_major"])
        if float(torch.linalg.det(m[:3, :3])) <= 0.0:
            raise ValueError(f"{name}: shape {sid} has a mirroring to_world")

        vertices = _transform_points(m, g.vertices)
        normals = _transform_normals(m, g.normals) if (smooth and g.normals is not None) else None
        normal_indices = g.normal_indices if normals is not None else None
        if smooth and normals is None:
            # Mitsuba computes vertex normals for an OBJ that has none; on a flat mesh (the
            # only case here: rotate_shading_normals_plane) they all equal the face normal.
            idx = g.indices.long()
            fn = torch.linalg.cross(vertices[idx[:, 1]] - vertices[idx[:, 0]],
                                    vertices[idx[:, 2]] - vertices[idx[:, 0]])
            fn = fn / fn.norm(dim=1, keepdim=True)
            if not torch.allclose(fn, fn[:1].expand_as(fn)):
                raise ValueError(f"{name}: shape {sid}: vertex normals of a curved OBJ "
                                 "without normals are not implemented")
            normals = fn[:1].expand(vertices.shape[0], 3).contiguous()
            normal_indices = None

        if moved and kind == "translate":
            vertices = vertices + t * torch.tensor(direction, dtype=torch.float64)
        elif moved and kind == "scale":
            vertices = vertices * (1.0 + t)
        elif moved and kind == "rotate_normals":
            if normals is None:
                raise ValueError(f"{name}: shape {sid} has no shading normals to rotate")
            normals = normals @ _rotation(direction, t).T

        bsdf = shape.get("bsdf", {})
        albedo = _colour(bsdf.get("reflectance", 0.5), f"{name}.{sid}.bsdf.reflectance")
        if moved and kind == "albedo_offset":
            albedo = albedo + t
        emission = None
        if "emitter" in shape:
            emission = _colour(shape["emitter"]["radiance"], f"{name}.{sid}.emitter.radiance")
            if moved and kind == "emission_offset":
                emission = emission + t
        material = ep.Material(diffuse=_f32(albedo), two_sided=False)

        mesh = ep.Mesh(vertices=_f32(vertices), indices=g.indices, uvs=g.uvs,
                       uv_indices=g.uv_indices,
                       normals=None if normals is None else _f32(normals),
                       normal_indices=normal_indices, material=material,
                       emission=None if emission is None else _f32(emission),
                       two_sided_emission=False)
        meshes.append(mesh)
        if moved:
            if kind in ("translate", "scale"):
                param.tensors[f"meshes[{i}].vertices"] = mesh.vertices
            elif kind == "rotate_normals":
                param.tensors[f"meshes[{i}].normals"] = mesh.normals
            elif kind == "albedo_offset":
                param.tensors[f"meshes[{i}].material.diffuse"] = material.diffuse
            elif kind == "emission_offset":
                param.tensors[f"meshes[{i}].emission"] = mesh.emission

    env = c["scene"]["environment"]
    envmap = None
    if env["type"].startswith("constant"):
        radiance = _colour(env.get("radiance", 1.0), f"{name}.environment.radiance")
        if kind == "envmap_offset":
            radiance = radiance + t
        envmap = ep.EnvironmentMap(values=_f32(radiance.reshape(1, 1, 3)))
        if kind == "envmap_offset":
            param.tensors["envmap.values"] = envmap.values
    elif env["type"].startswith("envmap"):
        to_world = env.get("to_world", "identity")
        if to_world != "identity":
            to_world = torch.tensor(to_world, dtype=torch.float32)
        else:
            to_world = None
        envmap = ep.EnvironmentMap(values=_texture(env["file"]), to_world=to_world,
                                   scale=float(env.get("scale", 1.0)))
    elif not env["type"].startswith("none"):
        raise ValueError(f"{name}: unsupported environment {env['type']!r}")

    camera = _camera(c, kind, direction, t)
    if kind == "camera_translate":
        param.tensors["camera.to_world"] = camera.to_world
    return ep.Scene(camera=camera, meshes=meshes, envmap=envmap), param


def _camera(c: dict, kind: str, direction, t: torch.Tensor) -> ep.Camera:
    sensor = c["sensor"]
    if sensor["type"] != "perspective":
        raise ValueError(f"{c['name']}: unsupported sensor {sensor['type']!r}")
    to_world = _matrix(sensor["to_world"])
    if kind == "camera_translate":
        shift = torch.eye(4, dtype=torch.float64)
        shift[:3, 3] = t * torch.tensor(direction, dtype=torch.float64)
        to_world = to_world @ shift
    film = sensor["film"]
    pf = film["pixel_filter"]
    if pf["type"] == "box":
        pixel_filter, stddev = "box", 0.5
    elif pf["type"] == "gaussian":
        pixel_filter, stddev = "gaussian", float(pf["stddev"])
        if abs(float(pf.get("radius_px", 4.0 * stddev)) - 4.0 * stddev) > 1e-6:
            raise ValueError(f"{c['name']}: Gaussian filters are cut at 4 stddev in edgepath")
    else:
        raise ValueError(f"{c['name']}: unsupported pixel filter {pf['type']!r}")
    crop = film.get("crop")
    crop_window = None
    if crop:
        crop_window = (int(crop["offset_x"]), int(crop["offset_y"]), int(crop["width"]),
                       int(crop["height"]))
    return ep.Camera(to_world=_f32(to_world), fov=float(sensor["fov"]["x_fov_deg"]),
                     resolution=(int(film["height"]), int(film["width"])),
                     camera_type="perspective", pixel_filter=pixel_filter,
                     filter_stddev=stddev, crop_window=crop_window)
