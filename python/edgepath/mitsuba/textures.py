"""Textures and colours of Mitsuba scene files: bitmap ``<texture>``s and the constant or
textured colour properties (reflectance, radiance, alpha, ...) that BSDFs and emitters take."""

from __future__ import annotations

import warnings

import torch

from ..io import _texture_rgb, imread, to_srgb
from .xml import Node, Reader


def load_bitmap(ctx: Reader, node: Node, channels: int) -> torch.Tensor:
    key = (id(node), channels)
    if key in ctx.texture_cache:
        return ctx.texture_cache[key]
    if node.attrs.get("type") != "bitmap":
        ctx.fail(node, f"unsupported texture type '{node.attrs.get('type')}' (supported: bitmap)")
    props, nested = ctx.properties(node)
    if nested:
        ctx.fail(nested[0], "unexpected element inside a bitmap")
    filename = ctx.file(props["filename"], ctx.string_value(props.pop("filename"))) \
        if "filename" in props else ctx.fail(node, "missing <string name=\"filename\">")
    raw = ctx.bool_value(props.pop("raw")) if "raw" in props else False
    if "filter_type" in props:
        f = ctx.string_value(props["filter_type"])
        if f != "bilinear":
            ctx.fail(props["filter_type"], f"filter_type '{f}' is not supported (edgepath "
                                           "filters textures bilinearly)")
        props.pop("filter_type")
    if "wrap_mode" in props:
        w = ctx.string_value(props["wrap_mode"])
        if w not in ("repeat", "clamp", "mirror"):
            ctx.fail(props["wrap_mode"], f"unknown wrap_mode '{w}'")
        if w != "repeat":
            warnings.warn(f"{ctx.path}:{props['wrap_mode'].line}: wrap_mode '{w}' is loaded "
                          "as 'repeat' (edgepath textures repeat): texels within half a "
                          "texel of the border differ", stacklevel=4)
        props.pop("wrap_mode")
    ctx.leftovers(node, props, "texture")
    if channels == 3:
        image = _texture_rgb(filename)
    else:
        image = imread(filename)[:, :, :1].contiguous()
    if raw and not filename.lower().endswith((".exr", ".hdr")):
        # imread linearised the 8-bit sRGB values: encode them back (exact up to rounding).
        image = to_srgb(image).contiguous()
    ctx.texture_cache[key] = image
    if "id" in node.attrs:
        ctx.result.textures.setdefault(node.attrs["id"], image)
    return image


def colour(ctx: Reader, node: Node, channels: int = 3) -> torch.Tensor:
    """(channels,) float32 constant or (H, W, channels) texture from a property node."""
    node = ctx.deref(node, ("texture",))
    if node.tag == "texture":
        return load_bitmap(ctx, node, channels)
    if node.tag in ("float", "integer"):
        return torch.full((channels,), ctx.float_value(node), dtype=torch.float32)
    if node.tag == "spectrum":
        text = ctx.attr(node, "value")
        if ":" in text:
            ctx.fail(node, "spectra given as wavelength:value pairs are not supported "
                           "(give one value, or use <rgb>)")
        return torch.full((channels,), ctx.numbers(node, text, (1,))[0], dtype=torch.float32)
    if node.tag == "rgb":
        values = ctx.numbers(node, ctx.attr(node, "value"), (1, 3))
        if len(values) == 1:
            values = values * 3
        if channels == 1:
            if len(set(values)) != 1:
                ctx.fail(node, "expected a single value")
            values = values[:1]
        return torch.tensor(values, dtype=torch.float32)
    ctx.fail(node, "expected <float>, <rgb>, <spectrum> or a bitmap <texture>")
