"""The ``<integrator>`` of Mitsuba scene files: its type, ``max_depth`` and ``hide_emitters``.

Every type maps onto edgepath's one path tracer (docs/scene-files.md says what differs):
``path``, ``prb``, ``prb_basic`` and ``prb_projective`` with their ``max_depth``;
``direct_projective`` with its ``max_depth``, 2 (direct light) by default; ``direct``, which
has no ``max_depth``, as the path tracer with direct light only (``max_depth`` 2)."""

from __future__ import annotations

from .xml import Node, Reader

# Integrator type -> its default max_depth (-1: unbounded).
DEFAULT_DEPTH = {"path": -1, "prb": -1, "prb_basic": -1, "prb_projective": -1,
                 "direct": 2, "direct_projective": 2}


def load_integrator(ctx: Reader, node: Node) -> None:
    kind = node.attrs.get("type")
    if kind not in DEFAULT_DEPTH:
        ctx.fail(node, f"unsupported integrator type '{kind}' (supported: "
                       f"{', '.join(DEFAULT_DEPTH)})")
    props, nested = ctx.properties(node)
    if nested:
        ctx.fail(nested[0], "unexpected element inside <integrator>")
    if kind == "direct" and "max_depth" in props:
        ctx.fail(props["max_depth"], "the direct integrator has no max_depth (Mitsuba refuses "
                                     "it too): use path for deeper paths")
    depth = ctx.int_value(props.pop("max_depth")) if "max_depth" in props else DEFAULT_DEPTH[kind]
    if depth == 0 or depth < -1:
        ctx.fail(node, f"max_depth {depth}: must be -1 (unbounded) or >= 1")
    ctx.result.max_bounces = None if depth == -1 else depth - 1
    if "rr_depth" in props:  # edgepath does not stop paths early: same expected image
        ctx.int_value(props.pop("rr_depth"))
    if kind == "direct":  # sample counts per technique: the same expected image
        for name in ("emitter_samples", "bsdf_samples", "shading_samples"):
            if name in props and ctx.int_value(props.pop(name)) < 1:
                ctx.fail(node, f"{name} must be >= 1")
    if kind in ("prb_projective", "direct_projective"):  # how they sample edges
        for name in ("sppc", "sppp", "sppi", "guiding_rounds"):
            if name in props:
                ctx.int_value(props.pop(name))
        if "guiding" in props:
            ctx.string_value(props.pop("guiding"))
    if "hide_emitters" in props:
        ctx.result.hide_emitters = ctx.bool_value(props.pop("hide_emitters"))
    ctx.leftovers(node, props, "integrator")
