"""Checks at the border between the user's scene and the core.

Here: Python types, devices, dtypes and shapes, and the conversions the core needs
(float32 / int32, C-contiguous), which copy only when needed and never touch the caller's
tensors. The C++ core checks values (NaN/Inf, index ranges, degenerate triangles, camera
degeneracies) when the scene is built; both name fields the same way, e.g.
``meshes[1].indices: index 7 out of range for 3 vertices``.
"""

from __future__ import annotations

import numbers
from typing import Optional, Sequence, Union

import numpy as np
import torch

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
INT32_MAX = _INT32_MAX

# A shape spec is a tuple of ints (exact sizes) and strings (any size >= `min_rows`, named in
# messages), e.g. ("N", 3).
Shape = Sequence[Union[int, str]]


def fail(field: str, message: str):
    raise ValueError(f"{field}: {message}")


def _shape_str(shape: Sequence) -> str:
    if len(shape) == 1:
        return f"({shape[0]},)"
    return "(" + ", ".join(str(s) for s in shape) + ")"


def _holds_tensor(value) -> bool:
    if isinstance(value, torch.Tensor):
        return True
    return isinstance(value, (list, tuple)) and any(_holds_tensor(x) for x in value)


def tensor(value, field: str, dtype: Optional[torch.dtype] = None) -> torch.Tensor:
    """`value` as a torch.Tensor on the CPU. A tensor is taken as it is; a list, tuple or numpy
    array is copied into a new tensor (of ``dtype`` where given), which never requires grad."""
    if isinstance(value, (list, tuple, np.ndarray)):
        if _holds_tensor(value):
            fail(field, "a list holding tensors: build the tensor with torch.stack or torch.cat "
                        "so that gradients reach them")
        try:
            array = np.array(value, dtype=None if dtype is None else np.float32)
        except (TypeError, ValueError) as e:
            fail(field, f"cannot convert the {type(value).__name__} to a tensor ({e})")
        if array.dtype.kind not in "biuf":
            fail(field, f"expected numbers, got a {type(value).__name__} of {array.dtype}")
        return torch.from_numpy(array)
    if not isinstance(value, torch.Tensor):
        fail(field, f"expected a torch.Tensor, a list or a numpy array, got {type(value).__name__}")
    if value.device.type != "cpu":
        fail(field, f"tensor is on device '{value.device}', but edgepath renders on the CPU "
                    "(move it with .cpu())")
    return value


def check_shape(t: torch.Tensor, field: str, shape: Shape, min_rows: int = 1) -> None:
    ok = t.dim() == len(shape)
    if ok:
        for size, spec in zip(t.shape, shape):
            if isinstance(spec, str):
                ok = ok and size >= min_rows
            else:
                ok = ok and size == spec
    if not ok:
        if t.dim() == len(shape) and any(isinstance(s, str) and n < min_rows
                                         for n, s in zip(t.shape, shape)):
            fail(field, f"is empty: shape {_shape_str(tuple(t.shape))}, expected {_shape_str(shape)}"
                        f" with {'/'.join(s for s in shape if isinstance(s, str))} >= {min_rows}")
        fail(field, f"expected shape {_shape_str(shape)}, got {_shape_str(tuple(t.shape))}")


def float_tensor(value, field: str, shape: Shape, min_rows: int = 1) -> torch.Tensor:
    """A floating-point tensor (or a list / numpy array of numbers) of the given shape, as
    float32 C-contiguous (copied only if needed). The conversion is a differentiable torch op:
    the result stays attached to the caller's tensor, so gradients flow back to it (and to its
    dtype)."""
    t = tensor(value, field, torch.float32)
    if not t.dtype.is_floating_point:
        fail(field, f"expected a floating-point tensor, got {t.dtype}")
    check_shape(t, field, shape, min_rows)
    return t.to(torch.float32).contiguous()


def scalar_tensor(value, field: str) -> torch.Tensor:
    """A Python number or a one-element floating tensor, as a float32 tensor of shape (1,)
    (attached to the caller's tensor)."""
    number(value, field)  # type and shape checks
    if isinstance(value, torch.Tensor):
        if not value.dtype.is_floating_point:
            fail(field, f"expected a floating-point tensor, got {value.dtype}")
        return value.to(torch.float32).reshape(1)
    return torch.tensor([float(value)], dtype=torch.float32)


def index_tensor(value, field: str, shape: Shape = ("M", 3)) -> torch.Tensor:
    """An int32 or int64 index tensor (or a list / numpy array of ints), as int32
    C-contiguous. int64 values must fit in int32 (narrowing must not change an index); range
    checks against vertex counts are the core's."""
    t = tensor(value, field)
    if t.dtype not in (torch.int32, torch.int64):
        fail(field, f"expected an int32 or int64 tensor, got {t.dtype}")
    check_shape(t, field, shape)
    t = t.detach()
    if t.dtype == torch.int64 and t.numel() > 0:
        lo, hi = int(t.min()), int(t.max())
        if lo < _INT32_MIN or hi > _INT32_MAX:
            bad = lo if lo < _INT32_MIN else hi
            fail(field, f"index {bad} does not fit in int32")
    return t.to(torch.int32).contiguous()


def number(value, field: str) -> float:
    """A Python real number or a 0-d (or one-element) floating tensor or numpy array, as a
    float."""
    if isinstance(value, bool):
        fail(field, "expected a number, got bool")
    if isinstance(value, numbers.Real):
        return float(value)
    if isinstance(value, np.ndarray):
        value = tensor(value, field)
    if isinstance(value, torch.Tensor):
        t = tensor(value, field)
        if not t.dtype.is_floating_point and t.dtype not in (torch.int32, torch.int64):
            fail(field, f"expected a number, got a tensor of {t.dtype}")
        if t.numel() != 1 or t.dim() > 1:
            fail(field, f"expected a number or a 0-d tensor, got shape {_shape_str(tuple(t.shape))}")
        return float(t.detach().reshape(()).item())
    fail(field, f"expected a number, got {type(value).__name__}")


def integer(value, field: str, minimum: Optional[int] = None, maximum: Optional[int] = None) -> int:
    """A Python int (not bool), optionally at least `minimum` and at most `maximum`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        fail(field, f"expected an int, got {type(value).__name__}")
    value = int(value)
    if minimum is not None and value < minimum:
        fail(field, f"must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        fail(field, f"must be <= {maximum}, got {value}")
    return value


def boolean(value, field: str) -> bool:
    if not isinstance(value, bool):
        fail(field, f"expected True or False, got {type(value).__name__}")
    return value


def choice(value, field: str, options: dict):
    if not isinstance(value, str) or value not in options:
        fail(field, f"expected one of {', '.join(repr(k) for k in options)}, got {value!r}")
    return options[value]


def constant(value, field: str, channels: int) -> torch.Tensor:
    """A constant (as ``texture`` takes one; not a texture), as a float32 tensor of shape
    (channels,), attached to the caller's tensor like ``float_tensor``."""
    shape = tuple(getattr(value, "shape", ()))
    if len(shape) >= 2 and shape[:2] != (1, 1):  # (a 1x1 texture is a constant)
        _not_a_constant(field, channels, shape)
    return texture(value, field, channels).reshape(channels)


def _not_a_constant(field: str, channels: int, shape: Sequence) -> None:
    expected = "(1,)" if channels == 1 else f"({channels},) or (1,)"
    fail(field, f"a constant must have shape {expected}, got {_shape_str(tuple(shape))}")


def texture(value, field: str, channels: int) -> torch.Tensor:
    """A constant or a texture, as a float32 (H, W, channels) tensor; a constant is 1x1.
    Attached to the caller's tensor like ``float_tensor``.

    Constants: a Python number, a 0-d tensor, or a tensor, list or numpy array of shape
    (channels,) or (1,). Textures: (H, W, channels); with channels == 1 also (H, W)."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        return torch.full((1, 1, channels), float(value), dtype=torch.float32)
    t = tensor(value, field, torch.float32)
    if not t.dtype.is_floating_point:
        fail(field, f"expected a floating-point tensor, got {t.dtype}")
    if t.dim() <= 1:
        if t.numel() not in (1, channels):
            _not_a_constant(field, channels, t.shape)
        t = t.to(torch.float32).reshape(1, 1, -1)
        return t.expand(1, 1, channels).contiguous()
    if channels == 1 and t.dim() == 2:
        check_shape(t, field, ("H", "W"))
        return t.to(torch.float32).unsqueeze(-1).contiguous()
    if t.dim() != 3 or t.shape[2] != channels:
        shapes = f"(H, W, {channels})" + (" or (H, W)" if channels == 1 else "")
        fail(field, f"a texture must have shape {shapes}, got {_shape_str(tuple(t.shape))}")
    return float_tensor(t, field, ("H", "W", channels))
