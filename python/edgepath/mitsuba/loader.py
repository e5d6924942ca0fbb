"""``load_mitsuba``: a Mitsuba 3 scene file's top level (``$name`` parameters, ids, one element
after the other, each read by the module of its kind), and ``MitsubaScene``, what it returns."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple, Union

import torch

from ..scene import Material, Mesh, PointLight, Scene
from .emitters import load_directional, load_environment, load_point, load_spot, place_lights
from .integrator import load_integrator
from .materials import DIFFUSE_KEYS, load_bsdf
from .sensors import load_sensor
from .shapes import load_shape
from .textures import load_bitmap
from .xml import PLUGIN_TAGS, MitsubaError, Reader, parse_xml

PathLike = Union[str, os.PathLike]

# What an unbounded integrator depth (max_depth -1, Mitsuba's default) renders with: the
# direct light and one indirect bounce. ``MitsubaScene.render`` and the command line agree.
UNBOUNDED_MAX_BOUNCES = 2


@dataclass
class MitsubaScene:
    """What ``load_mitsuba`` returns.

    ``scene``: the ``edgepath.Scene``; ``max_bounces``: the integrator's ``max_depth - 1``
    (None where the file leaves it unbounded: ``render`` and the command line then use
    ``UNBOUNDED_MAX_BOUNCES``, 2); ``spp`` and ``seed``: the sampler's
    ``sample_count`` and ``seed``; ``hide_emitters``: the integrator's; ``shapes``: meshes by
    shape id (shapes without an id are named ``shape_<i>``, in file order), ``shape_ids`` in
    the order of ``scene.meshes``;
    ``point_lights``: the delta lights (``point`` and ``spot`` of radius 0) by emitter id
    (``point_<i>``, ``spot_<i>`` without one), as in ``scene.point_lights``;
    ``bsdfs``: materials by BSDF id; ``textures``: bitmap tensors by texture id. The tensors
    are the ones the scene holds: set ``requires_grad`` on them to optimise them."""
    scene: Scene
    max_bounces: Optional[int]
    spp: int
    seed: int = 0
    shapes: Dict[str, Mesh] = field(default_factory=dict)
    shape_ids: List[str] = field(default_factory=list)
    bsdfs: Dict[str, Material] = field(default_factory=dict)
    point_lights: Dict[str, PointLight] = field(default_factory=dict)
    textures: Dict[str, torch.Tensor] = field(default_factory=dict)
    path: str = ""
    hide_emitters: bool = False  # the integrator's hide_emitters
    # Mitsuba's names of a material's fields (see parameters), by id() of the Material.
    bsdf_keys: Dict[int, Dict[str, str]] = field(default_factory=dict, repr=False)

    def parameters(self) -> Dict[str, torch.Tensor]:
        """The scene's differentiable tensors by name, each tensor once, named as Mitsuba 3's
        ``mi.traverse`` names them where Mitsuba has the same quantity: ``sensor.to_world``,
        ``sensor.x_fov``, ``sensor.aperture_radius`` and ``sensor.focus_distance`` (a thin
        lens), ``SHAPE.vertex_positions`` ((N, 3) here), ``SHAPE.emitter.radiance``
        (area lights), ``LIGHT.position``, ``LIGHT.intensity.value``, ``LIGHT.cutoff_angle``,
        ``LIGHT.beam_width`` (point and spot lights of radius 0; edgepath's ``LIGHT.direction``,
        a spot's axis, where Mitsuba has its to_world), ``BSDF.reflectance`` (``diffuse_reflectance`` of a roughplastic,
        ``brdf_0.`` in front inside a twosided), ``BSDF.alpha``, ``envmap.data``; constants end
        in ``.value``, textures in ``.data``. edgepath's own names where Mitsuba has none:
        ``BSDF.specular`` (the GGX lobe's F0, which Mitsuba derives from eta/k or the IOR),
        ``BSDF.diffuse`` of a rough conductor; ``BSDF.eta`` is a dielectric's relative
        index of refraction (int_ior / ext_ior, a 0-d tensor) as in Mitsuba. ``BSDF``: the BSDF's id, or ``SHAPE.bsdf`` for one
        without an id. A tensor shared by several shapes or BSDFs is listed under the first."""
        out: Dict[str, torch.Tensor] = {}
        listed = set()

        def put(name: str, value, texture_suffix: bool = False) -> None:
            if not isinstance(value, torch.Tensor) or id(value) in listed:
                return
            if texture_suffix:
                name += ".data" if value.dim() >= 2 else ".value"
            listed.add(id(value))
            out[name] = value

        camera = self.scene.camera
        put("sensor.to_world", camera.to_world)
        put("sensor.x_fov", camera.fov)
        put("sensor.aperture_radius", camera.aperture_radius)  # a thin lens's
        put("sensor.focus_distance", camera.focus_distance)
        bsdf_names = {id(m): name for name, m in self.bsdfs.items()}
        for sid, mesh in zip(self.shape_ids, self.scene.meshes):
            put(f"{sid}.vertex_positions", mesh.vertices)
            put(f"{sid}.emitter.radiance", mesh.emission, texture_suffix=True)
            material = mesh.material
            prefix = bsdf_names.get(id(material), f"{sid}.bsdf")
            keys = self.bsdf_keys.get(id(material), DIFFUSE_KEYS)
            for name in ("diffuse", "specular", "roughness", "ior", "normal_map"):
                mitsuba = keys.get(name)
                put(f"{prefix}.{mitsuba or name}", getattr(material, name, None),
                    texture_suffix=mitsuba is not None and name != "ior")
        if self.scene.envmap is not None:
            put("envmap.data", self.scene.envmap.values)
        for sid, light in self.point_lights.items():
            put(f"{sid}.position", light.position)
            put(f"{sid}.intensity.value", light.intensity)
            if light.spot is not None:
                put(f"{sid}.direction", light.spot.direction)
                put(f"{sid}.cutoff_angle", light.spot.cutoff_angle)
                put(f"{sid}.beam_width", light.spot.beam_width)
        return out

    def direction(self, name: str, values: Sequence[float]) -> Tuple[torch.Tensor, torch.Tensor]:
        """(tensor, direction) for ``ep.derivative_image`` from a parameter name and a few
        numbers: ``SHAPE.vertex_positions``: 3 numbers, a translation of every vertex;
        ``sensor.to_world``: 16 numbers (row-major), or ``sensor.position`` (a direction of
        ``sensor.to_world``): 3 numbers, a translation of the camera; colours (radiance,
        reflectance, ``specular``, ``envmap.data``): 1 number (every channel) or 3 (per
        channel), added to every texel; scalars (``sensor.x_fov``, ``sensor.aperture_radius``,
        ``sensor.focus_distance``, ``alpha``): 1 number (every texel)."""
        params = self.parameters()
        key = "sensor.to_world" if name == "sensor.position" else name
        if key not in params:
            shorthand = ", sensor.position" if "sensor.to_world" in params else ""
            raise ValueError(f"parameter {name!r}: not in this scene (have: "
                             f"{', '.join(params)}{shorthand})")
        param = params[key]
        values = [float(x) for x in values]
        d = torch.tensor(values, dtype=param.dtype)

        def need(counts):
            if len(values) not in counts:
                raise ValueError(f"direction of {name!r}: expected "
                                 f"{' or '.join(map(str, counts))} numbers, got {len(values)}")
        if name == "sensor.position":
            need((3,))
            out = torch.zeros_like(param)
            out[:3, 3] = d
            return param, out
        if name == "sensor.to_world":
            need((16,))
            return param, d.reshape(4, 4)
        if name.endswith(".vertex_positions"):
            need((3,))
            return param, d.expand_as(param).clone()
        channels = param.shape[-1] if param.dim() > 0 else 1
        need((1, 3) if channels == 3 else (1,))
        return param, d.expand_as(param).clone() if param.dim() > 0 else d.reshape(())

    def render(self, **options) -> torch.Tensor:
        """``ep.render`` of the scene with the file's spp, max_bounces, seed and
        hide_emitters (keyword arguments override them)."""
        from ..render import render
        args = {"spp": self.spp, "seed": self.seed, "hide_emitters": self.hide_emitters,
                "max_bounces": UNBOUNDED_MAX_BOUNCES if self.max_bounces is None else self.max_bounces}
        args.update(options)
        return render(self.scene, **args)


def load_scene(ctx: Reader, user_params: Dict[str, object]) -> MitsubaScene:
    """Reads the file into ``ctx.result``: ``$name`` parameters first, then every top-level
    element with the loader of its kind."""
    root = parse_xml(ctx.path)
    if root.tag != "scene":
        ctx.fail(root, "the root element must be <scene>")
    defaults = {}
    for child in root.children:
        if child.tag == "default":
            defaults[ctx.attr(child, "name")] = ctx.attr(child, "value")
    ctx.params = dict(defaults)
    for name, value in user_params.items():
        ctx.params[name] = _param_text(value)
    ctx.substitute(root)
    unknown = set(user_params) - ctx.used_params - set(defaults)
    if unknown:
        raise MitsubaError(f"{ctx.path}: parameter(s) {', '.join(sorted(unknown))} unknown "
                           "to the file (no $name refers to them, no <default> declares them)")

    for child in root.children:
        if "id" in child.attrs and child.tag in PLUGIN_TAGS:
            if child.attrs["id"] in ctx.ids:
                ctx.fail(child, f"id '{child.attrs['id']}' used twice")
            ctx.ids[child.attrs["id"]] = child

    sensor = None
    meshes: List[Mesh] = []
    envmap = None
    lights = []  # suns and point lights, placed once the shapes' bounds are known
    for child in root.children:
        tag = child.tag
        if tag == "default":
            continue
        if tag == "integrator":
            load_integrator(ctx, child)
        elif tag == "sensor":
            if sensor is not None:
                ctx.fail(child, "only one sensor is supported")
            sensor = load_sensor(ctx, child)
        elif tag == "shape":
            meshes.append(load_shape(ctx, child, len(meshes)))
        elif tag == "bsdf":
            load_bsdf(ctx, child)
        elif tag == "texture":
            load_bitmap(ctx, child, 3)
        elif tag == "emitter" and child.attrs.get("type") == "directional":
            lights.append(load_directional(ctx, child, len(lights)))
        elif tag == "emitter" and child.attrs.get("type") == "point":
            lights.append(load_point(ctx, child, len(lights)))
        elif tag == "emitter" and child.attrs.get("type") == "spot":
            lights.append(load_spot(ctx, child, len(lights)))
        elif tag == "emitter":
            if envmap is not None:
                ctx.fail(child, "only one environment emitter (constant or envmap) is supported")
            envmap = load_environment(ctx, child)
        else:
            ctx.fail(child, "unsupported element (supported at the top level: default, "
                            "integrator, sensor, shape, bsdf, texture, emitter)")
    if sensor is None:
        raise MitsubaError(f"{ctx.path}: no <sensor> (edgepath needs a camera)")
    if not meshes:
        raise MitsubaError(f"{ctx.path}: no <shape>")
    light_meshes, point_lights = place_lights(ctx, lights, meshes)
    ctx.result.scene = Scene(camera=sensor, meshes=meshes + light_meshes, envmap=envmap,
                             point_lights=point_lights)
    return ctx.result


def _param_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ", ".join(str(x) for x in value)
    return os.fspath(value) if isinstance(value, os.PathLike) else str(value)


def load_mitsuba(path: PathLike, **params) -> MitsubaScene:
    """Loads a Mitsuba 3 XML scene (the subset in docs/scene-files.md) as a ``MitsubaScene``.

    ``params`` replace ``$name`` in the file's attributes, overriding its ``<default>``
    values (numbers, strings, paths, booleans; lists become comma-separated). Relative file
    names are resolved against the XML file's folder. Raises ``MitsubaError`` (a ValueError)
    naming the line and element of anything outside the subset, ``FileNotFoundError`` for a
    missing scene file."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: scene file not found")
    reader = Reader(path, MitsubaScene(scene=None, max_bounces=None, spp=4, path=path))
    try:
        return load_scene(reader, params)
    except RecursionError:
        # Nesting is bounded when parsing: only <ref>s that lead back into themselves recurse.
        node = reader.last_ref
        where = path if node is None else f"{path}:{node.line}: {node.describe()}"
        raise MitsubaError(f"{where}: refers to an element that contains it (a cycle of "
                           "references)") from None
