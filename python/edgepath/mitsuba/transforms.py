"""Transforms of Mitsuba scene files: ``<transform>`` and its operations (translate, scale,
rotate, matrix, lookat) as 4x4 float64 matrices."""

from __future__ import annotations

import math

import torch

from .xml import Node, Reader


def transform(ctx: Reader, node: Node) -> torch.Tensor:
    if node.tag != "transform":
        ctx.fail(node, "expected a <transform>")
    m = torch.eye(4, dtype=torch.float64)
    for op in node.children:
        m = transform_op(ctx, op) @ m
    return m


def transform_op(ctx: Reader, op: Node) -> torch.Tensor:
    t = torch.eye(4, dtype=torch.float64)
    a = op.attrs
    if op.tag == "translate":
        v = ctx.numbers(op, a["value"], (3,)) if "value" in a else \
            [ctx.numbers(op, a.get(k, "0"), (1,))[0] for k in "xyz"]
        t[:3, 3] = torch.tensor(v, dtype=torch.float64)
    elif op.tag == "scale":
        if "value" in a:
            v = ctx.numbers(op, a["value"], (1, 3))
            v = v * 3 if len(v) == 1 else v
        else:
            v = [ctx.numbers(op, a.get(k, "1"), (1,))[0] for k in "xyz"]
        t[:3, :3] = torch.diag(torch.tensor(v, dtype=torch.float64))
    elif op.tag == "rotate":
        axis = ctx.numbers(op, a["value"], (3,)) if "value" in a else \
            [ctx.numbers(op, a.get(k, "0"), (1,))[0] for k in "xyz"]
        angle = ctx.numbers(op, ctx.attr(op, "angle"), (1,))[0]
        t[:3, :3] = _rotation(torch.tensor(axis, dtype=torch.float64), angle, op, ctx)
    elif op.tag == "matrix":
        v = ctx.numbers(op, ctx.attr(op, "value"), (9, 16))
        if len(v) == 9:
            t[:3, :3] = torch.tensor(v, dtype=torch.float64).reshape(3, 3)
        else:
            t = torch.tensor(v, dtype=torch.float64).reshape(4, 4)
    elif op.tag == "lookat":
        origin = ctx.numbers(op, ctx.attr(op, "origin"), (3,))
        target = ctx.numbers(op, ctx.attr(op, "target"), (3,))
        up = ctx.numbers(op, a.get("up", "0 1 0"), (3,))
        t = _look_at(origin, target, up, op, ctx)
    else:
        ctx.fail(op, "unsupported transform operation (supported: translate, rotate, "
                     "scale, matrix, lookat)")
    return t


def _rotation(axis: torch.Tensor, degrees: float, node: Node, ctx: Reader) -> torch.Tensor:
    n = float(axis.norm())
    if n == 0:
        ctx.fail(node, "rotation axis is zero")
    a = axis / n
    angle = math.radians(degrees)
    k = torch.tensor([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]], dtype=torch.float64)
    return torch.eye(3, dtype=torch.float64) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _look_at(origin, target, up, node: Node, ctx: Reader) -> torch.Tensor:
    """Mitsuba's look_at: columns left, up, forward, origin."""
    o, t, u = (torch.tensor(x, dtype=torch.float64) for x in (origin, target, up))
    d = t - o
    if float(d.norm()) == 0:
        ctx.fail(node, "origin and target coincide")
    d = d / d.norm()
    left = torch.linalg.cross(u, d)
    if float(left.norm()) < 1e-12:
        ctx.fail(node, "up is parallel to the viewing direction")
    left = left / left.norm()
    new_up = torch.linalg.cross(d, left)
    m = torch.eye(4, dtype=torch.float64)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m
