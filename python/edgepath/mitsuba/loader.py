"""Mitsuba 3 scene files: ``load_mitsuba`` reads a documented subset of Mitsuba's XML format
into an ``edgepath.Scene`` (see docs/scene-files.md for the subset, element by element).

Anything outside the subset raises ``MitsubaError`` (a ValueError) naming the file, the line
and the element, e.g. ``scene.xml:12: <emitter type="point">: unsupported emitter type 'point'
(supported: area, constant, envmap)``. Analytic shapes (rectangle, cube, sphere, disk) are
tessellated; materials are mapped onto edgepath's diffuse + GGX model, approximately where
Mitsuba's model differs (documented per BSDF).
"""

from __future__ import annotations

import math
import os
import re
import warnings
import xml.parsers.expat
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple, Union

import torch

from ..io import _texture_rgb, imread, load_obj, load_ply, to_srgb
from ..scene import Camera, EnvironmentMap, Material, Mesh, Scene

PathLike = Union[str, os.PathLike]

SPHERE_RINGS = 64        # tessellation of analytic spheres: rings (pole to pole) ...
SPHERE_SEGMENTS = 128    # ... and segments around the z axis
DISK_SEGMENTS = 128      # triangles of an analytic disk

# Reflectance at normal incidence (linear RGB) of Mitsuba's named conductors, from common
# tables of measured metals; Mitsuba itself uses spectral eta/k (an approximation, see docs).
CONDUCTOR_F0 = {
    "none": (1.0, 1.0, 1.0),
    "Ag": (0.972, 0.960, 0.915),
    "Al": (0.913, 0.922, 0.924),
    "Au": (1.000, 0.782, 0.344),
    "Co": (0.662, 0.655, 0.634),
    "Cr": (0.550, 0.556, 0.554),
    "Cu": (0.955, 0.638, 0.538),
    "Fe": (0.562, 0.565, 0.578),
    "Ni": (0.660, 0.609, 0.526),
    "Pt": (0.673, 0.637, 0.585),
    "Ti": (0.542, 0.497, 0.449),
}

# Mitsuba's named indices of refraction.
NAMED_IOR = {
    "vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277,
    "carbon dioxide": 1.00045, "water": 1.3330, "acetone": 1.36, "ethanol": 1.361,
    "carbon tetrachloride": 1.461, "glycerol": 1.4729, "benzene": 1.501,
    "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
    "pyrex": 1.470, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046,
    "sodium chloride": 1.544, "amber": 1.55, "pet": 1.5750, "diamond": 2.419,
}


class MitsubaError(ValueError):
    """A scene file outside the supported subset, or malformed."""


# Mitsuba's names of the Material fields a BSDF type sets (parameters() adds .value / .data).
# A material made without a <bsdf> (a shape's default) is a diffuse one.
_DIFFUSE_KEYS = {"diffuse": "reflectance"}
_BSDF_KEYS = {"diffuse": _DIFFUSE_KEYS, "roughplastic": {"diffuse": "diffuse_reflectance",
                                                         "roughness": "alpha"},
              "roughconductor": {"roughness": "alpha"}}

# What an unbounded integrator depth (max_depth -1, Mitsuba's default) renders with: the
# direct light and one indirect bounce. ``MitsubaScene.render`` and the command line agree.
UNBOUNDED_MAX_BOUNCES = 2


@dataclass
class MitsubaScene:
    """What ``load_mitsuba`` returns.

    ``scene``: the ``edgepath.Scene``; ``max_bounces``: the integrator's ``max_depth - 1``
    (None where the file leaves it unbounded: ``render`` and the command line then use
    ``UNBOUNDED_MAX_BOUNCES``, 2); ``spp`` and ``seed``: the sampler's
    ``sample_count`` and ``seed``; ``shapes``: meshes by shape id (shapes without an id are
    named ``shape_<i>``, in file order), ``shape_ids`` in the order of ``scene.meshes``;
    ``bsdfs``: materials by BSDF id; ``textures``: bitmap tensors by texture id. The tensors
    are the ones the scene holds: set ``requires_grad`` on them to optimise them."""
    scene: Scene
    max_bounces: Optional[int]
    spp: int
    seed: int = 0
    shapes: Dict[str, Mesh] = field(default_factory=dict)
    shape_ids: List[str] = field(default_factory=list)
    bsdfs: Dict[str, Material] = field(default_factory=dict)
    textures: Dict[str, torch.Tensor] = field(default_factory=dict)
    path: str = ""
    # Mitsuba's names of a material's fields (see parameters), by id() of the Material.
    bsdf_keys: Dict[int, Dict[str, str]] = field(default_factory=dict, repr=False)

    def parameters(self) -> Dict[str, torch.Tensor]:
        """The scene's differentiable tensors by name, each tensor once, named as Mitsuba 3's
        ``mi.traverse`` names them where Mitsuba has the same quantity: ``sensor.to_world``,
        ``sensor.x_fov``, ``SHAPE.vertex_positions`` ((N, 3) here), ``SHAPE.emitter.radiance``
        (area lights), ``BSDF.reflectance`` (``diffuse_reflectance`` of a roughplastic,
        ``brdf_0.`` in front inside a twosided), ``BSDF.alpha``, ``envmap.data``; constants end
        in ``.value``, textures in ``.data``. edgepath's own names where Mitsuba has none:
        ``BSDF.specular`` (the GGX lobe's F0, which Mitsuba derives from eta/k or the IOR),
        ``BSDF.diffuse`` of a conductor. ``BSDF``: the BSDF's id, or ``SHAPE.bsdf`` for one
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
        bsdf_names = {id(m): name for name, m in self.bsdfs.items()}
        for sid, mesh in zip(self.shape_ids, self.scene.meshes):
            put(f"{sid}.vertex_positions", mesh.vertices)
            put(f"{sid}.emitter.radiance", mesh.emission, texture_suffix=True)
            material = mesh.material
            prefix = bsdf_names.get(id(material), f"{sid}.bsdf")
            keys = self.bsdf_keys.get(id(material), _DIFFUSE_KEYS)
            for name in ("diffuse", "specular", "roughness"):
                mitsuba = keys.get(name)
                put(f"{prefix}.{mitsuba or name}", getattr(material, name, None),
                    texture_suffix=mitsuba is not None)
        if self.scene.envmap is not None:
            put("envmap.data", self.scene.envmap.values)
        return out

    def direction(self, name: str, values: Sequence[float]) -> Tuple[torch.Tensor, torch.Tensor]:
        """(tensor, direction) for ``ep.derivative_image`` from a parameter name and a few
        numbers: ``SHAPE.vertex_positions``: 3 numbers, a translation of every vertex;
        ``sensor.to_world``: 16 numbers (row-major), or ``sensor.position`` (a direction of
        ``sensor.to_world``): 3 numbers, a translation of the camera; colours (radiance,
        reflectance, ``specular``, ``envmap.data``): 1 number (every channel) or 3 (per
        channel), added to every texel; scalars (``sensor.x_fov``, ``alpha``): 1 number
        (every texel)."""
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
        """``ep.render`` of the scene with the file's spp, max_bounces and seed (keyword
        arguments override them)."""
        from ..render import render
        args = {"spp": self.spp, "seed": self.seed,
                "max_bounces": UNBOUNDED_MAX_BOUNCES if self.max_bounces is None else self.max_bounces}
        args.update(options)
        return render(self.scene, **args)


# ---- XML with line numbers -----------------------------------------------------------------

@dataclass
class _Node:
    tag: str
    attrs: Dict[str, str]
    line: int
    children: List["_Node"] = field(default_factory=list)

    def describe(self) -> str:
        shown = [f'{k}="{self.attrs[k]}"' for k in ("type", "name", "id") if k in self.attrs]
        return "<" + " ".join([self.tag] + shown) + ">"


_FLOAT32_MAX = 3.4028234663852886e38

# Deeper nesting than any scene needs is refused (the loader recurses over the tree).
_MAX_DEPTH = 64


def _parse_xml(path: str) -> _Node:
    stack: List[_Node] = []
    root: List[_Node] = []
    parser = xml.parsers.expat.ParserCreate()

    def start(tag, attrs):
        if len(stack) >= _MAX_DEPTH:
            raise MitsubaError(f"{path}:{parser.CurrentLineNumber}: <{tag}>: elements nested "
                               f"deeper than {_MAX_DEPTH} levels")
        node = _Node(tag, dict(attrs), parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    with open(path, "rb") as f:
        data = f.read()
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as error:
        raise MitsubaError(f"{path}:{error.lineno}: malformed XML: "
                           f"{xml.parsers.expat.ErrorString(error.code)}") from None
    except LookupError as error:  # the XML declaration names an encoding Python lacks
        raise MitsubaError(f"{path}:{parser.CurrentLineNumber}: {error}") from None
    return root[0]


# ---- the loader ----------------------------------------------------------------------------

_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_PROPERTY_TAGS = ("float", "integer", "boolean", "string", "rgb", "spectrum", "point",
                  "vector", "transform", "ref")
_PLUGIN_TAGS = ("bsdf", "texture", "emitter", "film", "rfilter", "sampler", "shape",
                "sensor", "integrator")


class _Loader:
    def __init__(self, path: str, params: Dict[str, str]):
        self.path = path
        self.directory = os.path.dirname(os.path.abspath(path))
        self.params = params
        self.used_params: set = set()
        self.ids: Dict[str, _Node] = {}
        self.bsdf_cache: Dict[int, Material] = {}
        self.texture_cache: Dict[int, torch.Tensor] = {}
        self.result = MitsubaScene(scene=None, max_bounces=None, spp=4, path=path)
        self.last_ref: Optional[_Node] = None  # names the culprit of a cycle of references

    # errors and values

    def fail(self, node: _Node, message: str):
        raise MitsubaError(f"{self.path}:{node.line}: {node.describe()}: {message}")

    def attr(self, node: _Node, name: str, required: bool = True) -> Optional[str]:
        if name not in node.attrs:
            if required:
                self.fail(node, f"missing attribute '{name}'")
            return None
        return node.attrs[name]

    def substitute(self, node: _Node) -> None:
        for key, value in node.attrs.items():
            def repl(m, node=node):
                name = m.group(1)
                if name not in self.params:
                    self.fail(node, f"undefined parameter ${name} (give it to load_mitsuba as "
                                    f"{name}=... or declare a <default name=\"{name}\">)")
                self.used_params.add(name)
                return self.params[name]
            node.attrs[key] = _PARAM.sub(repl, value)
        for child in node.children:
            self.substitute(child)

    def numbers(self, node: _Node, text: str, counts: Sequence[int]) -> List[float]:
        parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            self.fail(node, f"expected numbers, got {text!r}")
        if not all(abs(x) <= _FLOAT32_MAX for x in values):  # NaN fails too
            self.fail(node, f"expected finite numbers (as float32), got {text!r}")
        if len(values) not in counts:
            self.fail(node, f"expected {' or '.join(map(str, counts))} numbers, got {len(values)}")
        return values

    def float_value(self, node: _Node) -> float:
        if node.tag not in ("float", "integer"):
            self.fail(node, "expected a <float>")
        return self.numbers(node, self.attr(node, "value"), (1,))[0]

    def int_value(self, node: _Node) -> int:
        if node.tag != "integer":
            self.fail(node, "expected an <integer>")
        text = self.attr(node, "value")
        try:
            return int(text)
        except ValueError:
            self.fail(node, f"expected an integer, got {text!r}")

    def bool_value(self, node: _Node) -> bool:
        if node.tag != "boolean":
            self.fail(node, "expected a <boolean>")
        text = self.attr(node, "value").strip().lower()
        if text not in ("true", "false"):
            self.fail(node, f"expected true or false, got {text!r}")
        return text == "true"

    def string_value(self, node: _Node) -> str:
        if node.tag != "string":
            self.fail(node, "expected a <string>")
        return self.attr(node, "value")

    def vector_value(self, node: _Node) -> List[float]:
        if node.tag not in ("point", "vector"):
            self.fail(node, "expected a <point> or <vector>")
        if "value" in node.attrs:
            return self.numbers(node, node.attrs["value"], (3,))
        return [self.numbers(node, node.attrs.get(k, "0"), (1,))[0] for k in "xyz"]

    def file(self, node: _Node, name: str) -> str:
        name = name.replace("\\", "/")
        full = name if os.path.isabs(name) else os.path.join(self.directory, name)
        if not os.path.isfile(full):
            self.fail(node, f"file not found: {full}")
        return full

    # plugins and their properties

    def properties(self, plugin: _Node) -> Tuple[Dict[str, _Node], List[_Node]]:
        """Named properties of a plugin element, and its nested plugins (refs included)."""
        props: Dict[str, _Node] = {}
        nested: List[_Node] = []
        for child in plugin.children:
            if child.tag in _PLUGIN_TAGS or (child.tag == "ref" and "name" not in child.attrs):
                nested.append(child)
                if child.tag in ("texture", "bsdf") and "name" in child.attrs:
                    props[child.attrs["name"]] = child
                continue
            if child.tag not in _PROPERTY_TAGS:
                self.fail(child, f"unsupported element inside <{plugin.tag}>")
            name = self.attr(child, "name")
            if name in props:
                self.fail(child, f"property '{name}' given twice")
            props[name] = child
        return props, nested

    def leftovers(self, plugin: _Node, props: Dict[str, _Node], kind: str) -> None:
        for name, node in props.items():
            self.fail(node, f"property '{name}' of {kind} '{plugin.attrs.get('type')}' is not "
                            "supported")

    def deref(self, node: _Node, tags: Tuple[str, ...]) -> _Node:
        if node.tag != "ref":
            return node
        self.last_ref = node
        ref = self.attr(node, "id")
        if ref not in self.ids:
            self.fail(node, f"unknown id '{ref}'")
        target = self.ids[ref]
        if target.tag not in tags:
            self.fail(node, f"id '{ref}' is a <{target.tag}>, expected <{'> or <'.join(tags)}>")
        return target

    # textures and colours

    def bitmap(self, node: _Node, channels: int) -> torch.Tensor:
        key = (id(node), channels)
        if key in self.texture_cache:
            return self.texture_cache[key]
        if node.attrs.get("type") != "bitmap":
            self.fail(node, f"unsupported texture type '{node.attrs.get('type')}' (supported: bitmap)")
        props, nested = self.properties(node)
        if nested:
            self.fail(nested[0], "unexpected element inside a bitmap")
        filename = self.file(props["filename"], self.string_value(props.pop("filename"))) \
            if "filename" in props else self.fail(node, "missing <string name=\"filename\">")
        raw = self.bool_value(props.pop("raw")) if "raw" in props else False
        if "filter_type" in props:
            f = self.string_value(props["filter_type"])
            if f != "bilinear":
                self.fail(props["filter_type"], f"filter_type '{f}' is not supported (edgepath "
                                                "filters textures bilinearly)")
            props.pop("filter_type")
        if "wrap_mode" in props:
            w = self.string_value(props["wrap_mode"])
            if w not in ("repeat", "clamp", "mirror"):
                self.fail(props["wrap_mode"], f"unknown wrap_mode '{w}'")
            if w != "repeat":
                warnings.warn(f"{self.path}:{props['wrap_mode'].line}: wrap_mode '{w}' is loaded "
                              "as 'repeat' (edgepath textures repeat): texels within half a "
                              "texel of the border differ", stacklevel=4)
            props.pop("wrap_mode")
        self.leftovers(node, props, "texture")
        if channels == 3:
            image = _texture_rgb(filename)
        else:
            image = imread(filename)[:, :, :1].contiguous()
        if raw and not filename.lower().endswith((".exr", ".hdr")):
            # imread linearised the 8-bit sRGB values: encode them back (exact up to rounding).
            image = to_srgb(image).contiguous()
        self.texture_cache[key] = image
        if "id" in node.attrs:
            self.result.textures.setdefault(node.attrs["id"], image)
        return image

    def colour(self, node: _Node, channels: int = 3) -> torch.Tensor:
        """(channels,) float32 constant or (H, W, channels) texture from a property node."""
        node = self.deref(node, ("texture",))
        if node.tag == "texture":
            return self.bitmap(node, channels)
        if node.tag in ("float", "integer"):
            return torch.full((channels,), self.float_value(node), dtype=torch.float32)
        if node.tag == "spectrum":
            text = self.attr(node, "value")
            if ":" in text:
                self.fail(node, "spectra given as wavelength:value pairs are not supported "
                                "(give one value, or use <rgb>)")
            return torch.full((channels,), self.numbers(node, text, (1,))[0], dtype=torch.float32)
        if node.tag == "rgb":
            values = self.numbers(node, self.attr(node, "value"), (1, 3))
            if len(values) == 1:
                values = values * 3
            if channels == 1:
                if len(set(values)) != 1:
                    self.fail(node, "expected a single value")
                values = values[:1]
            return torch.tensor(values, dtype=torch.float32)
        self.fail(node, "expected <float>, <rgb>, <spectrum> or a bitmap <texture>")

    # transforms

    def transform(self, node: _Node) -> torch.Tensor:
        if node.tag != "transform":
            self.fail(node, "expected a <transform>")
        m = torch.eye(4, dtype=torch.float64)
        for op in node.children:
            m = self.transform_op(op) @ m
        return m

    def transform_op(self, op: _Node) -> torch.Tensor:
        t = torch.eye(4, dtype=torch.float64)
        a = op.attrs
        if op.tag == "translate":
            v = self.numbers(op, a["value"], (3,)) if "value" in a else \
                [self.numbers(op, a.get(k, "0"), (1,))[0] for k in "xyz"]
            t[:3, 3] = torch.tensor(v, dtype=torch.float64)
        elif op.tag == "scale":
            if "value" in a:
                v = self.numbers(op, a["value"], (1, 3))
                v = v * 3 if len(v) == 1 else v
            else:
                v = [self.numbers(op, a.get(k, "1"), (1,))[0] for k in "xyz"]
            t[:3, :3] = torch.diag(torch.tensor(v, dtype=torch.float64))
        elif op.tag == "rotate":
            axis = self.numbers(op, a["value"], (3,)) if "value" in a else \
                [self.numbers(op, a.get(k, "0"), (1,))[0] for k in "xyz"]
            angle = self.numbers(op, self.attr(op, "angle"), (1,))[0]
            t[:3, :3] = _rotation(torch.tensor(axis, dtype=torch.float64), angle, op, self)
        elif op.tag == "matrix":
            v = self.numbers(op, self.attr(op, "value"), (9, 16))
            if len(v) == 9:
                t[:3, :3] = torch.tensor(v, dtype=torch.float64).reshape(3, 3)
            else:
                t = torch.tensor(v, dtype=torch.float64).reshape(4, 4)
        elif op.tag == "lookat":
            origin = self.numbers(op, self.attr(op, "origin"), (3,))
            target = self.numbers(op, self.attr(op, "target"), (3,))
            up = self.numbers(op, a.get("up", "0 1 0"), (3,))
            t = _look_at(origin, target, up, op, self)
        else:
            self.fail(op, "unsupported transform operation (supported: translate, rotate, "
                          "scale, matrix, lookat)")
        return t

    # the scene

    def load(self, user_params: Dict[str, object]) -> MitsubaScene:
        root = _parse_xml(self.path)
        if root.tag != "scene":
            self.fail(root, "the root element must be <scene>")
        defaults = {}
        for child in root.children:
            if child.tag == "default":
                defaults[self.attr(child, "name")] = self.attr(child, "value")
        self.params = dict(defaults)
        for name, value in user_params.items():
            self.params[name] = _param_text(value)
        self.substitute(root)
        unknown = set(user_params) - self.used_params - set(defaults)
        if unknown:
            raise MitsubaError(f"{self.path}: parameter(s) {', '.join(sorted(unknown))} unknown "
                               "to the file (no $name refers to them, no <default> declares them)")

        for child in root.children:
            if "id" in child.attrs and child.tag in _PLUGIN_TAGS:
                if child.attrs["id"] in self.ids:
                    self.fail(child, f"id '{child.attrs['id']}' used twice")
                self.ids[child.attrs["id"]] = child

        sensor = None
        meshes: List[Mesh] = []
        envmap = None
        for child in root.children:
            tag = child.tag
            if tag == "default":
                continue
            if tag == "integrator":
                self.integrator(child)
            elif tag == "sensor":
                if sensor is not None:
                    self.fail(child, "only one sensor is supported")
                sensor = self.sensor(child)
            elif tag == "shape":
                meshes.append(self.shape(child, len(meshes)))
            elif tag == "bsdf":
                self.material(child)
            elif tag == "texture":
                self.bitmap(child, 3)
            elif tag == "emitter":
                if envmap is not None:
                    self.fail(child, "only one environment emitter (constant or envmap) is supported")
                envmap = self.environment(child)
            else:
                self.fail(child, "unsupported element (supported at the top level: default, "
                                 "integrator, sensor, shape, bsdf, texture, emitter)")
        if sensor is None:
            raise MitsubaError(f"{self.path}: no <sensor> (edgepath needs a camera)")
        if not meshes:
            raise MitsubaError(f"{self.path}: no <shape>")
        self.result.scene = Scene(camera=sensor, meshes=meshes, envmap=envmap)
        return self.result

    def integrator(self, node: _Node) -> None:
        kind = node.attrs.get("type")
        if kind not in ("path", "prb", "prb_basic", "prb_projective", "direct_projective"):
            self.fail(node, f"unsupported integrator type '{kind}' (supported: path, prb, "
                            "prb_basic, prb_projective, direct_projective)")
        props, nested = self.properties(node)
        if nested:
            self.fail(nested[0], "unexpected element inside <integrator>")
        depth = self.int_value(props.pop("max_depth")) if "max_depth" in props else -1
        if kind == "direct_projective":
            depth = 2 if depth == -1 else depth
        if depth == 0 or depth < -1:
            self.fail(node, f"max_depth {depth}: must be -1 (unbounded) or >= 1")
        self.result.max_bounces = None if depth == -1 else depth - 1
        if "rr_depth" in props:  # edgepath does not stop paths early: same expected image
            self.int_value(props.pop("rr_depth"))
        if "hide_emitters" in props:
            if self.bool_value(props["hide_emitters"]):
                self.fail(props["hide_emitters"], "hide_emitters is not supported")
            props.pop("hide_emitters")
        self.leftovers(node, props, "integrator")

    def sensor(self, node: _Node) -> Camera:
        kind = node.attrs.get("type")
        if kind not in ("perspective", "orthographic"):
            self.fail(node, f"unsupported sensor type '{kind}' (supported: perspective, "
                            "orthographic)")
        props, nested = self.properties(node)
        width, height, rfilter, stddev, crop = 768, 576, "gaussian", 0.5, None
        for child in nested:
            if child.tag == "film":
                width, height, rfilter, stddev, crop = self.film(child)
            elif child.tag == "sampler":
                self.sampler(child)
            else:
                self.fail(child, "unexpected element inside <sensor> (supported: film, sampler)")
        to_world = self.transform(props.pop("to_world")) if "to_world" in props else \
            torch.eye(4, dtype=torch.float64)
        if float(torch.linalg.det(to_world[:3, :3])) <= 0:
            self.fail(node, "to_world mirrors the image (negative determinant, e.g. a negative "
                            "scale): not supported")
        for name in ("near_clip", "far_clip"):  # edgepath clips nothing
            if name in props:
                self.float_value(props.pop(name))
        camera = Camera(to_world=to_world.to(torch.float32), resolution=(height, width),
                        camera_type=kind, pixel_filter=rfilter, filter_stddev=stddev,
                        crop_window=crop)
        if kind == "perspective":
            camera.fov = torch.tensor(self.fov(node, props, width / height), dtype=torch.float32)
        else:
            sx, sy = (float(to_world[:3, i].norm()) for i in (0, 1))
            if abs(sx - sy) > 1e-6 * max(sx, sy):
                self.fail(node, f"to_world scales x and y differently ({sx:g}, {sy:g}): not "
                                "supported for orthographic sensors")
            camera.ortho_scale = sx
        self.leftovers(node, props, "sensor")
        return camera

    def fov(self, node: _Node, props: Dict[str, _Node], aspect: float) -> float:
        axis = self.string_value(props.pop("fov_axis")) if "fov_axis" in props else "x"
        if "fov" in props and "focal_length" in props:
            self.fail(node, "give fov or focal_length, not both")
        if "fov" in props:
            fov = self.float_value(props.pop("fov"))
        else:
            text = self.string_value(props.pop("focal_length")) if "focal_length" in props else "50mm"
            m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(mm)?\s*", text)
            if not m or float(m.group(1)) <= 0:
                self.fail(node, f"focal_length {text!r}: expected a length in mm, e.g. '50mm'")
            fov = math.degrees(2 * math.atan(math.hypot(36, 24) / (2 * float(m.group(1)))))
            axis = "diagonal"
        if not 0 < fov < 180:
            self.fail(node, f"fov {fov}: must be in (0, 180) degrees")
        t = math.tan(math.radians(fov) / 2)
        if axis == "smaller":
            axis = "x" if aspect <= 1 else "y"
        elif axis == "larger":
            axis = "x" if aspect >= 1 else "y"
        if axis == "y":
            t *= aspect
        elif axis == "diagonal":
            t *= aspect / math.sqrt(aspect * aspect + 1)
        elif axis != "x":
            self.fail(node, f"fov_axis '{axis}': expected x, y, diagonal, smaller or larger")
        return math.degrees(2 * math.atan(t))

    def film(self, node: _Node):
        if node.attrs.get("type") != "hdrfilm":
            self.fail(node, f"unsupported film type '{node.attrs.get('type')}' (supported: hdrfilm)")
        props, nested = self.properties(node)
        width = self.int_value(props.pop("width")) if "width" in props else 768
        height = self.int_value(props.pop("height")) if "height" in props else 576
        if width < 1 or height < 1:
            self.fail(node, f"film size {width}x{height}: must be positive")
        rfilter, stddev = "gaussian", 0.5
        for child in nested:
            if child.tag != "rfilter":
                self.fail(child, "unexpected element inside <film> (supported: rfilter)")
            rfilter, stddev = self.rfilter(child)
        crop = None
        keys = ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")
        if any(k in props for k in keys):
            x = self.int_value(props.pop(keys[0])) if keys[0] in props else 0
            y = self.int_value(props.pop(keys[1])) if keys[1] in props else 0
            w = self.int_value(props.pop(keys[2])) if keys[2] in props else width
            h = self.int_value(props.pop(keys[3])) if keys[3] in props else height
            if x < 0 or y < 0 or w < 1 or h < 1 or x + w > width or y + h > height:
                self.fail(node, f"crop window ({x}, {y}, {w}, {h}) outside the {width}x{height} film")
            crop = (x, y, w, h)
        for name in ("pixel_format", "component_format", "file_format"):  # output only
            if name in props:
                self.string_value(props.pop(name))
        if "sample_border" in props:
            self.bool_value(props.pop("sample_border"))
        self.leftovers(node, props, "film")
        return width, height, rfilter, stddev, crop

    def rfilter(self, node: _Node):
        kind = node.attrs.get("type")
        props, nested = self.properties(node)
        if nested:
            self.fail(nested[0], "unexpected element inside <rfilter>")
        if kind == "box":
            if "radius" in props and abs(self.float_value(props.pop("radius")) - 0.5) > 1e-9:
                self.fail(node, "box filters of a radius other than 0.5 px are not supported")
            self.leftovers(node, props, "rfilter")
            return "box", 0.5
        if kind == "gaussian":
            stddev = self.float_value(props.pop("stddev")) if "stddev" in props else 0.5
            if not stddev > 0:
                self.fail(node, f"stddev {stddev}: must be > 0")
            self.leftovers(node, props, "rfilter")
            return "gaussian", stddev
        self.fail(node, f"unsupported rfilter type '{kind}' (supported: box, gaussian)")

    def sampler(self, node: _Node) -> None:
        kind = node.attrs.get("type")
        if kind not in ("independent", "stratified", "multijitter", "orthogonal", "ldsampler"):
            self.fail(node, f"unsupported sampler type '{kind}'")
        props, nested = self.properties(node)
        if nested:
            self.fail(nested[0], "unexpected element inside <sampler>")
        if "sample_count" in props:
            self.result.spp = self.int_value(props.pop("sample_count"))
            if self.result.spp < 1:
                self.fail(node, f"sample_count {self.result.spp}: must be >= 1")
        if "seed" in props:
            self.result.seed = self.int_value(props.pop("seed"))
        if "jitter" in props:  # edgepath's own sample pattern
            self.bool_value(props.pop("jitter"))
        self.leftovers(node, props, "sampler")

    # shapes

    def shape(self, node: _Node, index: int) -> Mesh:
        kind = node.attrs.get("type")
        if kind not in ("obj", "ply", "rectangle", "cube", "sphere", "disk"):
            self.fail(node, f"unsupported shape type '{kind}' (supported: obj, ply, rectangle, "
                            "cube, sphere, disk)")
        sid = node.attrs.get("id", f"shape_{index}")
        if sid in self.result.shapes:
            self.fail(node, f"shape id '{sid}' used twice")
        props, nested = self.properties(node)
        for name, p in list(props.items()):
            if p.tag in ("ref", "bsdf", "emitter"):
                props.pop(name)
                if p not in nested:
                    nested.append(p)
        material, emission = None, None
        for child in nested:
            target = self.deref(child, ("bsdf", "emitter"))
            if target.tag == "bsdf":
                if material is not None:
                    self.fail(child, "a shape takes one BSDF")
                material = self.material(target)
            elif target.tag == "emitter":
                if emission is not None:
                    self.fail(child, "a shape takes one emitter")
                emission = self.area(target)
            else:
                self.fail(child, "unexpected element inside <shape> (supported: bsdf, emitter, ref)")
        to_world = self.transform(props.pop("to_world")) if "to_world" in props else \
            torch.eye(4, dtype=torch.float64)
        flip = self.bool_value(props.pop("flip_normals")) if "flip_normals" in props else False

        normals = None
        smooth = False
        if kind in ("obj", "ply"):
            if "filename" not in props:
                self.fail(node, "missing <string name=\"filename\">")
            filename = self.file(props["filename"], self.string_value(props.pop("filename")))
            face_normals = self.bool_value(props.pop("face_normals")) if "face_normals" in props else False
            flip_uv = True
            if kind == "obj" and "flip_tex_coords" in props:
                flip_uv = self.bool_value(props.pop("flip_tex_coords"))
            try:
                mesh = _merge(load_obj(filename)) if kind == "obj" else load_ply(filename)
            except (ValueError, OSError) as error:
                self.fail(node, str(error))
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
                center = self.vector_value(props.pop("center")) if "center" in props else [0, 0, 0]
                radius = self.float_value(props.pop("radius")) if "radius" in props else 1.0
                if not radius > 0:
                    self.fail(node, f"radius {radius}: must be > 0")
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
        self.leftovers(node, props, "shape")

        vertices = vertices @ to_world[:3, :3].T + to_world[:3, 3]
        if normals is not None:
            inverse, singular = torch.linalg.inv_ex(to_world[:3, :3])
            if singular:
                self.fail(node, "to_world is singular (a zero scale?): the normals have no transform")
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
        self.result.shapes[sid] = mesh
        self.result.shape_ids.append(sid)
        return mesh

    def area(self, node: _Node) -> torch.Tensor:
        if node.attrs.get("type") != "area":
            self.fail(node, f"unsupported emitter type '{node.attrs.get('type')}' inside a shape "
                            "(supported: area)")
        props, nested = self.properties(node)
        if "radiance" not in props:
            self.fail(node, "missing radiance")
        radiance = self.colour(props.pop("radiance"))
        for child in nested:
            if child.attrs.get("name") != "radiance":
                self.fail(child, "unexpected element inside <emitter>")
        self.leftovers(node, props, "emitter")
        return radiance

    def environment(self, node: _Node) -> EnvironmentMap:
        kind = node.attrs.get("type")
        props, nested = self.properties(node)
        for child in nested:
            if child.attrs.get("name") != "radiance":
                self.fail(child, "unexpected element inside <emitter>")
        if kind == "constant":
            radiance = self.colour(props.pop("radiance")) if "radiance" in props else \
                torch.ones(3)
            if radiance.dim() != 1:
                self.fail(node, "a constant emitter's radiance must be a constant, not a texture")
            self.leftovers(node, props, "emitter")
            return EnvironmentMap(values=radiance.reshape(1, 1, 3).contiguous())
        if kind == "envmap":
            if "filename" not in props:
                self.fail(node, "missing <string name=\"filename\">")
            filename = self.file(props["filename"], self.string_value(props.pop("filename")))
            scale = self.float_value(props.pop("scale")) if "scale" in props else 1.0
            to_world = None
            if "to_world" in props:
                m = self.transform(props.pop("to_world"))
                r = m[:3, :3]
                if not torch.allclose(r.T @ r, torch.eye(3, dtype=torch.float64), atol=1e-6) \
                        or float(torch.linalg.det(r)) < 0:
                    self.fail(node, "an envmap's to_world must be a rotation")
                to_world = m.to(torch.float32)
            self.leftovers(node, props, "emitter")
            return EnvironmentMap(values=_texture_rgb(filename), to_world=to_world, scale=scale)
        if kind == "area":
            self.fail(node, "area emitters belong inside a <shape>")
        self.fail(node, f"unsupported emitter type '{kind}' (supported: area, constant, envmap)")

    # materials

    def material(self, node: _Node) -> Material:
        if id(node) in self.bsdf_cache:
            return self.bsdf_cache[id(node)]
        kind = node.attrs.get("type")
        props, nested = self.properties(node)
        if kind == "twosided":
            inner = [c for c in nested if c.tag in ("bsdf", "ref")]
            if len(inner) != 1 or len(nested) != 1:
                self.fail(node, "twosided takes exactly one BSDF (different BSDFs per side are "
                                "not supported)")
            base = self.material(self.deref(inner[0], ("bsdf",)))
            props.pop(inner[0].attrs.get("name"), None)
            self.leftovers(node, props, "bsdf")
            material = Material(diffuse=base.diffuse, specular=base.specular,
                                roughness=base.roughness, two_sided=True)
            self.result.bsdf_keys[id(material)] = {
                k: "brdf_0." + v for k, v in self.result.bsdf_keys[id(base)].items()}
        else:
            for child in nested:
                if child.tag != "texture" and child.tag != "ref":
                    self.fail(child, "unexpected element inside <bsdf>")
                if child.tag == "texture" and "name" not in child.attrs:
                    self.fail(child, "a texture inside a <bsdf> needs a name (the property it sets)")
            refs = [c for c in nested if c.tag == "ref"]
            for r in refs:
                props[self.attr(r, "name")] = r
            material = self.simple_material(node, kind, props)
            self.result.bsdf_keys[id(material)] = _BSDF_KEYS[kind]
        self.bsdf_cache[id(node)] = material
        if "id" in node.attrs:
            self.result.bsdfs[node.attrs["id"]] = material
        return material

    def alpha(self, node: _Node, props: Dict[str, _Node]):
        dist = self.string_value(props.pop("distribution")) if "distribution" in props else "beckmann"
        if dist not in ("ggx", "beckmann"):
            self.fail(node, f"distribution '{dist}': expected ggx or beckmann")
        if dist == "beckmann":
            warnings.warn(f"{self.path}:{node.line}: {node.describe()}: the Beckmann distribution "
                          "(Mitsuba's default) is rendered as GGX with the same alpha",
                          stacklevel=5)
        if "alpha_u" in props or "alpha_v" in props:
            if "alpha" in props or "alpha_u" not in props or "alpha_v" not in props:
                self.fail(node, "give alpha, or both alpha_u and alpha_v")
            u = self.float_value(props.pop("alpha_u"))
            v = self.float_value(props.pop("alpha_v"))
            if u != v:
                self.fail(node, "anisotropic roughness (alpha_u != alpha_v) is not supported")
            return u
        if "alpha" in props:
            value = self.colour(props.pop("alpha"), channels=1)
            return float(value[0]) if value.dim() == 1 else value
        return 0.1

    def ior(self, node: _Node, props: Dict[str, _Node], name: str, default: float) -> float:
        if name not in props:
            return default
        p = props.pop(name)
        if p.tag == "string":
            key = self.string_value(p).lower()
            if key not in NAMED_IOR:
                self.fail(p, f"unknown IOR name '{key}' (known: {', '.join(sorted(NAMED_IOR))})")
            return NAMED_IOR[key]
        return self.float_value(p)

    def simple_material(self, node: _Node, kind: str, props: Dict[str, _Node]) -> Material:
        if "sample_visible" in props:  # a sampling choice: the same expected image
            self.bool_value(props.pop("sample_visible"))
        if kind == "diffuse":
            reflectance = self.colour(props.pop("reflectance")) if "reflectance" in props else \
                torch.full((3,), 0.5)
            self.leftovers(node, props, "bsdf")
            return Material(diffuse=reflectance)
        if kind == "roughconductor":
            alpha = self.alpha(node, props)
            if "material" in props and ("eta" in props or "k" in props):
                self.fail(node, "give material or eta and k, not both")
            if "eta" in props or "k" in props:
                if "eta" not in props or "k" not in props:
                    self.fail(node, "give both eta and k")
                eta, k = self.colour(props.pop("eta")), self.colour(props.pop("k"))
                if eta.dim() != 1 or k.dim() != 1:
                    self.fail(node, "eta and k must be constants")
                f0 = ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)
            else:
                # Mitsuba's default: "none", a perfect white reflector (eta 0, k 1: F0 = 1)
                name = self.string_value(props.pop("material")) if "material" in props else "none"
                if name not in CONDUCTOR_F0:
                    self.fail(node, f"conductor material '{name}' is not supported (supported: "
                                    f"{', '.join(CONDUCTOR_F0)}; or give eta and k)")
                f0 = torch.tensor(CONDUCTOR_F0[name])
            if "specular_reflectance" in props:
                f0 = f0 * self.colour(props.pop("specular_reflectance"))
            self.leftovers(node, props, "bsdf")
            return Material(diffuse=torch.zeros(3), specular=f0.to(torch.float32).contiguous(),
                            roughness=alpha)
        if kind == "roughplastic":
            alpha = self.alpha(node, props)
            int_ior = self.ior(node, props, "int_ior", NAMED_IOR["polypropylene"])
            ext_ior = self.ior(node, props, "ext_ior", NAMED_IOR["air"])
            if not int_ior > 0 or not ext_ior > 0:
                self.fail(node, "indices of refraction must be > 0")
            if "nonlinear" in props:
                if self.bool_value(props["nonlinear"]):
                    self.fail(props["nonlinear"], "nonlinear=true is not supported")
                props.pop("nonlinear")
            diffuse = self.colour(props.pop("diffuse_reflectance")) \
                if "diffuse_reflectance" in props else torch.full((3,), 0.5)
            f0 = ((int_ior - ext_ior) / (int_ior + ext_ior)) ** 2
            specular = torch.full((3,), f0)
            if "specular_reflectance" in props:
                specular = specular * self.colour(props.pop("specular_reflectance"))
            self.leftovers(node, props, "bsdf")
            return Material(diffuse=diffuse, specular=specular.contiguous(), roughness=alpha)
        self.fail(node, f"unsupported bsdf type '{kind}' (supported: diffuse, roughconductor, "
                        "roughplastic, twosided)")


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
    loader = _Loader(path, {})
    try:
        return loader.load(params)
    except RecursionError:
        # Nesting is bounded when parsing: only <ref>s that lead back into themselves recurse.
        node = loader.last_ref
        where = path if node is None else f"{path}:{node.line}: {node.describe()}"
        raise MitsubaError(f"{where}: refers to an element that contains it (a cycle of "
                           "references)") from None


# ---- geometry ------------------------------------------------------------------------------

def _rotation(axis: torch.Tensor, degrees: float, node: _Node, loader: _Loader) -> torch.Tensor:
    n = float(axis.norm())
    if n == 0:
        loader.fail(node, "rotation axis is zero")
    a = axis / n
    angle = math.radians(degrees)
    k = torch.tensor([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]], dtype=torch.float64)
    return torch.eye(3, dtype=torch.float64) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _look_at(origin, target, up, node: _Node, loader: _Loader) -> torch.Tensor:
    """Mitsuba's look_at: columns left, up, forward, origin."""
    o, t, u = (torch.tensor(x, dtype=torch.float64) for x in (origin, target, up))
    d = t - o
    if float(d.norm()) == 0:
        loader.fail(node, "origin and target coincide")
    d = d / d.norm()
    left = torch.linalg.cross(u, d)
    if float(left.norm()) < 1e-12:
        loader.fail(node, "up is parallel to the viewing direction")
    left = left / left.norm()
    new_up = torch.linalg.cross(d, left)
    m = torch.eye(4, dtype=torch.float64)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


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
