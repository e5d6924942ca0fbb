"""Emitters of Mitsuba scene files: area lights inside a ``<shape>`` and the environment
(``constant`` or ``envmap``) at the top level."""

from __future__ import annotations

import torch

from ..io import _texture_rgb
from ..scene import EnvironmentMap
from .textures import colour
from .transforms import transform
from .xml import Node, Reader


def load_area(ctx: Reader, node: Node) -> torch.Tensor:
    if node.attrs.get("type") != "area":
        ctx.fail(node, f"unsupported emitter type '{node.attrs.get('type')}' inside a shape "
                       "(supported: area)")
    props, nested = ctx.properties(node)
    if "radiance" not in props:
        ctx.fail(node, "missing radiance")
    radiance = colour(ctx, props.pop("radiance"))
    for child in nested:
        if child.attrs.get("name") != "radiance":
            ctx.fail(child, "unexpected element inside <emitter>")
    ctx.leftovers(node, props, "emitter")
    return radiance


def load_environment(ctx: Reader, node: Node) -> EnvironmentMap:
    kind = node.attrs.get("type")
    props, nested = ctx.properties(node)
    for child in nested:
        if child.attrs.get("name") != "radiance":
            ctx.fail(child, "unexpected element inside <emitter>")
    if kind == "constant":
        radiance = colour(ctx, props.pop("radiance")) if "radiance" in props else \
            torch.ones(3)
        if radiance.dim() != 1:
            ctx.fail(node, "a constant emitter's radiance must be a constant, not a texture")
        ctx.leftovers(node, props, "emitter")
        return EnvironmentMap(values=radiance.reshape(1, 1, 3).contiguous())
    if kind == "envmap":
        if "filename" not in props:
            ctx.fail(node, "missing <string name=\"filename\">")
        filename = ctx.file(props["filename"], ctx.string_value(props.pop("filename")))
        scale = ctx.float_value(props.pop("scale")) if "scale" in props else 1.0
        to_world = None
        if "to_world" in props:
            m = transform(ctx, props.pop("to_world"))
            r = m[:3, :3]
            if not torch.allclose(r.T @ r, torch.eye(3, dtype=torch.float64), atol=1e-6) \
                    or float(torch.linalg.det(r)) < 0:
                ctx.fail(node, "an envmap's to_world must be a rotation")
            to_world = m.to(torch.float32)
        ctx.leftovers(node, props, "emitter")
        return EnvironmentMap(values=_texture_rgb(filename), to_world=to_world, scale=scale)
    if kind == "area":
        ctx.fail(node, "area emitters belong inside a <shape>")
    ctx.fail(node, f"unsupported emitter type '{kind}' (supported: area, constant, envmap)")
