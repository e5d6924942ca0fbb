"""Rendering: check and flatten a Scene into the core's plain description, call the core.

``render`` = ``flatten_scene`` (validation, float32/int32 views) + ``render_flat`` (one call
into the C++ core). A torch.autograd.Function can wrap ``render_flat`` later: the flat scene
lists every tensor the core reads.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import torch

from . import _core
from . import _validate as v
from .scene import Camera, EnvironmentMap, Material, Mesh, Scene, frame_from_to_world

SAMPLING = {"mis": 0, "light": 1, "bsdf": 2}
CAMERA_TYPES = {"perspective": 0, "orthographic": 1}
PIXEL_FILTERS = {"box": 0, "gaussian": 1}


@dataclass
class FlatScene:
    """A validated scene in the form the core takes: dicts of numbers and float32/int32
    C-contiguous CPU tensors (views of the caller's tensors where no conversion was needed).
    ``materials[i]`` belongs to ``meshes[i]``, so core messages map back to mesh fields."""
    camera: dict
    materials: List[dict] = field(default_factory=list)
    meshes: List[dict] = field(default_factory=list)
    envmap: Optional[dict] = None
    height: int = 0  # size of the rendered image (the crop window if one is set)
    width: int = 0


@dataclass
class RenderOptions:
    spp: int = 16
    max_bounces: int = 1
    seed: int = 0
    num_threads: int = 0  # 0: all cores
    sampling: int = 0


def render(scene: Scene, spp: int = 16, max_bounces: int = 1, seed: int = 0,
           num_threads: Optional[int] = None, sampling: str = "mis") -> torch.Tensor:
    """Renders ``scene`` and returns a float32 (H, W, 3) tensor of linear radiance, row 0 at
    the top (H, W: the crop window's size if the camera has one).

    ``spp``: samples per pixel; ``max_bounces``: scattering events per path (0: emitters
    seen directly, 1: direct lighting, ...); ``seed`` fixes the image bit for bit whatever
    ``num_threads`` (None: all cores); ``sampling``: "mis", "light" or "bsdf" (direct light
    by multiple importance sampling, by light sampling only, or by BSDF sampling only)."""
    options = render_options(spp, max_bounces, seed, num_threads, sampling)
    image, _ = render_flat(flatten_scene(scene), options)
    return image


def render_options(spp=16, max_bounces=1, seed=0, num_threads=None, sampling="mis") -> RenderOptions:
    return RenderOptions(
        spp=v.integer(spp, "spp", minimum=1),
        max_bounces=v.integer(max_bounces, "max_bounces", minimum=0),
        seed=_seed(seed),
        num_threads=0 if num_threads is None else v.integer(num_threads, "num_threads", minimum=1),
        sampling=v.choice(sampling, "sampling", SAMPLING),
    )


def render_flat(flat: FlatScene, options: RenderOptions) -> Tuple[torch.Tensor, dict]:
    """One call into the core. Returns the image and the core's counters."""
    image = torch.empty((flat.height, flat.width, 3), dtype=torch.float32)
    try:
        stats = _core.render(flat.camera, flat.materials, flat.meshes, flat.envmap, image,
                             options.spp, options.max_bounces, options.seed,
                             options.num_threads, options.sampling)
    except ValueError as error:
        raise ValueError(_user_field_names(str(error))) from None
    return image, stats


def flatten_scene(scene: Scene) -> FlatScene:
    if not isinstance(scene, Scene):
        v.fail("scene", f"expected an edgepath.Scene, got {type(scene).__name__}")
    flat = FlatScene(camera=_flatten_camera(scene.camera))
    crop = flat.camera.get("crop_window")
    flat.height = crop[3] if crop else flat.camera["height"]
    flat.width = crop[2] if crop else flat.camera["width"]

    meshes = scene.meshes
    if not isinstance(meshes, (list, tuple)):
        v.fail("meshes", f"expected a list of edgepath.Mesh, got {type(meshes).__name__}")
    if len(meshes) == 0:
        v.fail("meshes", "the scene has no meshes")
    for i, mesh in enumerate(meshes):
        mesh_dict, material_dict = _flatten_mesh(mesh, f"meshes[{i}]")
        mesh_dict["material"] = i
        flat.meshes.append(mesh_dict)
        flat.materials.append(material_dict)

    if scene.envmap is not None:
        flat.envmap = _flatten_envmap(scene.envmap)
    return flat


# ---- pieces -------------------------------------------------------------------------------

def _seed(seed) -> int:
    seed = v.integer(seed, "seed", minimum=0)
    if seed >= 2**64:
        v.fail("seed", f"must be < 2**64, got {seed}")
    return seed


def _vec3_list(t: torch.Tensor) -> List[float]:
    return [float(x) for x in t.tolist()]


def _flatten_camera(camera) -> dict:
    f = "camera"
    if not isinstance(camera, Camera):
        v.fail(f, f"expected an edgepath.Camera, got {type(camera).__name__}")
    if camera.to_world is not None:
        if any(x is not None for x in (camera.position, camera.look_at, camera.up)):
            v.fail(f, "give either to_world or position/look_at/up, not both")
        m = v.float_tensor(camera.to_world, "camera.to_world", (4, 4))
        if float(torch.linalg.det(m[:3, :3])) < 0:
            v.fail("camera.to_world", "mirrors the image (negative determinant); not supported")
        position, look_at, up = frame_from_to_world(m)
    else:
        if camera.position is None:
            v.fail("camera.position", "missing (give position/look_at/up or to_world)")
        if camera.look_at is None:
            v.fail("camera.look_at", "missing (give position/look_at/up or to_world)")
        position, look_at, up = camera.frame()
        position = v.float_tensor(position, "camera.position", (3,))
        look_at = v.float_tensor(look_at, "camera.look_at", (3,))
        up = v.float_tensor(up, "camera.up", (3,))

    resolution = camera.resolution
    if not isinstance(resolution, (tuple, list)) or len(resolution) != 2:
        v.fail("camera.resolution", f"expected (height, width), got {resolution!r}")
    height = v.integer(resolution[0], "camera.resolution", minimum=1)
    width = v.integer(resolution[1], "camera.resolution", minimum=1)

    out = {
        "position": _vec3_list(position),
        "look_at": _vec3_list(look_at),
        "up": _vec3_list(up),
        "fov": v.number(camera.fov, "camera.fov"),
        "ortho_scale": v.number(camera.ortho_scale, "camera.ortho_scale"),
        "type": v.choice(camera.camera_type, "camera.camera_type", CAMERA_TYPES),
        "height": height,
        "width": width,
        "filter": v.choice(camera.pixel_filter, "camera.pixel_filter", PIXEL_FILTERS),
        "filter_stddev": v.number(camera.filter_stddev, "camera.filter_stddev"),
        "crop_window": None,
    }
    if camera.crop_window is not None:
        crop = camera.crop_window
        if not isinstance(crop, (tuple, list)) or len(crop) != 4:
            v.fail("camera.crop_window", f"expected (x, y, width, height), got {crop!r}")
        x, y = (v.integer(c, "camera.crop_window", minimum=0) for c in crop[:2])
        w, h = (v.integer(c, "camera.crop_window", minimum=1) for c in crop[2:])
        out["crop_window"] = [x, y, w, h]  # fitting in the film: checked by the core
    return out


def _flatten_material(material, f: str, emissive: bool) -> dict:
    if material is None:
        material = Material(diffuse=0.0 if emissive else 0.5)
    if not isinstance(material, Material):
        v.fail(f, f"expected an edgepath.Material, got {type(material).__name__}")
    return {
        "diffuse": v.texture(material.diffuse, f + ".diffuse", 3),
        "specular": v.texture(material.specular, f + ".specular", 3),
        "roughness": v.texture(material.roughness, f + ".roughness", 1),
        "two_sided": v.boolean(material.two_sided, f + ".two_sided"),
    }


def _flatten_mesh(mesh, f: str) -> Tuple[dict, dict]:
    if not isinstance(mesh, Mesh):
        v.fail(f, f"expected an edgepath.Mesh, got {type(mesh).__name__}")
    vertices = v.float_tensor(mesh.vertices, f + ".vertices", ("N", 3))
    indices = v.index_tensor(mesh.indices, f + ".indices", ("M", 3))
    rows = indices.shape[0]
    out = {
        "vertices": vertices,
        "indices": indices,
        "uvs": None,
        "uv_indices": None,
        "normals": None,
        "normal_indices": None,
        "emission": None,
        "two_sided_emission": v.boolean(mesh.two_sided_emission, f + ".two_sided_emission"),
    }
    if mesh.uvs is not None:
        out["uvs"] = v.float_tensor(mesh.uvs, f + ".uvs", ("K", 2))
    if mesh.uv_indices is not None:
        out["uv_indices"] = v.index_tensor(mesh.uv_indices, f + ".uv_indices", (rows, 3))
    if mesh.normals is not None:
        out["normals"] = v.float_tensor(mesh.normals, f + ".normals", ("K", 3))
    if mesh.normal_indices is not None:
        out["normal_indices"] = v.index_tensor(mesh.normal_indices, f + ".normal_indices", (rows, 3))
    if mesh.emission is not None:
        out["emission"] = v.texture(mesh.emission, f + ".emission", 3)
    material = _flatten_material(mesh.material, f + ".material", mesh.emission is not None)
    return out, material


def _flatten_envmap(envmap) -> dict:
    f = "envmap"
    if not isinstance(envmap, EnvironmentMap):
        v.fail(f, f"expected an edgepath.EnvironmentMap, got {type(envmap).__name__}")
    values = v.float_tensor(envmap.values, f + ".values", ("H", "W", 3))
    if envmap.to_world is None:
        rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    else:
        m = v.tensor(envmap.to_world, f + ".to_world")
        if tuple(m.shape) not in ((3, 3), (4, 4)):
            v.fail(f + ".to_world", f"expected shape (3, 3) or (4, 4), got {tuple(m.shape)}")
        m = v.float_tensor(m, f + ".to_world", tuple(m.shape))
        rotation = [float(x) for x in m[:3, :3].reshape(-1).tolist()]
    return {"values": values, "to_world": rotation, "scale": v.number(envmap.scale, f + ".scale")}


_MATERIAL_FIELD = re.compile(r"\bmaterials\[(\d+)\]")


def _user_field_names(message: str) -> str:
    """The core numbers materials in its own list; ours has materials[i] for meshes[i]."""
    return _MATERIAL_FIELD.sub(r"meshes[\1].material", message)
