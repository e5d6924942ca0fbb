"""Rendering and its derivatives: check and flatten a Scene into the core's plain description,
call the core, and connect it to autograd.

``flatten_scene`` validates the scene and converts every tensor the core reads with
differentiable torch ops (dtype, layout, constants to 1x1 textures, the camera's parameters
gathered into one vector), so that ``FlatScene.params`` lists, per gradient slot of the core,
a float32 tensor still attached to the caller's tensors. ``render`` wraps the core in a
``torch.autograd.Function`` whose inputs are those tensors: autograd carries the core's
gradients back to whatever the user differentiates (vertices, a camera matrix, a float64
colour, ...). ``derivative_image`` does the same in forward mode, with torch's forward-mode AD
turning a direction on the user's tensor into directions on the core's slots.
"""

from __future__ import annotations

import re
import threading
import warnings
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple, Union

import torch
import torch.autograd.forward_ad as fwad

from . import _core
from . import _validate as v
from .scene import (Camera, EnvironmentMap, Material, Mesh, PointLight, Scene, Spot,
                    frame_from_to_world)

SAMPLING = {"mis": 0, "light": 1, "bsdf": 2}
EDGE_SAMPLING = {"importance": 0, "uniform": 1}
CAMERA_TYPES = {"perspective": 0, "orthographic": 1, "thinlens": 2, "fisheye": 3, "panorama": 4}
PIXEL_FILTERS = {"box": 0, "gaussian": 1, "tent": 2}
MATERIAL_KINDS = {"standard": 0, "conductor": 1, "dielectric": 2, "plastic": 3}
LIGHT_SAMPLING = {"area": 0, "solid_angle": 1, "spherical_triangle": 2}
MAX_EDGE_SAMPLES = 2**62  # the core's bound (chunked int64 sample indices)
MAX_PIXELS = 2**31 - 1  # the core's bound on the film's pixel count

# A gradient slot of the core: ("camera",), ("envmap",), ("envmap_rotation",),
# ("meshes", i, "vertices" | "uvs" | "normals" | "emission" | "colors"),
# ("materials", i, "diffuse" | "specular" | "roughness" | "ior" | "normal_map"),
# ("meshes", i, "spot_profile"), ("point_lights", i, "position" | "intensity" | "spot_profile").
Slot = Tuple


@dataclass
class FlatScene:
    """A validated scene in the form the core takes: dicts of numbers and detached float32 /
    int32 C-contiguous CPU tensors (views of the caller's tensors where no conversion was
    needed). ``params`` maps each differentiable slot to the same values as a tensor attached
    to the caller's tensors. ``materials[i]`` belongs to ``meshes[i]``."""
    camera: dict
    materials: List[dict] = field(default_factory=list)
    meshes: List[dict] = field(default_factory=list)
    envmap: Optional[dict] = None
    point_lights: List[dict] = field(default_factory=list)
    height: int = 0  # size of the rendered image (the crop window if one is set)
    width: int = 0
    params: Dict[Slot, torch.Tensor] = field(default_factory=dict)
    cache: Optional[object] = None  # the scene's _core.SceneCache (kept across calls)

    def core_args(self):
        return self.camera, self.materials, self.meshes, self.envmap

    def named_tensors(self) -> List[Tuple[str, torch.Tensor]]:
        """Every tensor the core reads, with the field it came from (views of the caller's
        tensors where no conversion was needed, so they share their version counters)."""
        out = []
        for i, (mesh, material) in enumerate(zip(self.meshes, self.materials)):
            out += [(f"meshes[{i}].{k}", t) for k, t in mesh.items() if isinstance(t, torch.Tensor)]
            out += [(f"meshes[{i}].material.{k}", t) for k, t in material.items()
                    if isinstance(t, torch.Tensor)]
        if self.envmap is not None:
            out.append(("envmap.values", self.envmap["values"]))
        return out

    def slot_buffers(self, buffers: Dict[Slot, torch.Tensor]) -> dict:
        """The core's nested description of gradient slots, from {slot: float32 tensor}."""
        out: dict = {}
        for slot, t in buffers.items():
            if len(slot) == 1:
                out[slot[0]] = t
            else:
                group, i, name = slot
                lst = out.setdefault(group, [None] * len(getattr(self, group)))
                if lst[i] is None:
                    lst[i] = {}
                lst[i][name] = t
        return out


@dataclass
class RenderOptions:
    spp: int = 16
    max_bounces: int = 1
    seed: int = 0
    num_threads: int = 0  # 0: all cores
    sampling: int = 0
    primary_edges: bool = True
    secondary_edges: bool = True
    edge_samples: int = 0  # 0: one per output pixel per spp
    edge_sampling: int = 0
    hide_emitters: bool = False
    secondary_survival: Optional[float] = None  # None: the core's default
    # The image's paths are those a gradient pass (or a derivative image) with the same seed
    # retraces. False for an image whose paths no gradient pass retraces (none follows it, or
    # its gradient pass has a seed of its own): the environment is then sampled by its light
    # above its mean, a uniform sky not at all (docs/conventions.md, "How lights are sampled"),
    # and the rays trace the BVH built for images alone.
    replayable: bool = True
    # Many views: a seed per view (``seed`` is the first), or None: every view takes ``seed``.
    view_seeds: Optional[List[int]] = None

    def core(self) -> dict:
        out = {"spp": self.spp, "max_bounces": self.max_bounces, "seed": self.seed,
               "num_threads": self.num_threads, "sampling": self.sampling,
               "primary_edges": self.primary_edges, "secondary_edges": self.secondary_edges,
               "edge_samples": self.edge_samples, "edge_sampling": self.edge_sampling,
               "hide_emitters": self.hide_emitters, "replayable": self.replayable}
        if self.secondary_survival is not None:
            out["secondary_survival"] = self.secondary_survival
        if self.view_seeds is not None:
            out["view_seeds"] = list(self.view_seeds)
        return out


def render(scene: Scene, spp: int = 16, max_bounces: int = 1, seed: Union[int, Sequence[int]] = 0,
           num_threads: Optional[int] = None, sampling: str = "mis",
           backward_spp: Optional[int] = None,
           backward_seed: Union[None, int, Sequence[int]] = None, primary_edges: bool = True,
           secondary_edges: bool = True, edge_samples: Optional[int] = None,
           edge_sampling: str = "importance", hide_emitters: bool = False,
           cameras: Optional[Sequence[Camera]] = None,
           secondary_survival: Optional[float] = None) -> torch.Tensor:
    """Renders ``scene`` and returns a float32 (H, W, 3) tensor of linear radiance, row 0 at
    the top (H, W: the crop window's size if the camera has one).

    ``spp``: samples per pixel; ``max_bounces``: scattering events per path (0: emitters
    seen directly, 1: direct lighting, ...); ``seed`` fixes the image bit for bit whatever
    ``num_threads`` (None: all cores); ``sampling``: "mis", "light" or "bsdf" (direct light
    by multiple importance sampling, by light sampling only, or by BSDF sampling only).

    Differentiable: if a scene tensor requires grad, ``loss.backward()`` runs the gradient pass
    with ``backward_spp`` samples per pixel (default: ``spp``). Its random numbers are
    independent of the image's by default (an unbiased gradient of the expected image), and the
    image is then the one rendered without a gradient, bit for bit; ``backward_seed=seed`` makes
    the pass differentiate exactly the paths of the returned image. (An image whose paths no
    gradient pass retraces, with ``sampling="mis"``, samples the environment by its light above
    its mean, and a uniform sky not at all, where the gradient pass samples its whole radiance:
    other paths, less noise; docs/conventions.md. With ``backward_seed=seed`` the image samples
    it as the pass does.)
    The gradient includes the boundary terms of edges that move (edge sampling):
    ``primary_edges`` (silhouettes seen by the camera) and ``secondary_edges`` (seen from
    shading points: shadows, reflections, indirect light) switch them off for speed or
    comparison; ``edge_samples`` is the number of
    primary edge samples (default: one per output pixel per backward sample);
    ``edge_sampling``: "importance" (primary: silhouettes by clipped film length, stratified;
    secondary: the edge hierarchy, with a second sample towards the lights) or "uniform" (every
    edge by world length: the baseline, for comparison). ``hide_emitters``: as Mitsuba's
    integrators' ``hide_emitters``, area lights are transparent to camera rays and the
    environment seen directly is black; seen after a bounce both stay (the gradient follows).
    ``secondary_survival`` (in (0, 1]; None: the default, 1): below 1, the gradient pass
    samples the secondary edges' term at a path vertex with a probability set per mesh and depth
    by a small pilot pass, no lower than this, and divides it by that probability (unbiased);
    1 samples it at every vertex (see docs/gradients.md, "Roulette by class").

    Many views: with ``cameras`` (a list of ``Camera`` of one film size), renders the scene once
    per camera (``scene.camera`` is not used) and returns (V, H, W, 3), view k exactly the image
    ``render`` gives with ``scene.camera = cameras[k]`` and the same options; the scene is built
    once for all of them, and the backward pass is one core call that sums the scene's
    gradients over the views. Each camera's parameters are differentiable as ``scene.camera``'s
    are. ``seed`` (and ``backward_seed``) may then be a list of one seed per view: view k is
    rendered (and differentiated) with ``seed[k]`` (``backward_seed[k]``; by default a seed
    derived from ``seed[k]`` as for one view), so that views alike up to a symmetry of the scene
    do not share their noise; an integer gives every view the same seed.

    The core scene (the ray-tracing BVH, the edge list) is kept on ``scene`` across calls and
    updated from what changed: nothing is rebuilt when only materials, lights, textures, the
    environment or the camera change, the BVH is refitted when only vertices move, and rebuilt
    when the topology does (``Scene.build_counts`` counts them)."""
    view_seeds = grad_view_seeds = None
    if cameras is not None:
        flat, views, view_params = _flatten_views(scene, cameras)
        view_seeds = _view_seeds(seed, "seed", len(views))
        grad_view_seeds = _view_seeds(backward_seed, "backward_seed", len(views))
    else:
        for value, name in ((seed, "seed"), (backward_seed, "backward_seed")):
            if isinstance(value, (list, tuple)):
                v.fail(name, "a list of seeds (one per view) needs cameras=[...]")
        flat = flatten_scene(scene)
    options = render_options(spp, max_bounces, seed if view_seeds is None else view_seeds[0], num_threads,
                             sampling, primary_edges, secondary_edges, edge_samples, edge_sampling,
                             hide_emitters, secondary_survival)
    options.view_seeds = view_seeds
    attached = [(slot, t) for slot, t in flat.params.items() if t.requires_grad]
    attached_views = [] if cameras is None else [(k, t) for k, t in enumerate(view_params) if t.requires_grad]
    if (not attached and not attached_views) or not torch.is_grad_enabled():
        options.replayable = False  # an image alone
        if cameras is not None:
            return render_views_flat(flat, views, options)
        image, _ = render_flat(flat, options)
        return image
    if backward_seed is None and view_seeds is not None:
        grad_view_seeds = [_backward_seed(s) for s in view_seeds]
    if grad_view_seeds is not None:
        backward_seed = grad_view_seeds[0]
    grad_options = render_options(spp if backward_spp is None else backward_spp, max_bounces,
                                  _backward_seed(options.seed) if backward_seed is None else backward_seed,
                                  num_threads, sampling, primary_edges, secondary_edges,
                                  edge_samples, edge_sampling, hide_emitters, secondary_survival)
    grad_options.view_seeds = grad_view_seeds
    options.replayable = _retraced(options, grad_options, None if cameras is None else len(views))
    slots = [slot for slot, _ in attached]
    if cameras is not None:
        return _RenderViewsFunction.apply(flat, views, options, grad_options, slots,
                                          [k for k, _ in attached_views],
                                          *[t for _, t in attached + attached_views])
    return _RenderFunction.apply(flat, options, grad_options, slots, *[t for _, t in attached])


def _flatten_views(scene: Scene, cameras) -> Tuple[FlatScene, List[dict], List[torch.Tensor]]:
    """The flat scene seen by cameras[0] (without a camera slot: each view's is apart), the
    cameras' core descriptions and their attached parameter vectors."""
    if not isinstance(cameras, (list, tuple)) or len(cameras) == 0:
        v.fail("cameras", f"expected a non-empty list of edgepath.Camera, got {cameras!r}")
    views, params, size = [], [], None
    for k, camera in enumerate(cameras):
        one = FlatScene(camera={})
        try:
            _flatten_camera(camera, one)
        except ValueError as error:
            raise ValueError(re.sub(r"^camera\b", f"cameras[{k}]", str(error))) from None
        crop = one.camera["crop_window"]
        film = (one.camera["height"], one.camera["width"], crop)
        if size is not None and film != size:
            v.fail(f"cameras[{k}].resolution", f"film {film[:2]} with crop window {film[2]} differs from "
                                              f"cameras[0]'s {size[:2]} with {size[2]}: the views "
                                              "of one call share one film size")
        size = film
        views.append(one.camera)
        params.append(one.params[("camera",)])
    if not isinstance(scene, Scene):
        v.fail("scene", f"expected an edgepath.Scene, got {type(scene).__name__}")
    flat = flatten_scene(Scene(cameras[0], scene.meshes, scene.envmap,
                               getattr(scene, "point_lights", ())))
    del flat.params[("camera",)]
    flat.cache = _scene_cache(scene)
    return flat, views, params


def render_views_flat(flat: FlatScene, views: List[dict], options: RenderOptions) -> torch.Tensor:
    """One call into the core for every view: (V, H, W, 3)."""
    images = torch.empty((len(views), flat.height, flat.width, 3), dtype=torch.float32)
    _call_core(_core.render_views, views, *flat.core_args()[1:], images, options.core(), flat=flat)
    _check_finite(images, "the rendered images")
    return images


class _RenderViewsFunction(torch.autograd.Function):
    """As _RenderFunction for many views. Inputs after the flat scene, the views' cameras and
    the options: the scene's slots needing gradients, the indices of the views whose camera
    needs them, then the tracked tensors of both, in that order."""

    @staticmethod
    def forward(ctx, flat, views, options, grad_options, slots, view_indices, *tensors):
        images = render_views_flat(flat, views, options)
        _save_inputs(ctx, flat, tensors)
        ctx.flat, ctx.views, ctx.grad_options = flat, views, grad_options
        ctx.slots, ctx.view_indices = slots, view_indices
        return images

    @staticmethod
    def backward(ctx, grad_images):
        flat, n = ctx.flat, len(ctx.slots)
        _check_saved_inputs(ctx)
        needed = ctx.needs_input_grad[6:]
        buffers = {slot: torch.zeros(flat.params[slot].shape, dtype=torch.float32)
                   for slot, need in zip(ctx.slots, needed[:n]) if need}
        camera_grads = [None] * len(ctx.views)
        for k, need, t in zip(ctx.view_indices, needed[n:], ctx.saved_tensors[n:]):
            if need:
                camera_grads[k] = torch.zeros(t.shape, dtype=torch.float32)
        if buffers or any(g is not None for g in camera_grads):
            adjoint = grad_images.detach().to(torch.float32).contiguous()
            _call_core(_core.render_views_gradients, ctx.views, *flat.core_args()[1:], adjoint,
                       flat.slot_buffers(buffers), camera_grads, ctx.grad_options.core(),
                       flat=flat)
            _check_gradients(adjoint, [(_slot_field(s), g) for s, g in buffers.items()] +
                             [(f"cameras[{k}]", g) for k, g in enumerate(camera_grads)])
        gradients = [buffers.get(s) for s in ctx.slots] + [camera_grads[k] for k in ctx.view_indices]
        return (None,) * 6 + tuple(_first_order_only(ctx, gradients))


class _RenderFunction(torch.autograd.Function):
    """Inputs: the flat scene (its dicts hold detached copies of the values) and, as tensors
    autograd tracks, the attached params of the slots that need gradients."""

    @staticmethod
    def forward(ctx, flat, options, grad_options, slots, *tensors):
        image, _ = render_flat(flat, options)
        _save_inputs(ctx, flat, tensors)
        ctx.flat, ctx.grad_options, ctx.slots = flat, grad_options, slots
        return image

    @staticmethod
    def backward(ctx, grad_image):
        flat = ctx.flat
        _check_saved_inputs(ctx)
        needed = ctx.needs_input_grad[4:]
        buffers = {slot: torch.zeros(flat.params[slot].shape, dtype=torch.float32)
                   for slot, need in zip(ctx.slots, needed) if need}
        if buffers:
            adjoint = grad_image.detach().to(torch.float32).contiguous()
            _call_core(_core.render_gradients, *flat.core_args(), adjoint,
                       flat.slot_buffers(buffers), ctx.grad_options.core(), flat=flat)
            _check_gradients(adjoint, [(_slot_field(s), g) for s, g in buffers.items()])
        return (None, None, None, None, *_first_order_only(ctx, [buffers.get(s) for s in ctx.slots]))


def _save_inputs(ctx, flat: FlatScene, tensors) -> None:
    """Keeps what the gradient pass will read, as torch's own ops do: the tracked inputs
    through ``save_for_backward``, and the versions of every tensor of the flat scene (indices
    and constant tensors too), so that editing one in place before ``backward()`` raises
    instead of differentiating a scene that was never rendered."""
    ctx.save_for_backward(*tensors)
    ctx.versions = [(name, t, t._version) for name, t in flat.named_tensors()]


def _check_saved_inputs(ctx) -> None:
    for name, t, version in ctx.versions:
        if t._version != version:
            raise RuntimeError(
                f"{name}: one of the variables needed for gradient computation has been modified "
                f"by an inplace operation: it is at version {t._version}, expected version "
                f"{version} (edit scene tensors after backward(), or render again)")
    _ = ctx.saved_tensors  # torch's own check of the tracked inputs


class _FirstOrderOnly(torch.autograd.Function):
    """The identity on a gradient, attached to the input it is the gradient of, whose own
    derivative raises: under ``create_graph=True`` the render's gradient then carries a node
    that refuses a second differentiation, instead of silently having none."""

    @staticmethod
    def forward(ctx, gradient, anchor):
        return gradient.clone()

    @staticmethod
    def backward(ctx, *_):
        raise RuntimeError("edgepath: cannot differentiate twice through a render: its gradient "
                           "is first-order only (double backward, create_graph=True, is not "
                           "supported)")


def _first_order_only(ctx, gradients: List[Optional[torch.Tensor]]) -> List[Optional[torch.Tensor]]:
    if not torch.is_grad_enabled():  # grad mode is on in backward only with create_graph=True
        return gradients
    return [g if g is None else _FirstOrderOnly.apply(g, t)
            for g, t in zip(gradients, ctx.saved_tensors)]


def derivative_image(scene: Scene, param: torch.Tensor, direction: torch.Tensor,
                     spp: int = 16, max_bounces: int = 1, seed: int = 0,
                     num_threads: Optional[int] = None, sampling: str = "mis",
                     primary_edges: bool = True, secondary_edges: bool = True,
                     edge_samples: Optional[int] = None,
                     edge_sampling: str = "importance", hide_emitters: bool = False,
                     secondary_survival: Optional[float] = None) -> torch.Tensor:
    """The derivative of the image along ``direction`` in the space of ``param`` (forward mode):
    (H, W, 3) float32, dI/dt of the image of the scene with ``param + t * direction``.

    ``param`` is any tensor the scene holds (vertices, a texture, ``camera.to_world``, the
    envmap's ``scale``, ...), or a tensor with ``requires_grad`` that the scene's tensors were
    computed from (a pose, a scalar offset); ``direction`` has its shape. Computed by the gradient pass's own
    code, per camera sample, with the same random numbers as ``render`` for the same seed (the
    paths of a render whose gradient is wanted: see ``render``), plus the edges' boundary terms
    (options as for ``render``)."""
    options = render_options(spp, max_bounces, seed, num_threads, sampling, primary_edges,
                             secondary_edges, edge_samples, edge_sampling, hide_emitters,
                             secondary_survival)
    directions = _slot_directions(scene, param, direction)
    flat = flatten_scene(scene)
    image = torch.empty((flat.height, flat.width, 3), dtype=torch.float32)
    if directions:
        _call_core(_core.derivative_image, *flat.core_args(), flat.slot_buffers(directions),
                   image, options.core(), flat=flat)
    else:
        image.zero_()
    return image


def finite_difference_image(scene: Scene, param: torch.Tensor, direction: torch.Tensor,
                            eps: float = 1e-3, spp: int = 16, max_bounces: int = 1, seed: int = 0,
                            num_threads: Optional[int] = None,
                            sampling: str = "mis", hide_emitters: bool = False) -> torch.Tensor:
    """Central finite difference (I(param + eps/2 direction) - I(param - eps/2 direction)) / eps,
    both images rendered with the same seed (the same random numbers), as Mitsuba's references
    are made. Compare it with ``derivative_image``. ``param`` must be a tensor the scene holds
    (to difference a tensor the scene is computed from, rebuild the scene at both values)."""
    return finite_difference_channels(scene, param, direction, ["radiance"], eps, spp, max_bounces,
                                      seed, num_threads, sampling, hide_emitters)["radiance"]


# ---- output channels -------------------------------------------------------------------------

# Name -> number of values per pixel (docs/conventions.md, "Output channels").
CHANNELS = {"radiance": 3, "alpha": 1, "depth": 1, "position": 3, "geometry_normal": 3,
            "shading_normal": 3, "uv": 2, "albedo": 3, "mesh_id": 1, "triangle_id": 1,
            "barycentrics": 2, "vertex_color": 3, "roughness": 1, "specular": 3, "material_id": 1}
ID_CHANNELS = ("mesh_id", "triangle_id", "material_id")


def render_channels(scene: Scene, channels=None, spp: int = 16, max_bounces: int = 1,
                    seed: int = 0, num_threads: Optional[int] = None, sampling: str = "mis",
                    backward_spp: Optional[int] = None, backward_seed: Optional[int] = None,
                    primary_edges: bool = True, secondary_edges: bool = True,
                    edge_samples: Optional[int] = None,
                    edge_sampling: str = "importance", hide_emitters: bool = False,
                    secondary_survival: Optional[float] = None) -> Dict[str, torch.Tensor]:
    """Renders output channels: a dict {name: (H, W, C) tensor} for the names in ``channels``
    (a list; default: all of ``CHANNELS``), in that order. "radiance" is ``render``'s image for
    the same options, bit for bit (``backward_seed`` included); "alpha", "depth", "position",
    "geometry_normal", "shading_normal", "uv", "albedo", "barycentrics", "vertex_color",
    "roughness" and "specular" are float32, averaged over the same camera samples (filtered like
    radiance); "mesh_id", "triangle_id" and "material_id" are int32 (-1 where nothing is hit),
    those of the ray through the pixel centre. Meanings and units: docs/conventions.md.

    Differentiable like ``render`` (same options): a loss on any continuous channel
    backpropagates into the scene, including the boundary terms of silhouettes (alpha, depth,
    ...) and of the geometric normal's jumps between faces; ids have no gradient."""
    names = _channel_names(channels)
    options = render_options(spp, max_bounces, seed, num_threads, sampling, primary_edges,
                             secondary_edges, edge_samples, edge_sampling, hide_emitters,
                             secondary_survival)
    flat = flatten_scene(scene)
    attached = [(slot, t) for slot, t in flat.params.items() if t.requires_grad]
    continuous = [n for n in names if n not in ID_CHANNELS]
    if not attached or not continuous or not torch.is_grad_enabled():
        options.replayable = False  # an image alone
        values, ids, _ = render_channels_flat(flat, names, options)
    else:
        grad_options = render_options(spp if backward_spp is None else backward_spp, max_bounces,
                                      _backward_seed(options.seed) if backward_seed is None else backward_seed,
                                      num_threads, sampling, primary_edges, secondary_edges,
                                      edge_samples, edge_sampling, hide_emitters, secondary_survival)
        options.replayable = _retraced(options, grad_options)
        slots = [slot for slot, _ in attached]
        values, ids = _ChannelsFunction.apply(flat, names, options, grad_options, slots,
                                              *[t for _, t in attached])
    out = _split_channels(names, values, ids)
    if "material_id" in out:
        out["material_id"] = _material_ids(scene, out["material_id"])
    return out


def _material_ids(scene: Scene, core_ids: torch.Tensor) -> torch.Tensor:
    """The core numbers materials per mesh (material i is mesh i's); a material id is the
    index of the distinct ``Material`` object in the order the meshes first use it (meshes that
    share one object share its id; each mesh without one has its own)."""
    table, seen = [], {}
    for i, mesh in enumerate(scene.meshes):
        key = ("mesh", i) if mesh.material is None else id(mesh.material)
        table.append(seen.setdefault(key, len(seen)))
    lookup = torch.tensor(table + [-1], dtype=torch.int32)  # index -1: no hit
    return lookup[core_ids.long()]


def render_channels_flat(flat: FlatScene, names: List[str],
                         options: RenderOptions) -> Tuple[torch.Tensor, torch.Tensor, dict]:
    """One call into the core: the packed continuous values, the packed ids, the counters."""
    nv = sum(CHANNELS[n] for n in names if n not in ID_CHANNELS)
    ni = sum(1 for n in names if n in ID_CHANNELS)
    values = torch.empty((flat.height, flat.width, nv), dtype=torch.float32)
    ids = torch.empty((flat.height, flat.width, ni), dtype=torch.int32)
    stats = _call_core(_core.render_channels, *flat.core_args(), names, values, ids, options.core(),
                       flat=flat)
    return values, ids, stats


class _ChannelsFunction(torch.autograd.Function):
    """As _RenderFunction, for the packed continuous channels (the ids ride along, not
    differentiable)."""

    @staticmethod
    def forward(ctx, flat, names, options, grad_options, slots, *tensors):
        values, ids, _ = render_channels_flat(flat, names, options)
        ctx.mark_non_differentiable(ids)
        _save_inputs(ctx, flat, tensors)
        ctx.flat, ctx.names, ctx.grad_options, ctx.slots = flat, names, grad_options, slots
        return values, ids

    @staticmethod
    def backward(ctx, grad_values, grad_ids):
        flat = ctx.flat
        _check_saved_inputs(ctx)
        needed = ctx.needs_input_grad[5:]
        buffers = {slot: torch.zeros(flat.params[slot].shape, dtype=torch.float32)
                   for slot, need in zip(ctx.slots, needed) if need}
        if buffers and grad_values is not None:
            adjoint = grad_values.detach().to(torch.float32).contiguous()
            _call_core(_core.channel_gradients, *flat.core_args(), ctx.names, adjoint,
                       flat.slot_buffers(buffers), ctx.grad_options.core(), flat=flat)
        return (None, None, None, None, None,
                *_first_order_only(ctx, [buffers.get(s) for s in ctx.slots]))


def derivative_channels(scene: Scene, param: torch.Tensor, direction: torch.Tensor, channels=None,
                        spp: int = 16, max_bounces: int = 1, seed: int = 0,
                        num_threads: Optional[int] = None, sampling: str = "mis",
                        primary_edges: bool = True, secondary_edges: bool = True,
                        edge_samples: Optional[int] = None,
                        edge_sampling: str = "importance", hide_emitters: bool = False,
                        secondary_survival: Optional[float] = None) -> Dict[str, torch.Tensor]:
    """``derivative_image`` for output channels: {name: (H, W, C) float32} derivatives along
    ``direction`` of the continuous channels in ``channels`` (default: all of them; ids have
    no derivative and are refused), with the same random numbers as ``render_channels``."""
    names = _channel_names(channels, continuous_only=True)
    options = render_options(spp, max_bounces, seed, num_threads, sampling, primary_edges,
                             secondary_edges, edge_samples, edge_sampling, hide_emitters,
                             secondary_survival)
    directions = _slot_directions(scene, param, direction)
    flat = flatten_scene(scene)
    values = torch.empty((flat.height, flat.width, sum(CHANNELS[n] for n in names)), dtype=torch.float32)
    if directions:
        _call_core(_core.channel_derivative_image, *flat.core_args(), names,
                   flat.slot_buffers(directions), values, options.core(), flat=flat)
    else:
        values.zero_()
    return _split_channels(names, values, None)


def finite_difference_channels(scene: Scene, param: torch.Tensor, direction: torch.Tensor,
                               channels=None, eps: float = 1e-3, spp: int = 16,
                               max_bounces: int = 1, seed: int = 0,
                               num_threads: Optional[int] = None,
                               sampling: str = "mis",
                               hide_emitters: bool = False) -> Dict[str, torch.Tensor]:
    """``finite_difference_image`` for output channels: central differences of the continuous
    channels in ``channels`` (default: all), both sides rendered with the same seed. Compare
    with ``derivative_channels``."""
    names = _channel_names(channels, continuous_only=True)
    eps = v.number(eps, "eps")
    if not eps > 0:
        v.fail("eps", f"must be > 0, got {eps}")
    base, direction = _check_direction(param, direction)
    # Replayable paths (the options' default): those of derivative_channels for the same seed.
    options = render_options(spp, max_bounces, seed, num_threads, sampling, hide_emitters=hide_emitters)
    sides = []
    with torch.no_grad():
        for sign in (0.5, -0.5):
            moved = _substitute(scene, param, (base + sign * eps * direction).to(param.dtype))
            values, _, _ = render_channels_flat(flatten_scene(moved), names, options)
            sides.append(_split_channels(names, values, None))
    return {n: (sides[0][n] - sides[1][n]) / eps for n in names}


def _channel_names(channels, continuous_only: bool = False) -> List[str]:
    if channels is None:
        return [n for n in CHANNELS if not (continuous_only and n in ID_CHANNELS)]
    if isinstance(channels, str) or not isinstance(channels, (list, tuple)):
        v.fail("channels", f"expected a list of channel names, got {channels!r}")
    if len(channels) == 0:
        v.fail("channels", "asks for no channel")
    names = []
    for i, name in enumerate(channels):
        if not isinstance(name, str) or name not in CHANNELS:
            v.fail(f"channels[{i}]", f"unknown channel {name!r} (known: {', '.join(CHANNELS)})")
        if name in names:
            v.fail(f"channels[{i}]", f"{name!r} is asked for twice")
        if continuous_only and name in ID_CHANNELS:
            v.fail(f"channels[{i}]", f"{name!r} is an id and has no derivative")
        names.append(name)
    return names


def _split_channels(names: List[str], values: torch.Tensor,
                    ids: Optional[torch.Tensor]) -> Dict[str, torch.Tensor]:
    out, o, k = {}, 0, 0
    for name in names:
        if name in ID_CHANNELS:
            out[name] = ids[..., k:k + 1]
            k += 1
        else:
            out[name] = values[..., o:o + CHANNELS[name]]
            o += CHANNELS[name]
    return out


def render_options(spp=16, max_bounces=1, seed=0, num_threads=None, sampling="mis",
                   primary_edges=True, secondary_edges=True, edge_samples=None,
                   edge_sampling="importance", hide_emitters=False,
                   secondary_survival=None) -> RenderOptions:
    if secondary_survival is not None:
        secondary_survival = v.number(secondary_survival, "secondary_survival")
        if not 0.0 < secondary_survival <= 1.0:
            v.fail("secondary_survival", f"must be in (0, 1], got {secondary_survival}")
    return RenderOptions(
        secondary_survival=secondary_survival,
        hide_emitters=v.boolean(hide_emitters, "hide_emitters"),
        edge_sampling=v.choice(edge_sampling, "edge_sampling", EDGE_SAMPLING),
        primary_edges=v.boolean(primary_edges, "primary_edges"),
        secondary_edges=v.boolean(secondary_edges, "secondary_edges"),
        edge_samples=0 if edge_samples is None else v.integer(edge_samples, "edge_samples", minimum=1,
                                                              maximum=MAX_EDGE_SAMPLES),
        spp=v.integer(spp, "spp", minimum=1, maximum=v.INT32_MAX),
        max_bounces=v.integer(max_bounces, "max_bounces", minimum=0, maximum=v.INT32_MAX),
        seed=_seed(seed),
        num_threads=0 if num_threads is None else v.integer(num_threads, "num_threads", minimum=1,
                                                            maximum=v.INT32_MAX),
        sampling=v.choice(sampling, "sampling", SAMPLING),
    )


def render_flat(flat: FlatScene, options: RenderOptions) -> Tuple[torch.Tensor, dict]:
    """One call into the core. Returns the image and the core's counters."""
    image = torch.empty((flat.height, flat.width, 3), dtype=torch.float32)
    stats = _call_core(_core.render, *flat.core_args(), image, options.core(), flat=flat)
    _check_finite(image, "the rendered image")
    return image, stats


def _non_finite(values: torch.Tensor, what: str, causes: str = "") -> Optional[str]:
    """What is wrong where the core's float32 output overflowed (None where it did not): every
    input is in its range by then (checked), but products of several may not be. ``causes``:
    more of them, after the scene's own."""
    finite = torch.isfinite(values)
    if bool(finite.all()):
        return None
    bad = ~finite
    first = tuple(int(i) for i in bad.nonzero()[0])
    return (f"{what}: {int(bad.sum())} non-finite values (the first at index {first}): float32 "
            f"overflowed, though each input is within its range; look for reflectances far above 1 "
            f"(diffuse, specular, vertex colours) carried over several bounces, emission and "
            f"intensities near their limit (1e16){causes}")


def _check_finite(values: torch.Tensor, what: str) -> None:
    """An image that overflowed is an error, not an image of Inf or NaN."""
    message = _non_finite(values, what)
    if message is not None:
        raise ValueError(message)


def _slot_field(slot: Slot) -> str:
    """The user's name of the parameter a gradient slot holds: ("meshes", 0, "vertices") is
    meshes[0].vertices, ("materials", 0, "diffuse") meshes[0].material.diffuse."""
    if slot[0] == "materials":
        return f"meshes[{slot[1]}].material.{slot[2]}"
    name = {"envmap": "envmap.values", "envmap_rotation": "envmap.to_world"}.get(slot[0], slot[0])
    for part in slot[1:]:
        name += f"[{part}]" if isinstance(part, int) else f".{part}"
    return name


def _check_gradients(adjoint: torch.Tensor, named: List[Tuple[str, Optional[torch.Tensor]]]) -> None:
    """A warning for each gradient that overflowed where the incoming adjoint is finite (a loss
    that is Inf or NaN makes them so, as any torch operation passes such values on). Warned,
    not raised: as torch's own operations, the gradients pass Inf and NaN on to what tests for
    them (a gradient scaler lowering its scale, anomaly detection)."""
    if not bool(torch.isfinite(adjoint).all()):
        return
    for name, g in named:
        message = None if g is None else _non_finite(g, f"the gradient with respect to {name}",
                                                     ", or a loss scaled beyond float32")
        if message is not None:
            warnings.warn(message, RuntimeWarning, stacklevel=2)


def _scene_cache(scene: Scene):
    """The core scene kept on ``scene`` across calls (created on first use)."""
    cache = getattr(scene, "_core_cache", None)
    if cache is None:
        cache = scene._core_cache = _core.SceneCache()
    return cache


def flatten_scene(scene: Scene) -> FlatScene:
    if not isinstance(scene, Scene):
        v.fail("scene", f"expected an edgepath.Scene, got {type(scene).__name__}")
    flat = FlatScene(camera={}, cache=_scene_cache(scene))
    _flatten_camera(scene.camera, flat)
    crop = flat.camera.get("crop_window")
    flat.height = crop[3] if crop else flat.camera["height"]
    flat.width = crop[2] if crop else flat.camera["width"]

    meshes = scene.meshes
    if not isinstance(meshes, (list, tuple)):
        v.fail("meshes", f"expected a list of edgepath.Mesh, got {type(meshes).__name__}")
    if len(meshes) == 0:
        v.fail("meshes", "the scene has no meshes")
    for i, mesh in enumerate(meshes):
        _flatten_mesh(mesh, i, flat)

    if scene.envmap is not None:
        _flatten_envmap(scene.envmap, flat)
    lights = getattr(scene, "point_lights", ())
    if not isinstance(lights, (list, tuple)):
        v.fail("point_lights", f"expected a list of edgepath.PointLight, got "
                               f"{type(lights).__name__}")
    for i, light in enumerate(lights):
        _flatten_point_light(light, i, flat)
    return flat


# ---- pieces -------------------------------------------------------------------------------

def _as_arrays(value):
    """``value`` (nested dicts, lists and tuples) with its CPU tensors as numpy views of the same
    memory. The core's arguments are read through DLPack, and torch's ``Tensor.__dlpack__`` is
    Python code: a Ctrl-C whose handler ran inside it would raise KeyboardInterrupt there, which
    the binding's array conversion discards when it falls back to another route, and the
    interrupt would be lost. numpy's ``__dlpack__`` runs no Python code, so a signal waits for
    the core call's own check (which cancels the call). Other devices are left as they are, for
    the binding to refuse with the field's name."""
    if isinstance(value, torch.Tensor):
        if value.device.type != "cpu":
            return value
        return (value.detach() if value.requires_grad else value).numpy()
    if isinstance(value, dict):
        return {k: _as_arrays(x) for k, x in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_as_arrays(x) for x in value)
    return value


def _call_core(fn, *args, flat: Optional[FlatScene] = None):
    """``fn(*args)`` with the flat scene's cache and point lights; core errors name the user's
    fields."""
    try:
        return fn(*_as_arrays(args), cache=None if flat is None else flat.cache,
                  point_lights=_as_arrays([] if flat is None else flat.point_lights))
    except ValueError as error:
        raise ValueError(_user_field_names(str(error))) from None


def _seed(seed, name: str = "seed") -> int:
    seed = v.integer(seed, name, minimum=0)
    if seed >= 2**64:
        v.fail(name, f"must be < 2**64, got {seed}")
    return seed


def _view_seeds(value, name: str, views: int) -> Optional[List[int]]:
    """A list (or tuple) of one seed per view, checked; None for anything else (one seed for
    every view, checked where it is used)."""
    if not isinstance(value, (list, tuple)):
        return None
    if len(value) != views:
        v.fail(name, f"expected one seed per camera ({views}), got {len(value)}")
    return [_seed(s, f"{name}[{k}]") for k, s in enumerate(value)]


def _retraced(options: RenderOptions, grad_options: RenderOptions, views: Optional[int] = None) -> bool:
    """Whether the gradient pass retraces the image's paths (it has the image's seed: its
    samples are the image's, or the first of them): only then is the image traced as that pass
    traces (``RenderOptions.replayable``). Otherwise the image is the one rendered without a
    gradient, bit for bit. With seeds per view, every view alike: all retraced or none."""
    if views is None or (options.view_seeds is None and grad_options.view_seeds is None):
        return grad_options.seed == options.seed
    image = options.view_seeds or [options.seed] * views
    grad = grad_options.view_seeds or [grad_options.seed] * views
    same = [a == b for a, b in zip(image, grad)]
    if any(same) and not all(same):
        v.fail("backward_seed", "equals seed for some views and not for others: give every view its "
                                "image's seed (to differentiate the image's own paths) or none")
    return all(same)


def _backward_seed(seed: int) -> int:
    """A seed for the gradient pass whose random numbers are independent of the image's."""
    x = (seed ^ 0x9E3779B97F4A7C15) & (2**64 - 1)
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & (2**64 - 1)
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & (2**64 - 1)
    return x ^ (x >> 31)


def _param(flat: FlatScene, slot: Slot, value: torch.Tensor) -> torch.Tensor:
    """Records the attached value of a slot; returns the detached one the core reads."""
    flat.params[slot] = value
    return value.detach()


def _flatten_camera(camera, flat: FlatScene) -> None:
    f = "camera"
    if not isinstance(camera, Camera):
        v.fail(f, f"expected an edgepath.Camera, got {type(camera).__name__}")
    if camera.to_world is not None:
        if any(x is not None for x in (camera.position, camera.look_at, camera.up)):
            v.fail(f, "give either to_world or position/look_at/up, not both")
        m = v.float_tensor(camera.to_world, "camera.to_world", (4, 4))
        _check_camera_to_world(m.detach(), camera.camera_type != "orthographic")
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

    params = torch.cat([position, look_at, up, v.scalar_tensor(camera.fov, "camera.fov"),
                        v.scalar_tensor(camera.ortho_scale, "camera.ortho_scale"),
                        v.scalar_tensor(camera.aperture_radius, "camera.aperture_radius"),
                        v.scalar_tensor(camera.focus_distance, "camera.focus_distance")])
    values = [float(x) for x in _param(flat, ("camera",), params).tolist()]

    resolution = camera.resolution
    if not isinstance(resolution, (tuple, list)) or len(resolution) != 2:
        v.fail("camera.resolution", f"expected (height, width), got {resolution!r}")
    height = v.integer(resolution[0], "camera.resolution", minimum=1)
    width = v.integer(resolution[1], "camera.resolution", minimum=1)
    if height * width > MAX_PIXELS:
        v.fail("camera.resolution", f"({height}, {width}) has more than {MAX_PIXELS} pixels")

    flat.camera = {
        "position": values[0:3],
        "look_at": values[3:6],
        "up": values[6:9],
        "fov": values[9],
        "ortho_scale": values[10],
        "aperture_radius": values[11],
        "focus_distance": values[12],
        "type": v.choice(camera.camera_type, "camera.camera_type", CAMERA_TYPES),
        "height": height,
        "width": width,
        "filter": v.choice(camera.pixel_filter, "camera.pixel_filter", PIXEL_FILTERS),
        "filter_stddev": v.number(camera.filter_stddev, "camera.filter_stddev"),
        "filter_radius": v.number(getattr(camera, "filter_radius", 1.0), "camera.filter_radius"),
        "crop_window": None,
    }
    if camera.crop_window is not None:
        crop = camera.crop_window
        if not isinstance(crop, (tuple, list)) or len(crop) != 4:
            v.fail("camera.crop_window", f"expected (x, y, width, height), got {crop!r}")
        x, y = (v.integer(c, "camera.crop_window", minimum=0) for c in crop[:2])
        w, h = (v.integer(c, "camera.crop_window", minimum=1) for c in crop[2:])
        if x + w > width or y + h > height:
            v.fail("camera.crop_window", f"({x}, {y}, {w}, {h}) does not fit in the film of "
                                         f"{width}x{height}")
        flat.camera["crop_window"] = [x, y, w, h]


def _check_camera_to_world(m: torch.Tensor, perspective: bool) -> None:
    """What the camera takes from ``to_world`` (its translation, and its y and z columns as up and
    forward) describes it only if the matrix is a rotation times a uniform scale plus a
    translation (for an orthographic camera, the z column's length does not matter): anything
    else (a NaN or a shear in the ignored x column, a bottom row other than (0, 0, 0, 1)) would
    render another camera than the matrix describes."""
    f = "camera.to_world"
    m = m.to(torch.float64)
    if not bool(torch.isfinite(m).all()):
        v.fail(f, "contains NaN or Inf")
    if not torch.equal(m[3], torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64)):
        v.fail(f, f"bottom row must be (0, 0, 0, 1), got {tuple(m[3].tolist())}")
    columns = m[:3, :3].T
    lengths = columns.norm(dim=1)
    if not bool((lengths > 0).all()):
        v.fail(f, "has a zero column in its 3x3 part")
    unit = columns / lengths[:, None]
    for i, j in ((0, 1), (0, 2), (1, 2)):
        cosine = float(unit[i] @ unit[j])
        if abs(cosine) > 1e-3:
            v.fail(f, f"columns {i} and {j} are not orthogonal (cosine {cosine:.3g}): a camera's "
                      "to_world must be a rotation with a uniform scale and a translation")
    scaled = lengths if perspective else lengths[:2]
    if float(scaled.max() - scaled.min()) > 1e-3 * float(scaled.max()):
        v.fail(f, f"scales its axes differently ({', '.join(f'{x:.6g}' for x in scaled.tolist())}): "
                  "a camera's to_world must be a rotation with a uniform scale and a translation")
    if float(torch.linalg.det(m[:3, :3])) < 0:
        v.fail(f, "mirrors the image (negative determinant); not supported")


def _flatten_material(material, i: int, emissive: bool, flat: FlatScene) -> dict:
    f = f"meshes[{i}].material"
    if material is None:
        material = Material(diffuse=0.0 if emissive else 0.5)
    if not isinstance(material, Material):
        v.fail(f, f"expected an edgepath.Material, got {type(material).__name__}")
    out = {"two_sided": v.boolean(material.two_sided, f + ".two_sided"),
           "kind": v.choice(getattr(material, "kind", "standard"), f + ".kind", MATERIAL_KINDS)}
    fields = (("diffuse", 3), ("specular", 3), ("roughness", 1))
    plastic = out["kind"] == MATERIAL_KINDS["plastic"]
    if out["kind"] in (MATERIAL_KINDS["dielectric"], MATERIAL_KINDS["plastic"]):
        fields += (("ior", 1),)
    if plastic:
        out["nonlinear"] = v.boolean(getattr(material, "nonlinear", False), f + ".nonlinear")
    for name, channels in fields:
        value = v.texture(getattr(material, name), f"{f}.{name}", channels)
        if plastic and name in ("roughness", "ior") and value.numel() != 1:
            v.fail(f"{f}.{name}", f"a plastic's {name} must be one value (its coating is tabulated for "
                                  f"it), got shape {tuple(value.shape)}")
        out[name] = _param(flat, ("materials", i, name), value)
    normal_map = getattr(material, "normal_map", None)
    if normal_map is not None:
        normal_map = v.float_tensor(normal_map, f + ".normal_map", ("H", "W", 3))
        out["normal_map"] = _param(flat, ("materials", i, "normal_map"), normal_map)
    return out


def _flatten_mesh(mesh, i: int, flat: FlatScene) -> None:
    f = f"meshes[{i}]"
    if not isinstance(mesh, Mesh):
        v.fail(f, f"expected an edgepath.Mesh, got {type(mesh).__name__}")
    vertices = v.float_tensor(mesh.vertices, f + ".vertices", ("N", 3))
    indices = v.index_tensor(mesh.indices, f + ".indices", ("M", 3))
    rows = indices.shape[0]
    light_sampling = v.choice(getattr(mesh, "light_sampling", "area"), f + ".light_sampling",
                              LIGHT_SAMPLING)
    out = {
        "vertices": _param(flat, ("meshes", i, "vertices"), vertices),
        "indices": indices,
        "uvs": None,
        "uv_indices": None,
        "normals": None,
        "normal_indices": None,
        "emission": None,
        "colors": None,
        "two_sided_emission": v.boolean(mesh.two_sided_emission, f + ".two_sided_emission"),
        "sample_solid_angle": light_sampling == 1,
        "sample_spherical_triangle": light_sampling == 2,
        "material": i,
        # Vertices being optimised move between calls: the kept scene is built for refitting.
        "moves": bool(isinstance(mesh.vertices, torch.Tensor) and mesh.vertices.requires_grad),
    }
    if mesh.uvs is not None:
        out["uvs"] = _param(flat, ("meshes", i, "uvs"), v.float_tensor(mesh.uvs, f + ".uvs", ("K", 2)))
    if mesh.uv_indices is not None:
        out["uv_indices"] = v.index_tensor(mesh.uv_indices, f + ".uv_indices", (rows, 3))
    if mesh.normals is not None:
        normals = v.float_tensor(mesh.normals, f + ".normals", ("K", 3))
        out["normals"] = _param(flat, ("meshes", i, "normals"), normals)
    if mesh.normal_indices is not None:
        out["normal_indices"] = v.index_tensor(mesh.normal_indices, f + ".normal_indices", (rows, 3))
    if mesh.emission is not None:
        emission = v.texture(mesh.emission, f + ".emission", 3)
        out["emission"] = _param(flat, ("meshes", i, "emission"), emission)
    colors = getattr(mesh, "colors", None)
    if colors is not None:
        colors = v.float_tensor(colors, f + ".colors", (vertices.shape[0], 3))
        out["colors"] = _param(flat, ("meshes", i, "colors"), colors)
    spot = getattr(mesh, "spot", None)
    if spot is not None:
        if mesh.emission is None:
            v.fail(f + ".spot", "a spot profile needs an emitting mesh (give emission)")
        out["spot_profile"] = _spot_profile(spot, f + ".spot", flat, ("meshes", i, "spot_profile"))
    material = _flatten_material(mesh.material, i, mesh.emission is not None, flat)
    flat.meshes.append(out)
    flat.materials.append(material)


def _spot_profile(spot, f: str, flat: FlatScene, slot: Slot) -> List[float]:
    """The core's five values of a Spot (axis, cutoff angle and beam width in radians)."""
    if not isinstance(spot, Spot):
        v.fail(f, f"expected an edgepath.Spot, got {type(spot).__name__}")
    axis = v.float_tensor(spot.direction, f + ".direction", (3,))
    da = axis.detach()
    if not bool(torch.isfinite(da).all()) or float(da.norm()) == 0:
        v.fail(f + ".direction", f"must be 3 finite numbers, not all zero, got {da.tolist()}")
    cutoff = v.scalar_tensor(spot.cutoff_angle, f + ".cutoff_angle")
    beam = cutoff * 0.75 if spot.beam_width is None else \
        v.scalar_tensor(spot.beam_width, f + ".beam_width")
    c, b = float(cutoff.detach()), float(beam.detach())
    if not 0 < c <= 180:
        v.fail(f + ".cutoff_angle", f"must be in (0, 180] degrees, got {c}")
    if not 0 <= b < c:
        v.fail(f + ".beam_width", f"must be in [0, cutoff_angle) degrees, got {b} "
                                  f"(cutoff_angle {c})")
    profile = torch.cat([axis, torch.deg2rad(cutoff), torch.deg2rad(beam)])
    return [float(x) for x in _param(flat, slot, profile).tolist()]


def _flatten_point_light(light, i: int, flat: FlatScene) -> None:
    f = f"point_lights[{i}]"
    if not isinstance(light, PointLight):
        v.fail(f, f"expected an edgepath.PointLight, got {type(light).__name__}")
    position = v.float_tensor(light.position, f + ".position", (3,))
    intensity = v.constant(light.intensity, f + ".intensity", 3)
    slot = ("point_lights", i)
    out = {"position": [float(x) for x in _param(flat, slot + ("position",), position).tolist()],
           "intensity": [float(x) for x in _param(flat, slot + ("intensity",), intensity).tolist()]}
    if light.spot is not None:
        out["spot_profile"] = _spot_profile(light.spot, f + ".spot", flat, slot + ("spot_profile",))
    flat.point_lights.append(out)


def _flatten_envmap(envmap, flat: FlatScene) -> None:
    f = "envmap"
    if not isinstance(envmap, EnvironmentMap):
        v.fail(f, f"expected an edgepath.EnvironmentMap, got {type(envmap).__name__}")
    values = v.float_tensor(envmap.values, f + ".values", ("H", "W", 3))
    scale = v.number(envmap.scale, f + ".scale")  # checks the type
    if isinstance(envmap.scale, torch.Tensor):
        # A tensor scale multiplies the values here, so that it gets its gradient from theirs.
        values = values * v.scalar_tensor(envmap.scale, f + ".scale")
        scale = 1.0
    if envmap.to_world is None:
        rotation = torch.eye(3, dtype=torch.float32).reshape(9)
    else:
        m = v.tensor(envmap.to_world, f + ".to_world")
        if tuple(m.shape) not in ((3, 3), (4, 4)):
            v.fail(f + ".to_world", f"expected shape (3, 3) or (4, 4), got {tuple(m.shape)}")
        m = v.float_tensor(m, f + ".to_world", tuple(m.shape))
        rotation = m[:3, :3].reshape(9)
    flat.envmap = {
        "values": _param(flat, ("envmap",), values),
        "to_world": [float(x) for x in _param(flat, ("envmap_rotation",), rotation).tolist()],
        "scale": scale,
    }


# ---- derivatives along a direction -----------------------------------------------------------

def _check_direction(param, direction) -> Tuple[torch.Tensor, torch.Tensor]:
    if not isinstance(param, torch.Tensor) or not param.dtype.is_floating_point:
        v.fail("param", "expected a floating-point tensor of the scene")
    direction = v.tensor(direction, "direction")
    if tuple(direction.shape) != tuple(param.shape):
        v.fail("direction", f"expected the shape of param {tuple(param.shape)}, got {tuple(direction.shape)}")
    if not direction.dtype.is_floating_point:
        v.fail("direction", f"expected a floating-point tensor, got {direction.dtype}")
    if not bool(torch.isfinite(direction).all()):
        v.fail("direction", "contains NaN or Inf")
    return param.detach().to(torch.float64), direction.detach().to(torch.float64)


_DUAL_LEVEL_LOCK = threading.Lock()
SPOT_FIELDS = ("direction", "cutoff_angle", "beam_width")


def _slot_directions(scene: Scene, param, direction) -> Dict[Slot, torch.Tensor]:
    """The directions on the core's slots that ``direction`` on ``param`` induces: by
    forward-mode AD through the flattening if the scene holds ``param`` itself, else (for a
    tensor the scene's tensors were computed from) by a Jacobian-vector product through the
    autograd graph that connects them."""
    _check_direction(param, direction)
    direction = direction.detach().to(param.dtype)
    # torch has one forward-mode AD level for the whole process: threads take turns here
    # (only the flattening; the core calls that follow run in parallel).
    with _DUAL_LEVEL_LOCK, fwad.dual_level():
        moved = _substitute(scene, param, fwad.make_dual(param.detach(), direction), required=False)
        tangents = None if moved is None else {
            slot: fwad.unpack_dual(t).tangent for slot, t in flatten_scene(moved).params.items()}
    if tangents is not None:
        return {slot: t.detach().to(torch.float32).contiguous()
                for slot, t in tangents.items() if t is not None}
    if not param.requires_grad:
        v.fail("param", "is not a tensor of this scene, nor does the scene depend on it through "
                        "autograd (pass the tensor the scene holds, e.g. scene.meshes[0].vertices, "
                        "or one with requires_grad that the scene's tensors were computed from)")
    with torch.enable_grad():
        flat = flatten_scene(scene)
        attached = [(slot, t) for slot, t in flat.params.items() if t.requires_grad]
        if not attached:
            return {}
        # J dir through two vector-Jacobian products: g(u) = u^T J is linear in u, and
        # d(g(u) . dir)/du = J dir.
        us = [torch.zeros_like(t, requires_grad=True) for _, t in attached]
        try:
            (g,) = torch.autograd.grad([t for _, t in attached], param, grad_outputs=us,
                                       create_graph=True, allow_unused=True)
            if g is None or not g.requires_grad:
                return {}
            jvps = torch.autograd.grad(g, us, grad_outputs=direction, allow_unused=True)
        except RuntimeError as error:
            v.fail("param", "the scene's tensors depend on it through an autograd graph that "
                            f"cannot be differentiated twice or was freed by a backward pass "
                            f"(compute them from param again): {error}")
    return {slot: j.detach().to(torch.float32).contiguous()
            for (slot, _), j in zip(attached, jvps) if j is not None}


def _substitute(scene: Scene, param: torch.Tensor, value: torch.Tensor,
                required: bool = True) -> Optional[Scene]:
    """A shallow copy of ``scene`` with every reference to the tensor ``param`` replaced by
    ``value``. If the scene does not hold ``param``: an error, or None if not ``required``."""
    found = False

    def swap(obj, names):
        nonlocal found
        if not isinstance(obj, (Camera, Mesh, Material, EnvironmentMap, PointLight, Spot)):
            return obj  # None, or a wrong type the flattening reports
        copy = object.__new__(type(obj))
        copy.__dict__.update(obj.__dict__)
        for name in names:
            if getattr(obj, name, None) is param:
                setattr(copy, name, value)
                found = True
        return copy

    if not isinstance(scene, Scene):
        v.fail("scene", f"expected an edgepath.Scene, got {type(scene).__name__}")
    camera = swap(scene.camera, ("position", "look_at", "up", "fov", "ortho_scale", "to_world",
                                 "aperture_radius", "focus_distance"))
    meshes = scene.meshes
    if isinstance(meshes, (list, tuple)):
        meshes = []
        for mesh in scene.meshes:
            m = swap(mesh, ("vertices", "uvs", "normals", "emission", "colors"))
            if isinstance(mesh, Mesh):
                m.material = swap(mesh.material, ("diffuse", "specular", "roughness", "ior", "normal_map"))
                m.spot = swap(getattr(mesh, "spot", None), SPOT_FIELDS)
            meshes.append(m)
    lights = getattr(scene, "point_lights", ())
    if isinstance(lights, (list, tuple)):
        lights = []
        for light in scene.point_lights:
            copy = swap(light, ("position", "intensity"))
            if isinstance(light, PointLight):
                copy.spot = swap(light.spot, SPOT_FIELDS)
            lights.append(copy)
    envmap = swap(scene.envmap, ("values", "to_world", "scale"))
    if not found:
        if not required:
            return None
        v.fail("param", "is not a tensor of this scene (pass the very tensor the scene holds, "
                        "e.g. scene.meshes[0].vertices)")
    return Scene(camera=camera, meshes=meshes, envmap=envmap, point_lights=lights)


_MATERIAL_FIELD = re.compile(r"\bmaterials\[(\d+)\]")


def _user_field_names(message: str) -> str:
    """The core numbers materials in its own list; ours has materials[i] for meshes[i]."""
    return _MATERIAL_FIELD.sub(r"meshes[\1].material", message)
