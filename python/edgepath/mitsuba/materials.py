"""BSDFs of Mitsuba scene files (diffuse, conductor, roughconductor, plastic, roughplastic,
dielectric, roughdielectric, twosided, normalmap), mapped onto edgepath's ``Material`` kinds
(diffuse + GGX, mirror, glass, plastic), approximately where Mitsuba's model differs (see
docs/scene-files.md)."""

from __future__ import annotations

import warnings
from typing import Dict

import torch

from ..scene import Material
from .textures import colour
from .xml import Node, Reader

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


# Mitsuba's names of the Material fields a BSDF type sets (parameters() adds .value / .data).
# A material made without a <bsdf> (a shape's default) is a diffuse one.
DIFFUSE_KEYS = {"diffuse": "reflectance"}
BSDF_KEYS = {"diffuse": DIFFUSE_KEYS, "roughplastic": {"diffuse": "diffuse_reflectance",
                                                       "specular": "specular_reflectance",
                                                       "roughness": "alpha", "ior": "eta"},
             "plastic": {"diffuse": "diffuse_reflectance", "specular": "specular_reflectance",
                         "ior": "eta"},
             "roughconductor": {"roughness": "alpha"}, "conductor": {},
             "dielectric": {"ior": "eta"}, "roughdielectric": {"ior": "eta", "roughness": "alpha"}}


def load_bsdf(ctx: Reader, node: Node) -> Material:
    if id(node) in ctx.bsdf_cache:
        return ctx.bsdf_cache[id(node)]
    kind = node.attrs.get("type")
    props, nested = ctx.properties(node)
    if kind == "twosided":
        inner = [c for c in nested if c.tag in ("bsdf", "ref")]
        if len(inner) != 1 or len(nested) != 1:
            ctx.fail(node, "twosided takes exactly one BSDF (different BSDFs per side are "
                           "not supported)")
        base = load_bsdf(ctx, ctx.deref(inner[0], ("bsdf",)))
        if base.kind == "dielectric":
            ctx.fail(node, "twosided cannot hold a dielectric (it transmits; Mitsuba refuses "
                           "it too): a dielectric is two-sided already")
        props.pop(inner[0].attrs.get("name"), None)
        ctx.leftovers(node, props, "bsdf")
        material = Material(diffuse=base.diffuse, specular=base.specular,
                            roughness=base.roughness, two_sided=True, kind=base.kind,
                            ior=base.ior, normal_map=base.normal_map,
                            nonlinear=base.nonlinear)
        ctx.result.bsdf_keys[id(material)] = {
            k: "brdf_0." + v for k, v in ctx.result.bsdf_keys[id(base)].items()}
    elif kind == "normalmap":
        material = normal_mapped(ctx, node, props, nested)
    else:
        for child in nested:
            if child.tag != "texture" and child.tag != "ref":
                ctx.fail(child, "unexpected element inside <bsdf>")
            if child.tag == "texture" and "name" not in child.attrs:
                ctx.fail(child, "a texture inside a <bsdf> needs a name (the property it sets)")
        refs = [c for c in nested if c.tag == "ref"]
        for r in refs:
            props[ctx.attr(r, "name")] = r
        material = simple_bsdf(ctx, node, kind, props)
        ctx.result.bsdf_keys[id(material)] = BSDF_KEYS[kind]
    ctx.bsdf_cache[id(node)] = material
    if "id" in node.attrs:
        ctx.result.bsdfs[node.attrs["id"]] = material
    return material


def normal_mapped(ctx: Reader, node: Node, props: Dict[str, Node], nested) -> Material:
    """<bsdf type="normalmap">: its one nested BSDF with the texture `normalmap` as the
    material's normal_map (a bitmap, loaded as Mitsuba loads it: give raw="true" to keep 8-bit
    values as stored)."""
    if "normalmap" not in props:
        ctx.fail(node, "normalmap needs a <texture name=\"normalmap\">")
    normal_map = colour(ctx, props.pop("normalmap"), channels=3)
    if normal_map.dim() == 1:
        normal_map = normal_map.reshape(1, 1, 3)
    inner = []
    for child in nested:
        target = ctx.deref(child, ("bsdf", "texture"))
        if target.tag == "bsdf":
            inner.append(target)
            props.pop(child.attrs.get("name"), None)
        elif child.attrs.get("name") != "normalmap":
            ctx.fail(child, "unexpected texture inside normalmap (expected one named 'normalmap')")
    if len(inner) != 1:
        ctx.fail(node, "normalmap takes exactly one BSDF")
    base = load_bsdf(ctx, inner[0])
    if base.normal_map is not None:
        ctx.fail(node, "a normalmap inside a normalmap is not supported")
    ctx.leftovers(node, props, "bsdf")
    material = Material(diffuse=base.diffuse, specular=base.specular, roughness=base.roughness,
                        two_sided=base.two_sided, kind=base.kind, ior=base.ior,
                        normal_map=normal_map, nonlinear=base.nonlinear)
    keys = {k: "nested_bsdf." + v for k, v in ctx.result.bsdf_keys[id(base)].items()}
    keys["normal_map"] = "normalmap"
    ctx.result.bsdf_keys[id(material)] = keys
    return material


def roughness_alpha(ctx: Reader, node: Node, props: Dict[str, Node]):
    dist = ctx.string_value(props.pop("distribution")) if "distribution" in props else "beckmann"
    if dist not in ("ggx", "beckmann"):
        ctx.fail(node, f"distribution '{dist}': expected ggx or beckmann")
    if dist == "beckmann":
        warnings.warn(f"{ctx.path}:{node.line}: {node.describe()}: the Beckmann distribution "
                      "(Mitsuba's default) is rendered as GGX with the same alpha",
                      stacklevel=5)
    if "alpha_u" in props or "alpha_v" in props:
        if "alpha" in props or "alpha_u" not in props or "alpha_v" not in props:
            ctx.fail(node, "give alpha, or both alpha_u and alpha_v")
        u = ctx.float_value(props.pop("alpha_u"))
        v = ctx.float_value(props.pop("alpha_v"))
        if u != v:
            ctx.fail(node, "anisotropic roughness (alpha_u != alpha_v) is not supported")
        return u
    if "alpha" in props:
        value = colour(ctx, props.pop("alpha"), channels=1)
        return float(value[0]) if value.dim() == 1 else value
    return 0.1


def ior_value(ctx: Reader, node: Node, props: Dict[str, Node], name: str,
              default: float) -> float:
    if name not in props:
        return default
    p = props.pop(name)
    if p.tag == "string":
        key = ctx.string_value(p).lower()
        if key not in NAMED_IOR:
            ctx.fail(p, f"unknown IOR name '{key}' (known: {', '.join(sorted(NAMED_IOR))})")
        return NAMED_IOR[key]
    return ctx.float_value(p)


def conductor_f0(ctx: Reader, node: Node, props: Dict[str, Node]) -> torch.Tensor:
    """A conductor's reflectance at normal incidence (float32, (3,)): from eta and k, or its
    named material ("none", a perfect mirror, by default), times specular_reflectance."""
    if "material" in props and ("eta" in props or "k" in props):
        ctx.fail(node, "give material or eta and k, not both")
    if "eta" in props or "k" in props:
        if "eta" not in props or "k" not in props:
            ctx.fail(node, "give both eta and k")
        eta, k = colour(ctx, props.pop("eta")), colour(ctx, props.pop("k"))
        if eta.dim() != 1 or k.dim() != 1:
            ctx.fail(node, "eta and k must be constants")
        f0 = ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)
    else:
        # Mitsuba's default: "none", a perfect white reflector (eta 0, k 1: F0 = 1)
        name = ctx.string_value(props.pop("material")) if "material" in props else "none"
        if name not in CONDUCTOR_F0:
            ctx.fail(node, f"conductor material '{name}' is not supported (supported: "
                           f"{', '.join(CONDUCTOR_F0)}; or give eta and k)")
        f0 = torch.tensor(CONDUCTOR_F0[name])
    if "specular_reflectance" in props:
        f0 = f0 * colour(ctx, props.pop("specular_reflectance"))
    return f0.to(torch.float32).contiguous()


def simple_bsdf(ctx: Reader, node: Node, kind: str, props: Dict[str, Node]) -> Material:
    if "sample_visible" in props:  # a sampling choice: the same expected image
        ctx.bool_value(props.pop("sample_visible"))
    if kind == "diffuse":
        reflectance = colour(ctx, props.pop("reflectance")) if "reflectance" in props else \
            torch.full((3,), 0.5)
        ctx.leftovers(node, props, "bsdf")
        return Material(diffuse=reflectance)
    if kind in ("conductor", "roughconductor"):
        alpha = roughness_alpha(ctx, node, props) if kind == "roughconductor" else None
        f0 = conductor_f0(ctx, node, props)
        ctx.leftovers(node, props, "bsdf")
        if kind == "conductor":
            return Material(kind="conductor", specular=f0)
        return Material(diffuse=torch.zeros(3), specular=f0, roughness=alpha)
    if kind in ("dielectric", "roughdielectric"):
        alpha = 0.0
        if kind == "roughdielectric":
            dist = ctx.string_value(props["distribution"]) if "distribution" in props else "beckmann"
            if dist != "ggx":
                ctx.fail(props.get("distribution", node),
                         f"distribution '{dist}'{'' if 'distribution' in props else ' (the default)'}: "
                         "a roughdielectric supports only ggx (give <string name=\"distribution\" "
                         "value=\"ggx\"/>)")
            alpha = roughness_alpha(ctx, node, props)
            if isinstance(alpha, float) and not alpha > 0:
                ctx.fail(node, f"alpha = {alpha:g}: a roughdielectric needs alpha > 0 (use dielectric)")
            if isinstance(alpha, float):
                alpha = torch.tensor(alpha, dtype=torch.float32)
        int_ior = ior_value(ctx, node, props, "int_ior", NAMED_IOR["bk7"])
        ext_ior = ior_value(ctx, node, props, "ext_ior", NAMED_IOR["air"])
        if not int_ior > 0 or not ext_ior > 0:
            ctx.fail(node, "indices of refraction must be > 0")
        eta = int_ior / ext_ior
        if not 0.1 <= eta <= 10:
            ctx.fail(node, f"int_ior / ext_ior = {eta:g}: must be in [0.1, 10]")
        for name in ("specular_reflectance", "specular_transmittance"):
            if name in props:
                value = colour(ctx, props[name])
                if value.dim() != 1 or not bool((value == 1).all()):
                    ctx.fail(props[name], f"{name} other than 1 is not supported")
                props.pop(name)
        ctx.leftovers(node, props, "bsdf")
        return Material(kind="dielectric", ior=torch.tensor(eta, dtype=torch.float32), roughness=alpha)
    if kind in ("plastic", "roughplastic"):
        # Mitsuba's plastic and roughplastic: kind "plastic", smooth (roughness 0) or GGX.
        alpha = 0.0
        if kind == "roughplastic":
            alpha = roughness_alpha(ctx, node, props)
            if not isinstance(alpha, float):
                ctx.fail(node, "a roughplastic's alpha must be a constant (a texture is not supported)")
            if not alpha > 0:
                ctx.fail(node, f"alpha = {alpha:g}: a roughplastic needs alpha > 0 (use plastic)")
        int_ior = ior_value(ctx, node, props, "int_ior", NAMED_IOR["polypropylene"])
        ext_ior = ior_value(ctx, node, props, "ext_ior", NAMED_IOR["air"])
        if not int_ior > 0 or not ext_ior > 0:
            ctx.fail(node, "indices of refraction must be > 0")
        eta = int_ior / ext_ior
        if not 0.1 <= eta <= 10 or abs(eta - 1) < 1e-3:
            ctx.fail(node, f"int_ior / ext_ior = {eta:g}: must be in [0.1, 10] and differ from 1")
        nonlinear = ctx.bool_value(props.pop("nonlinear")) if "nonlinear" in props else False
        diffuse = colour(ctx, props.pop("diffuse_reflectance")) \
            if "diffuse_reflectance" in props else torch.full((3,), 0.5)
        specular = colour(ctx, props.pop("specular_reflectance")) \
            if "specular_reflectance" in props else torch.ones(3)
        ctx.leftovers(node, props, "bsdf")
        return Material(kind="plastic", diffuse=diffuse, specular=specular,
                        roughness=torch.tensor(alpha, dtype=torch.float32),
                        ior=torch.tensor(eta, dtype=torch.float32), nonlinear=nonlinear)
    ctx.fail(node, f"unsupported bsdf type '{kind}' (supported: diffuse, conductor, "
                   "roughconductor, plastic, roughplastic, dielectric, roughdielectric, twosided, "
                   "normalmap)")
