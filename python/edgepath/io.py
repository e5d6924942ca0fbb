"""Files: images (PNG, JPEG, EXR) and OBJ meshes, read and written by the C++ core."""

from __future__ import annotations

import os
from typing import List, Union

import numpy as np
import torch

from . import _core
from .scene import Material, Mesh

PathLike = Union[str, os.PathLike]


def _existing(path: PathLike, what: str) -> str:
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: {what} not found")
    return path


def imread(path: PathLike) -> torch.Tensor:
    """Reads an image as a float32 (H, W, C) tensor of linear values, row 0 at the top.
    PNG/JPEG (sRGB) are linearised; EXR is returned as stored. C is 1 (grey), 2 (grey and
    alpha), 3 (RGB) or 4 (RGBA)."""
    return torch.from_numpy(_core.imread(_existing(path, "image")))


def imwrite(img: Union[torch.Tensor, np.ndarray], path: PathLike) -> None:
    """Writes a (H, W) or (H, W, C) image (C = 1..4) of linear values: .png (sRGB-encoded,
    clamped to [0, 1], 8-bit) or .exr (float32). Accepts torch tensors (any device, any
    float dtype) and numpy arrays; the input is never modified."""
    if isinstance(img, torch.Tensor):
        array = img.detach().to(device="cpu", dtype=torch.float32).contiguous().numpy()
    elif isinstance(img, np.ndarray):
        array = np.ascontiguousarray(img, dtype=np.float32)
    else:
        raise ValueError(f"image: expected a torch.Tensor or numpy.ndarray, got {type(img).__name__}")
    if array.ndim not in (2, 3) or (array.ndim == 3 and not 1 <= array.shape[2] <= 4):
        raise ValueError(f"image: expected shape (H, W) or (H, W, C) with C in 1..4, "
                         f"got {tuple(array.shape)}")
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise ValueError(f"image: is empty, shape {tuple(array.shape)}")
    _core.imwrite(os.fspath(path), array)


def _texture_rgb(path: str) -> torch.Tensor:
    image = imread(_existing(path, "texture"))
    if image.shape[2] <= 2:  # grey (+ alpha)
        return image[:, :, :1].expand(-1, -1, 3).contiguous()
    return image[:, :, :3].contiguous()


def load_obj(path: PathLike) -> List[Mesh]:
    """Loads an OBJ file (and its MTL materials) as one Mesh per material. uvs have v flipped
    (v = 0 is the top row of a texture image, as in Mitsuba). Materials: Kd (or map_Kd, read
    with imread) as diffuse, Ks as specular, roughness sqrt(2 / (Ns + 2)); Ke, if not black,
    makes the mesh an emitter. Faces without a material get edgepath's default material."""
    path = _existing(path, "OBJ file")
    meshes = []
    for m in _core.load_obj(path):
        info = m["material"]
        material = None
        if info["defined"]:
            texture = info["diffuse_texture"]
            material = Material(
                diffuse=_texture_rgb(texture) if texture else torch.tensor(info["diffuse"]),
                specular=torch.tensor(info["specular"]),
                roughness=float(info["roughness"]),
            )
        emission = torch.tensor(info["emission"]) if any(info["emission"]) else None

        def tensor(key):
            return None if m[key] is None else torch.from_numpy(m[key])

        meshes.append(Mesh(vertices=tensor("positions"), indices=tensor("indices"),
                           uvs=tensor("uvs"), normals=tensor("normals"),
                           uv_indices=tensor("uv_indices"), normal_indices=tensor("normal_indices"),
                           material=material, emission=emission))
    return meshes
