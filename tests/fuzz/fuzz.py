"""Fuzzing the loaders: mutated OBJ, PLY (ASCII and binary), Mitsuba XML, PNG, JPEG and EXR
files go through ``edgepath``'s loader and a small render, each in a child process with a time
and memory cap; and the Python API (kind ``api``): a small scene built in Python whose values
are changed (a JSON list of changes, corpus.mutate_api: NaN, Inf, huge and tiny values, other
dtypes, shapes, devices, out-of-range indices, coplanar points), and may first be put in another
form (corpus.API_VARIANTS: camera types, pixel filters, crop windows, resolutions, camera
matrices, material kinds, bounce counts, the entry point), is rendered with a gradient of
everything that can have one; and that scene, in up to three of its valid forms (kind
``placed``), is moved to another scale and place, where its image and gradients must be what
they were. Every outcome is classified:

  ok          loaded (and rendered, where the input makes a scene)
  error       a clean error: ValueError or OSError whose message names the file (loading)
              or a field (rendering)
  unnamed     a ValueError / OSError whose message names neither
  unexpected  any other Python exception (a traceback of an unexpected type, MemoryError, a
              C++ exception that reached Python as RuntimeError, ...)
  signal      the child died by a signal (abort, segfault, the memory cap)
  hang        the child computed past the time cap on one case (CPU time), or waited six
              times that without an answer (wall time)
  nonfinite   (api) rendered without an error, but the image or a gradient holds Inf or NaN
              (except gradients that overflowed, with the warning that says so, where the case
              scaled values by 1e30: every value in range, their product is not)
  modified    (api) the call, with or without an error, changed a tensor the caller gave it:
              its values, dtype, shape, version counter (an in-place operation) or requires_grad
  inconsistent (placed) the API scene, in up to three of its valid forms, moved to another
              scale (3e-10 to 3e10) and place, rendered another image sum (beyond 2%) or
              gradients (beyond a factor of 1.25, each value's |gradient| summed, times the
              scale to the power of its units) than where it was, with the same random numbers;
              or was refused there

Case ``i`` of ``--seed S`` is the same file on every run. The process that drives the cases
imports edgepath once and forks children (it never renders itself, so no TBB or OpenMP
threads exist when it forks); a child sets its limits and one thread each for torch and the
core, and runs a batch of cases one after the other, reporting each through a pipe, until one
kills it or runs past the time cap: a new child goes on after that case. Replayed files
(``--replay``) run one per child.

    python tests/fuzz/fuzz.py --cases 2000 --seed 1 --save build/fuzz/found
    python tests/fuzz/fuzz.py --replay tests/python/fuzz_regressions

Exit status 1 if any case was ``unexpected``, ``signal`` or ``hang``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import resource
import select
import shutil
import signal
import sys
import tempfile
import time
import traceback
import warnings
from collections import Counter, defaultdict
from typing import Dict, List, Optional, Tuple

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import corpus  # noqa: E402

BAD = ("unexpected", "signal", "hang", "nonfinite", "modified", "inconsistent")
OUTCOMES = ("ok", "error", "unnamed") + BAD

# Per case: seconds of the child's CPU time (a case that computes that long hangs), bytes of
# address space beyond what the driver had mapped. A case that waits without computing (a
# deadlock) hangs after IDLE_FACTOR times the limit in wall time. CPU time rather than wall time,
# so that a loaded machine, which slows every case down, does not make hangs of them.
TIME_LIMIT = 10.0
IDLE_FACTOR = 6.0
MEMORY_LIMIT = 2 << 30


def cpu_seconds(pid: int) -> Optional[float]:
    """The CPU time (user and system, every thread) process ``pid`` has used, or None where
    /proc cannot tell (then the limit is on wall time alone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def kind_of(path: str) -> str:
    """The loader a file goes to, from its name (regression files: KIND-...ext)."""
    name = os.path.basename(path)
    for kind in sorted(corpus.KINDS, key=len, reverse=True):
        if name.startswith(kind + "-") or name.startswith(kind + "."):
            return kind
    ext = os.path.splitext(name)[1].lower()
    return {".obj": "obj", ".ply": "ply_ascii", ".xml": "xml", ".png": "png", ".jpg": "jpeg",
            ".jpeg": "jpeg", ".exr": "exr", ".json": "api"}[ext]


# ---- one case, in the child ------------------------------------------------------------------

def _framing_camera(ep, meshes):
    import torch
    points = torch.cat([m.vertices.detach().reshape(-1, 3).double() for m in meshes])
    lo, hi = points.min(0).values, points.max(0).values
    centre = (lo + hi) / 2
    radius = max(float((hi - lo).norm()) / 2, 1e-3)
    return ep.Camera(position=(centre + torch.tensor([0.0, 0.0, 3 * radius])).float(),
                     look_at=centre.float(), up=torch.tensor([0.0, 1.0, 0.0]), fov=45.0,
                     resolution=(6, 8))


def _api_scene(ep):
    """The API kind's scene: a textured, normal-mapped glossy floor, a box of rough glass with
    normals and colours, an area lamp, a sky, a point light and a spot light; its float tensors
    require grad. Returns the scene and its objects by the names corpus.API_FIELDS uses."""
    import torch
    gen = torch.Generator().manual_seed(0)
    floor = ep.Mesh(torch.tensor([[-1., 0., -1.], [1., 0., -1.], [1., 0., 1.], [-1., 0., 1.]]),
                    torch.tensor([[0, 2, 1], [0, 3, 2]], dtype=torch.int32),
                    uvs=torch.tensor([[0., 0.], [1., 0.], [1., 1.], [0., 1.]]),
                    material=ep.Material(diffuse=torch.rand(4, 5, 3, generator=gen),
                                         specular=torch.tensor([.2, .2, .2]), roughness=torch.tensor([.3]),
                                         normal_map=torch.rand(3, 4, 3, generator=gen) * .4 + .3))
    box_vertices, box_indices = ep.shapes.box((0., .5, 0.), (.3, .3, .3))
    box = ep.Mesh(box_vertices, box_indices,
                  normals=torch.nn.functional.normalize(box_vertices - torch.tensor([0., .5, 0.]), dim=1),
                  colors=torch.rand(box_vertices.shape[0], 3, generator=gen),
                  material=ep.Material(diffuse=torch.tensor([.7, .3, .2]), roughness=torch.tensor([.2]),
                                       kind="dielectric", ior=1.4))
    lamp = ep.Mesh(torch.tensor([[-.2, 2., -.2], [.2, 2., -.2], [.2, 2., .2], [-.2, 2., .2]]),
                   torch.tensor([[0, 1, 2], [0, 2, 3]]), emission=torch.tensor([5., 5., 5.]))
    camera = ep.Camera(position=torch.tensor([0., 1.5, 3.]), look_at=torch.tensor([0., .3, 0.]),
                       up=torch.tensor([0., 1., 0.]), fov=45.0, resolution=(6, 8))
    envmap = ep.EnvironmentMap(torch.rand(4, 8, 3, generator=gen), scale=torch.tensor(1.0))
    light = ep.PointLight(torch.tensor([1., 1., 1.]), intensity=torch.tensor([2., 2., 2.]))
    spot = ep.Spot(torch.tensor([1., -1., -1.]), cutoff_angle=torch.tensor(40.0),
                   beam_width=torch.tensor(20.0))
    spot_light = ep.PointLight(torch.tensor([-1., 1., 1.]), intensity=torch.tensor([1., 2., 3.]),
                               spot=spot)
    scene = ep.Scene(camera, [floor, box, lamp], envmap=envmap, point_lights=[light, spot_light])
    objects = {"floor": floor, "box": box, "lamp": lamp, "camera": camera, "envmap": envmap,
               "floor_material": floor.material, "box_material": box.material, "point_light": light,
               "spot": spot}
    for obj in objects.values():
        for name, value in vars(obj).items():
            if isinstance(value, torch.Tensor) and value.is_floating_point():
                setattr(obj, name, value.detach().clone().requires_grad_(True))
    return scene, objects


def _api_variant(objects, field: str, value):
    """Puts the API scene in one of its other forms (corpus.API_VARIANTS), valid or not, before
    a case's changes; returns the max_bounces it asks for (None: the case's default)."""
    import torch
    camera = objects["camera"]

    def leaf(x):
        return torch.tensor(x).requires_grad_(True)

    if field == "camera_type":
        camera.camera_type = value
        camera.aperture_radius, camera.focus_distance = leaf(0.05), leaf(3.0)
        camera.ortho_scale = leaf(1.5)
    elif field == "pixel_filter":
        camera.pixel_filter = value
        camera.filter_stddev, camera.filter_radius = leaf(0.6), leaf(1.2)
    elif field in ("crop_window", "resolution"):
        setattr(camera, field, tuple(value))
    elif field == "to_world":
        position, look_at, up = (x.detach() for x in camera.frame())
        z = torch.nn.functional.normalize(look_at - position, dim=0)
        x = torch.nn.functional.normalize(torch.linalg.cross(up, z), dim=0)
        y = torch.linalg.cross(z, x)
        axes = {"look_at": (x, y, z), "scaled": (2 * x, 2 * y, 2 * z), "mirrored": (-x, y, z),
                "singular": (x, x, z), "sheared": (x, y + 0.5 * x, z)}[value]
        matrix = torch.eye(4)
        matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = *axes, position
        camera.to_world = matrix.requires_grad_(True)
        camera.position = camera.look_at = camera.up = None
    elif field in ("floor_kind", "box_kind"):
        material = objects[field.replace("kind", "material")]
        material.kind = value
    elif field in ("two_sided", "nonlinear"):
        setattr(objects["floor_material"], field, value)
    elif field == "floor_normal_map":
        # None: the floor flat (its shading normal the geometric one: a planar mirror's or pane's)
        objects["floor_material"].normal_map = value
    elif field in ("max_bounces", "call"):
        return value
    return None


def _api_call(ep, scene, call: Optional[str], bounces: int):
    """Renders ``scene`` through entry point ``call`` (the API kind's corpus.API_VARIANTS["call"];
    None, as for every other kind: ``ep.render``); returns what the gradient is taken of."""
    import torch
    if call == "views":
        second = ep.Camera(position=torch.tensor([1., 1., 2.5]), look_at=torch.tensor([0., .3, 0.]),
                           fov=50.0, resolution=scene.camera.resolution)
        return ep.render(scene, spp=1, max_bounces=bounces, num_threads=1, seed=[0, 1],
                         cameras=[scene.camera, second])
    if call == "channels":
        channels = ep.render_channels(scene, ["radiance", "alpha", "depth", "position", "uv",
                                              "albedo", "mesh_id"], spp=1, max_bounces=bounces,
                                      num_threads=1)
        return sum((v.sum() for v in channels.values() if v.is_floating_point()), torch.zeros(()))
    if call == "derivative":
        vertices = scene.meshes[1].vertices
        direction = torch.ones(vertices.shape) if isinstance(vertices, torch.Tensor) else None
        return ep.derivative_image(scene, vertices, direction, spp=1, max_bounces=bounces,
                                   num_threads=1)
    options = dict(sampling="bsdf", backward_spp=2, backward_seed=3, edge_samples=64,
                   edge_sampling="uniform", hide_emitters=True, secondary_survival=0.5) \
        if call == "options" else {}
    return ep.render(scene, spp=1, max_bounces=bounces, num_threads=1, **options)


def _api_change(value, mutation: str, index: int):
    """``value`` (a tensor, or a float or tuple made one) changed as ``mutation`` says; None
    (a field the scene leaves unset) stays None."""
    import torch
    if value is None:
        return None
    t = value.detach() if isinstance(value, torch.Tensor) else \
        torch.tensor(value) if isinstance(value, (tuple, list)) else torch.tensor(float(value))

    def at(x, v):
        x = x.contiguous().clone()
        if x.numel():
            x.view(-1)[index % x.numel()] = v
        return x

    changes = {
        "nan": lambda: at(t.float(), float("nan")), "inf": lambda: at(t.float(), float("inf")),
        "-inf": lambda: at(t.float(), -float("inf")), "huge": lambda: t.float() * 1e30,
        "tiny": lambda: t.float() * 1e-30, "negate": lambda: ~t if t.dtype == torch.bool else -t,
        "zero": lambda: torch.zeros_like(t),
        "empty": lambda: t.reshape(-1)[:0] if t.dim() == 0 else t[:0], "float64": lambda: t.double(),
        "float16": lambda: t.half(), "int64": lambda: t.long(), "int32": lambda: t.int(),
        "bool": lambda: t.bool(), "unsqueeze": lambda: t.unsqueeze(0), "flatten": lambda: t.reshape(-1),
        "transpose": lambda: t.t() if t.dim() == 2 else t.flip(0) if t.dim() else t,
        "strided": lambda: torch.cat([t, t], 0)[::2] if t.dim() else t,
        "index_big": lambda: at(t, 10**6), "index_negative": lambda: at(t, -1),
        "index_2**40": lambda: at(t.long(), 2**40), "meta": lambda: torch.empty(t.shape, device="meta"),
        "first_value": lambda: t.reshape(-1)[0] if t.numel() else t,
        "expand": lambda: t.expand(3, *t.shape) if t.dim() < 4 else t,
        "coplanar": lambda: torch.cat([t[..., :-1], t[..., -1:].mean().expand(t[..., -1:].shape)], -1)
        if t.dim() and t.shape[-1] > 1 and t.is_floating_point() else t,
        "repeat_row": lambda: t[:1].expand(t.shape).clone() if t.dim() >= 2 and t.shape[0] else t,
        "offset_tiny": lambda: t.float() + 1e-30,
        # in range, at its edge: coordinates up to their 1e12 bound, subnormals
        "large": lambda: t.float() * 1e11, "one_large": lambda: at(t.float(), 9e11),
        "subnormal": lambda: at(t.float(), 1e-40),
        "permute": lambda: t[..., [t.shape[-1] - 1 - k for k in range(t.shape[-1])]] if t.dim() else t,
    }
    changed = changes[mutation]()
    # A float value the scene differentiates stays differentiable where it can.
    if isinstance(value, torch.Tensor) and value.requires_grad and changed.is_floating_point() \
            and changed.device.type == "cpu":
        changed = changed.detach().clone().requires_grad_(True)
    return changed


def _scales_by_1e30(path: str) -> bool:
    """Whether an API case's changes scale some value by 1e30."""
    with open(path) as f:
        return any(change.get("mutation") == "huge" for change in json.load(f))


def _scene_of(ep, kind: str, path: str):
    """Loads ``path`` with the loader of ``kind``; returns a small scene that uses what was
    loaded (or None when there is nothing to render), its max_bounces and the API kind's entry
    point (_api_call)."""
    import torch
    if kind == "api":
        scene, objects = _api_scene(ep)
        bounces, call = 2, None
        with open(path) as f:
            for change in json.load(f):
                if change["target"] == "variant":
                    asked = _api_variant(objects, change["field"], change["value"])
                    if change["field"] == "call":
                        call = asked
                    elif asked is not None:
                        bounces = asked
                    continue
                obj = objects[change["target"]]
                setattr(obj, change["field"], _api_change(getattr(obj, change["field"]),
                                                          change["mutation"], change["index"]))
        return scene, bounces, call
    if kind == "xml":
        loaded = ep.load_mitsuba(path)
        scene = loaded.scene
        scene.camera.resolution, scene.camera.crop_window = (6, 8), None
        return scene, min(loaded.max_bounces if loaded.max_bounces is not None else 2, 2), None
    if kind == "obj":
        meshes = ep.load_obj(path)
        if not meshes:
            return None, 0, None
    elif kind.startswith("ply"):
        meshes = [ep.load_ply(path)]
    else:
        image = ep.imread(path)
        rgb = image[:, :, :1].expand(-1, -1, 3) if image.shape[2] <= 2 else image[:, :, :3]
        rgb = rgb.contiguous()
        vertices, indices, uvs, normals = ep.shapes.sphere(rings=4, segments=6)
        mesh = ep.Mesh(vertices=vertices, indices=indices, uvs=uvs, normals=normals,
                       material=ep.Material(diffuse=rgb.clamp(0, 1)))
        camera = ep.Camera(position=torch.tensor([0.0, 0.0, 4.0]), look_at=torch.zeros(3),
                           fov=40.0, resolution=(6, 8))
        return ep.Scene(camera=camera, meshes=[mesh], envmap=ep.EnvironmentMap(values=rgb)), 1, None
    envmap = ep.EnvironmentMap(values=torch.ones(1, 1, 3))
    return ep.Scene(camera=_framing_camera(ep, meshes), meshes=meshes, envmap=envmap), 1, None


def _names_source(message: str, path: str) -> bool:
    """A loading error names the file (or, from an XML scene, the seed file it refers to)."""
    return os.path.basename(path) in message or "seed" in message


def _api_objects(scene) -> list:
    """The objects of an API scene that hold its values (camera, lights, meshes, materials)."""
    return [obj for obj in [scene.camera, scene.envmap, *scene.meshes,
                            *(m.material for m in scene.meshes), *scene.point_lights,
                            *(p.spot for p in scene.point_lights)] if obj is not None]


def _inputs_state(scene) -> Dict[str, tuple]:
    """What the caller gave an API scene: every CPU tensor's bytes, dtype, shape, version
    counter and requires_grad, by name."""
    import torch
    state = {}
    for k, obj in enumerate(_api_objects(scene)):
        for name, value in vars(obj).items():
            if isinstance(value, torch.Tensor) and value.device.type == "cpu":
                state[f"{type(obj).__name__}[{k}].{name}"] = (
                    value.detach().numpy().tobytes(),
                    value.dtype, tuple(value.shape), value._version, value.requires_grad)
    return state


def _modified(before: Dict[str, tuple], scene) -> List[str]:
    """The names of the inputs ``before`` (_inputs_state) that a call changed."""
    after = _inputs_state(scene)
    return [name for name, state in before.items() if after.get(name) != state]


# ---- the placed kind: the same scene elsewhere -------------------------------------------

# The values that are lengths: placed at scale s, their gradients are 1 / s of what they were.
# Point lights' intensities go with s^2 (their light falls off with the squared distance); the
# rest (directions, angles, materials, the environment) stays as it is.
_LENGTHS = ("vertices", "position", "look_at", "aperture_radius", "focus_distance", "ortho_scale")
# The values that are vectors in space (rows of three): rotated with the scene, their gradients
# rotate too, and are compared by their lengths.
_VECTORS = ("vertices", "normals", "position", "look_at", "up", "direction")


def _rotation(q) -> "torch.Tensor":
    """The rotation matrix (double) of the unit quaternion q = (w, x, y, z)."""
    import torch
    w, x, y, z = q
    return torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]],
                        dtype=torch.float64)


def _place(scene, scale: float, shift, rotation, cameras=()) -> None:
    """Moves the API scene to R x scale + shift (R: ``rotation``'s matrix; in double, then
    rounded to float): its points (vertices, the cameras' (the scene's and ``cameras``)
    position and look_at or matrix's translation, point lights), rotates its directions
    (normals, the cameras' up, their matrices' axes, spots, the environment), scales its other
    lengths, and point lights' intensities by scale^2: the same image."""
    import torch
    offset, turn = torch.tensor(shift, dtype=torch.float64), _rotation(rotation)

    def moved(value, power: int = 0, point: bool = False, vector: bool = False):
        if not isinstance(value, torch.Tensor):
            return value if value is None else value * scale ** power
        x = value.detach().double()
        if vector:
            x = (x.reshape(-1, 3) @ turn.T).reshape(x.shape)
        x = x * scale ** power + (offset if point else 0.0)
        return x.float().requires_grad_(value.requires_grad)

    for mesh in scene.meshes:
        mesh.vertices = moved(mesh.vertices, 1, True, True)
        mesh.normals = moved(mesh.normals, vector=True)
    for camera in [scene.camera, *cameras]:
        camera.position, camera.look_at = moved(camera.position, 1, True, True), moved(camera.look_at, 1, True, True)
        camera.up = moved(camera.up, vector=True)
        for name in ("aperture_radius", "focus_distance", "ortho_scale"):
            setattr(camera, name, moved(getattr(camera, name), 1))
        if camera.to_world is not None:
            matrix = camera.to_world.detach().double().clone()
            matrix[:3, :3] = turn @ matrix[:3, :3]
            matrix[:3, 3] = turn @ matrix[:3, 3] * scale + offset
            camera.to_world = matrix.float().requires_grad_(True)
    envmap = scene.envmap
    envmap.to_world = (turn @ envmap.to_world.detach().double()[:3, :3]).float().requires_grad_(True)
    for light in scene.point_lights:
        light.position, light.intensity = moved(light.position, 1, True, True), moved(light.intensity, 2)
        if light.spot is not None:
            light.spot.direction = moved(light.spot.direction, vector=True)


def _gradient_sums(scene, scale: float, cameras=()) -> Dict[str, float]:
    """Each of the API scene's values (and ``cameras``') with a gradient: its gradient's size,
    times scale to the power of its units (_LENGTHS): what it was before _place(scene, scale,
    ...). The size of a vector's (_VECTORS) or a matrix column's gradient is its length, which
    a rotation keeps; of anything else, its |gradient| summed."""
    import torch
    sums = {}
    for k, obj in enumerate(_api_objects(scene) + list(cameras)):
        for name, value in vars(obj).items():
            if not isinstance(value, torch.Tensor) or value.grad is None:
                continue
            g, label = value.grad.double(), f"{type(obj).__name__}[{k}].{name}"
            if name == "to_world":  # columns: axes, and the camera's translation (a point)
                sums[label + "[:3, :3]"] = float(g[:3, :3].norm(dim=0).sum())
                if obj is scene.camera or any(obj is c for c in cameras):
                    sums[label + "[:3, 3]"] = float(g[:3, 3].norm()) * scale
                continue
            size = g.reshape(-1, 3).norm(dim=1).sum() if name in _VECTORS else g.abs().sum()
            power = 1 if name in _LENGTHS else 2 if name == "intensity" else 0
            sums[label] = float(size) * scale ** power
    return sums


Sums = Tuple[Dict[str, float], Dict[str, float]]  # (named sums of what was rendered, _gradient_sums)


def _inconsistencies(base: Sums, moved: Sums, others: List[Sums]) -> List[str]:
    """What differs between the (image sums, _gradient_sums) of a scene and of the same scene
    placed elsewhere, with the same random numbers: an image sum (_placed_render's: an image's,
    a view's, a channel's, a derivative image's) beyond 2% plus five times its noise; a gradient
    sum beyond a tenth of itself plus five times its noise, where that noise
    is at most a fifth of its mean. Noise: the standard deviation over ``base`` and ``others``
    (the same of other seeds where the scene was). Paths that round differently where the scene
    is placed, and a turned scene's paths, are other draws; a value whose noise is larger (a
    camera's one aperture radius, its up vector) is not compared (kinks, where rounding picks
    the derivative from one side, _placed_case keeps out of view). Tails still make
    about one case in a thousand a false lead (a normal map's gradient twice its mean at 16
    spp): rerun such a case with more seeds."""
    (base_sums, base_grads), (moved_sums, moved_grads) = base, moved
    others_sums = [sums for _, sums in others]

    def sigma(draws: List[float]) -> float:
        mean = sum(draws) / len(draws)
        return math.sqrt(sum((x - mean) ** 2 for x in draws) / (len(draws) - 1))

    off = []
    for name, base_sum in base_sums.items():
        moved_sum, image_draws = moved_sums[name], [base_sum] + [o[name] for o, _ in others]
        if abs(moved_sum - base_sum) > 0.02 * abs(base_sum) + 5 * sigma(image_draws):
            off.append(f"{name} sum {moved_sum:.6g} against {base_sum:.6g} (other seeds: "
                       f"{', '.join(f'{x:.6g}' for x in image_draws[1:])})")
    for name, b in sorted(base_grads.items()):
        m = moved_grads.get(name, 0.0)
        draws = [b] + [other.get(name, 0.0) for other in others_sums]
        mean, spread = sum(draws) / len(draws), sigma(draws)
        if mean > 1e-6 and spread <= 0.2 * mean and abs(m - b) > 0.1 * b + 5 * spread:
            off.append(f"{name}: {m:.4g} against {b:.4g} (other seeds: {', '.join(f'{x:.4g}' for x in draws[1:])})")
    return off


# The renders where the scene is (seeds 3, 4, ...) whose spread is a value's noise: with four,
# a value whose noise is two fifths of its mean (the floor's uvs, through its normal map) once
# came out within a twentieth on all four, and the placed render, another draw, 5 "sigma" off.
_NOISE_SEEDS = 8

# Point lights' intensities placed at scale s are s^2 times theirs: within the radiance bound
# (1e16) for scales up to 1e7, beyond which the placed kind leaves the point lights out.
_POINT_LIGHT_SCALE = 1e7


def _placed_render(ep, scene, call: Optional[str], bounces: int, seed: int, scale: float,
                   turn: "torch.Tensor", second) -> Tuple[Dict[str, float], Optional["torch.Tensor"]]:
    """Renders the placed kind's ``scene`` (placed at ``scale``, turned by ``turn``) through
    entry point ``call`` (corpus.PLACED_VARIANTS["call"]; None: ``ep.render``): the named sums
    of what it returns, each what it was before the scene was placed, and the loss to take the
    gradient of (None: a derivative image, which has none). Two views: the scene's camera and
    ``second``. Channels: radiance, alpha, uv and albedo as they are, depth over the scale, the
    shading normals along a fixed direction turned with the scene."""
    import torch
    options = dict(max_bounces=bounces, num_threads=1)
    if call == "views":
        images = ep.render(scene, spp=16, seed=[seed, seed + 100], cameras=[scene.camera, second], **options)
        return {"view 0": float(images[0].detach().double().sum()),
                "view 1": float(images[1].detach().double().sum())}, images.sum()
    if call == "channels":
        channels = ep.render_channels(scene, ["radiance", "alpha", "depth", "uv", "albedo", "shading_normal"],
                                      spp=16, seed=seed, **options)
        along = (turn @ torch.tensor([0.48, 0.6, 0.64], dtype=torch.float64)).float()
        parts = {name: channels[name].sum() for name in ("radiance", "alpha", "uv", "albedo")}
        parts["depth"] = channels["depth"].sum() / scale
        parts["shading_normal"] = (channels["shading_normal"].reshape(-1, 3) @ along).sum()
        return {name: float(v.detach()) for name, v in parts.items()}, sum(parts.values())
    if call == "derivative":
        # The box moving along a fixed direction (turned with the scene), per unit length.
        vertices = scene.meshes[1].vertices
        along = (turn @ torch.tensor([0.36, 0.48, 0.8], dtype=torch.float64)).float()
        d_image = ep.derivative_image(scene, vertices, along.expand(vertices.shape), spp=16, seed=seed,
                                      **options).double() * scale
        return {"derivative": float(d_image.sum()), "|derivative|": float(d_image.abs().sum())}, None
    image = ep.render(scene, spp=16, seed=seed, **options)
    return {"image": float(image.detach().double().sum())}, image.sum()


def api_scene_in_forms(ep, forms):
    """The API scene (_api_scene) in its valid forms `forms` (corpus.PLACED_VARIANTS' pairs), at
    12 x 16, looking along no axis: (scene, objects, max_bounces, entry point or None). Also
    tests/fuzz/truth.py's scene."""
    import torch
    scene, objects = _api_scene(ep)
    # Looking along no axis: an orthographic camera looking down the plane x = 0 sees the
    # box's sides edge-on, where a vertex moving either way has a derivative of its own
    # (the side turns towards or away from it), and rounding picks one.
    camera = objects["camera"]
    camera.look_at = (camera.look_at.detach() + torch.tensor([0.0173, 0.0, 0.0071])).requires_grad_(True)
    bounces, call = 2, None
    for field, value in forms:
        if field == "call":
            call = value
            continue
        asked = _api_variant(objects, field, value)
        bounces = bounces if asked is None else asked
    camera.resolution = (12, 16)
    return scene, objects, bounces, call


def _placed_case(ep, path: str) -> Tuple[str, str]:
    """A placed case (corpus.place_api): the API scene in its forms rendered (_placed_render)
    with a gradient of everything where it is (seed 3, and the next for the noise:
    _NOISE_SEEDS in all) and placed (seed 3); (outcome, detail)."""
    import torch
    with open(path) as f:
        case = json.load(f)
    renders = []
    here = (1.0, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
    there = (case["scale"], case["shift"], case.get("rotation", here[2]))
    for (scale, shift, rotation), seed in [(here, seed) for seed in range(3, 3 + _NOISE_SEEDS)] + [(there, 3)]:
        scene, objects, bounces, call = api_scene_in_forms(ep, case["variants"])
        scene.envmap.to_world = torch.eye(3).requires_grad_(True)  # rotated with the scene
        second = ep.Camera(position=torch.tensor([1., 1., 2.5]), look_at=torch.tensor([0.0173, .3, 0.0071]),
                           up=torch.tensor([0., 1., 0.]), fov=50.0, resolution=(12, 16))
        second.position.requires_grad_(True)
        if case["scale"] > _POINT_LIGHT_SCALE:
            scene.point_lights = []
        placed = (scale, shift, rotation) != here
        if placed:
            _place(scene, scale, shift, rotation, cameras=[second])
        try:
            image_sums, loss = _placed_render(ep, scene, call, bounces, seed, scale, _rotation(rotation), second)
        except ValueError as error:
            if placed:
                return "inconsistent", f"refused where placed: {error}"
            raise
        if loss is not None:
            loss.backward()
        sums = _gradient_sums(scene, scale, [second] if call == "views" else [])
        if not all(math.isfinite(v) for v in [*image_sums.values(), *sums.values()]):
            return "nonfinite", f"at scale {scale:g}: sums {image_sums}, gradients {sums}"
        renders.append((image_sums, sums))
    base, *others, moved = renders
    off = _inconsistencies(base, moved, others)
    if off:
        return "inconsistent", "; ".join(off)
    return "ok", "the same image and gradients, sums " + ", ".join(f"{k} {v:.6g}" for k, v in base[0].items())


def run_case(kind: str, path: str, report=lambda note: None) -> Tuple[str, str]:
    """Runs one case in this process: (outcome, detail). Only ``run_batch``'s children call it;
    ``report`` gets a note before the render (the detail if the render kills the process)."""
    import edgepath as ep
    import edgepath.shapes  # noqa: F401  (ep.shapes)
    stage, before = "load", None
    try:
        if kind == "placed":
            stage = "render"
            report("rendering")
            return _placed_case(ep, path)
        scene, bounces, call = _scene_of(ep, kind, path)
        if scene is None:
            return "ok", "nothing to render"
        stage = "render"
        report("rendering")
        if kind != "api":
            for mesh in scene.meshes:
                mesh.vertices.requires_grad_(True)
        before = _inputs_state(scene) if kind == "api" else None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            image = _api_call(ep, scene, call, bounces)
            if image.requires_grad:  # not a derivative image
                image.sum().backward()
        if kind == "api":
            import torch
            modified = _modified(before, scene)
            if modified:
                return "modified", f"rendered, and changed the caller's {modified}"
            leaves = [(name, value) for obj in _api_objects(scene) for name, value in vars(obj).items()
                      if isinstance(value, torch.Tensor) and value.grad is not None]
            # A half-precision parameter gets its gradient in half precision, which overflows
            # where float32 does not (as with torch's own operations): there, only NaN counts.
            bad = [name for name, value in leaves
                   if not bool((~torch.isnan(value.grad) if value.dtype == torch.float16
                                else torch.isfinite(value.grad)).all())]
            # Values scaled by 1e30 are in range where nothing bounds them (reflectances, uvs),
            # and the gradients of such a scene may overflow float32: then the overflow must have
            # been warned of (render.py: _check_gradients). Elsewhere Inf or NaN is a bug.
            warned = [str(w.message) for w in caught if "float32 overflowed" in str(w.message)]
            image_finite = bool(torch.isfinite(image).all())
            if bad and warned and image_finite and _scales_by_1e30(path):
                return "ok", f"rendered; the gradients of {bad} overflowed, warned of: {warned[0][:200]}"
            if not image_finite or bad:
                return "nonfinite", f"image finite: {image_finite}; gradients of {bad}"
        return "ok", f"rendered, sum {float(image.detach().sum()):.6g}"
    except (ValueError, OSError) as error:
        message = f"{stage}: {type(error).__name__}: {error}"
        modified = _modified(before, scene) if stage == "render" and before is not None else []
        if modified:
            return "modified", f"{message}; and changed the caller's {modified}"
        named = _names_source(str(error), path) if stage == "load" else ":" in str(error)
        return ("error" if named else "unnamed"), message
    except Exception as error:  # noqa: BLE001  (classifying is the point)
        return "unexpected", f"{stage}: " + "".join(
            traceback.format_exception(type(error), error, error.__traceback__))[-2000:]


def _child(cases: List[Tuple[str, str]], write_fd: int, memory_limit: int) -> None:
    code = 0
    try:
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        mapped = _mapped_bytes()
        resource.setrlimit(resource.RLIMIT_AS, (mapped + memory_limit, mapped + memory_limit))
        os.environ["OMP_NUM_THREADS"] = "1"
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)  # warnings (e.g. wrap modes) are fine; tracebacks are caught

        def send(answer):
            os.write(write_fd, (json.dumps(answer) + "\n").encode())

        for kind, path in cases:
            outcome, detail = run_case(kind, path, lambda note: send({"note": note}))
            send({"outcome": outcome, "detail": detail})
    except BaseException:  # noqa: BLE001  (nothing may escape a forked child)
        code = 3
    finally:
        os._exit(code)


def _mapped_bytes() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def run_batch(cases: List[Tuple[str, str]], time_limit: float = TIME_LIMIT,
              memory_limit: int = MEMORY_LIMIT) -> List[Tuple[str, str]]:
    """Runs cases (kind, path) in forked children, one after the other in the same child
    (a fork costs more than most cases) until one kills it or hangs: ``time_limit`` seconds of
    CPU time on one case, or IDLE_FACTOR times that in wall time (wall time alone where the
    CPU time is unknown); a new child goes on with the next. Returns (outcome, detail) per
    case."""
    results: List[Tuple[str, str]] = []
    while len(results) < len(cases):
        read_fd, write_fd = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(read_fd)
            _child(cases[len(results):], write_fd, memory_limit)
        os.close(write_fd)
        buffer, note, hang = b"", "", ""
        # Where the current case started, in wall time and in the child's CPU time.
        started, cpu_started = time.monotonic(), cpu_seconds(pid)
        try:
            while True:
                waited = time.monotonic() - started
                cpu = cpu_seconds(pid)
                if cpu is not None and cpu_started is not None:
                    if cpu - cpu_started > time_limit:
                        hang = f"no answer after {time_limit:g} s of CPU time"
                    elif waited > IDLE_FACTOR * time_limit:
                        hang = f"no answer in {IDLE_FACTOR * time_limit:g} s ({cpu - cpu_started:.1f} s of CPU time)"
                elif waited > time_limit:
                    hang = f"no answer in {time_limit:g} s"
                if hang:
                    os.kill(pid, signal.SIGKILL)
                    break
                ready, _, _ = select.select([read_fd], [], [], min(0.1, max(time_limit - waited, 0.01)))
                if not ready:
                    continue
                chunk = os.read(read_fd, 1 << 16)
                if not chunk:
                    break
                buffer += chunk
                *lines, buffer = buffer.split(b"\n")
                for line in lines:
                    answer = json.loads(line)
                    if "note" in answer:
                        note += f" while {answer['note']}"
                    else:
                        results.append((answer["outcome"], answer["detail"]))
                        note, started, cpu_started = "", time.monotonic(), cpu_seconds(pid)
        finally:
            os.close(read_fd)
            _, status = os.waitpid(pid, 0)
        if len(results) < len(cases):  # the child died in (or hung on) the next case
            if hang:
                results.append(("hang", hang + note))
            elif os.WIFSIGNALED(status):
                results.append(("signal", f"killed by {signal.Signals(os.WTERMSIG(status)).name}{note}"))
            else:
                results.append(("signal", f"exit status {os.WEXITSTATUS(status)} without an answer{note}"))
    return results


def _prepare_driver() -> None:
    """Imports what the children use, once, before any fork; one thread everywhere."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch
    torch.set_num_threads(1)
    import edgepath  # noqa: F401
    import edgepath.shapes  # noqa: F401


# ---- the driver ------------------------------------------------------------------------------

def make_case(seeds: Dict[str, List[str]], seed_dir: str, seed: int, i: int,
              kinds: List[str]) -> Tuple[str, bytes, List[str]]:
    """Case ``i``: its loader (round robin over ``kinds``), its bytes, its mutations."""
    rng = random.Random(f"{seed}:{i}")
    kind = kinds[i % len(kinds)]
    with open(os.path.join(seed_dir, rng.choice(seeds[kind])), "rb") as f:
        data = f.read()
    data, names = corpus.mutate(kind, data, rng)
    return kind, data, names


BATCH = 25  # cases per batch of files (and at most per child)


def fuzz(cases: int, seed: int, kinds: List[str], save: Optional[str], log=None,
         time_limit: float = TIME_LIMIT, start: int = 0, quiet: bool = False) -> Dict:
    _prepare_driver()
    counts: Dict[str, Counter] = defaultdict(Counter)
    work = tempfile.mkdtemp(prefix="edgepath-fuzz-")
    try:
        seed_dir = os.path.join(work, "seeds")
        os.mkdir(seed_dir)
        seeds = corpus.write_seeds(seed_dir)
        began = time.monotonic()
        done = 0
        for first in range(start, start + cases, BATCH):
            numbers = range(first, min(first + BATCH, start + cases))
            # The XML seed refers to the other seeds: each batch runs beside fresh copies.
            case_dir = os.path.join(work, "case")
            shutil.rmtree(case_dir, ignore_errors=True)
            shutil.copytree(seed_dir, case_dir)
            batch = []
            for i in numbers:
                kind, data, names = make_case(seeds, seed_dir, seed, i, kinds)
                path = os.path.join(case_dir, f"{kind}-{seed}-{i}{corpus.KINDS[kind]}")
                with open(path, "wb") as f:
                    f.write(data)
                batch.append((i, kind, path, names))
            results = run_batch([(kind, path) for _, kind, path, _ in batch], time_limit)
            for (i, kind, path, names), (outcome, detail) in zip(batch, results):
                counts[kind][outcome] += 1
                if log is not None:
                    log.write(json.dumps({"case": i, "seed": seed, "kind": kind,
                                          "mutations": names, "outcome": outcome,
                                          "detail": detail[-800:]}) + "\n")
                if outcome in BAD or outcome == "unnamed":
                    if not quiet:
                        print(f"case {i} ({kind}, {'+'.join(names)}): {outcome}: {detail[-300:]}",
                              file=sys.stderr)
                    if save and outcome in BAD:
                        os.makedirs(save, exist_ok=True)
                        shutil.copy(path, os.path.join(save, os.path.basename(path)))
            if log is not None:
                log.flush()
            done += len(batch)
            if not quiet and done % 500 < BATCH:
                print(f"{done}/{cases} cases, {time.monotonic() - began:.0f} s",
                      file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return counts


def replay(directory: str, time_limit: float = TIME_LIMIT) -> Dict[str, Tuple[str, str]]:
    """Runs every regression file of ``directory`` (beside a copy of the seeds, which XML
    files may refer to): {file name: (outcome, detail)}."""
    _prepare_driver()
    results = {}
    work = tempfile.mkdtemp(prefix="edgepath-fuzz-")
    try:
        corpus.write_seeds(work)
        for name in sorted(os.listdir(directory)):
            if name.startswith(".") or name.endswith((".md", ".txt")):
                continue
            path = os.path.join(work, name)
            shutil.copy(os.path.join(directory, name), path)
            results[name] = run_batch([(kind_of(name), path)], time_limit)[0]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return results


def print_table(counts: Dict[str, Counter], out=sys.stdout) -> None:
    width = max(len(o) for o in OUTCOMES) + 2
    print(f"{'loader':<11}" + "".join(f"{o:>{width}}" for o in OUTCOMES) + f"{'total':>8}", file=out)
    total = Counter()
    for kind in corpus.KINDS:
        if kind in counts:
            c = counts[kind]
            total.update(c)
            print(f"{kind:<11}" + "".join(f"{c[o]:>{width}}" for o in OUTCOMES) +
                  f"{sum(c.values()):>8}", file=out)
    print(f"{'all':<11}" + "".join(f"{total[o]:>{width}}" for o in OUTCOMES) +
          f"{sum(total.values()):>8}", file=out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=1000, help="number of cases (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the mutations (default 0)")
    parser.add_argument("--start", type=int, default=0, help="first case number (default 0)")
    parser.add_argument("--kinds", default=",".join(corpus.KINDS),
                        help=f"loaders, comma-separated (default all: {','.join(corpus.KINDS)})")
    parser.add_argument("--save", metavar="DIR", help="copy inputs that crash, hang or raise "
                                                      "unexpectedly into DIR")
    parser.add_argument("--log", metavar="FILE", help="one JSON line per case")
    parser.add_argument("--time-limit", type=float, default=TIME_LIMIT,
                        help=f"seconds of CPU time per case before it counts as a hang (default "
                             f"{TIME_LIMIT:g}; {IDLE_FACTOR:g} times that in wall time for a case that "
                             f"waits)")
    parser.add_argument("--replay", metavar="DIR", help="run the files of DIR instead")
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args(argv)
    if args.replay:
        results = replay(args.replay, args.time_limit)
        for name, (outcome, detail) in results.items():
            print(f"{name}: {outcome}: {detail[-300:]}")
        return 1 if any(o in BAD for o, _ in results.values()) else 0
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    unknown = [k for k in kinds if k not in corpus.KINDS]
    if unknown or not kinds:
        parser.error(f"--kinds: unknown {unknown}; choose from {', '.join(corpus.KINDS)}")
    log = open(args.log, "a") if args.log else None
    try:
        counts = fuzz(args.cases, args.seed, kinds, args.save, log, args.time_limit, args.start,
                      args.quiet)
    finally:
        if log:
            log.close()
    print(f"seed {args.seed}, cases {args.start}..{args.start + args.cases - 1}")
    print_table(counts)
    return 1 if any(c[o] for c in counts.values() for o in BAD) else 0


if __name__ == "__main__":
    sys.exit(main())
