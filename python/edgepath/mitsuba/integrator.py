"""The ``<integrator>`` of Mitsuba scene files: its type and ``max_depth``."""

from __future__ import annotations

from .xml import Node, Reader


def load_integrator(ctx: Reader, node: Node) -> None:
    kind = node.attrs.get("type")
    if kind not in ("path", "prb", "prb_basic", "prb_projective", "direct_projective"):
        ctx.fail(node, f"unsupported integrator type '{kind}' (supported: path, prb, "
                       "prb_basic, prb_projective, direct_projective)")
    props, nested = ctx.properties(node)
    if nested:
        ctx.fail(nested[0], "unexpected element inside <integrator>")
    depth = ctx.int_value(props.pop("max_depth")) if "max_depth" in props else -1
    if kind == "direct_projective":
        depth = 2 if depth == -1 else depth
    if depth == 0 or depth < -1:
        ctx.fail(node, f"max_depth {depth}: must be -1 (unbounded) or >= 1")
    ctx.result.max_bounces = None if depth == -1 else depth - 1
    if "rr_depth" in props:  # edgepath does not stop paths early: same expected image
        ctx.int_value(props.pop("rr_depth"))
    if "hide_emitters" in props:
        if ctx.bool_value(props["hide_emitters"]):
            ctx.fail(props["hide_emitters"], "hide_emitters is not supported")
        props.pop("hide_emitters")
    ctx.leftovers(node, props, "integrator")
