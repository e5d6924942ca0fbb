"""Files: images (PNG, JPEG, EXR) and OBJ meshes, read and written by the C++ core; Radiance
HDR images (.hdr, RGBE) through OpenCV; PLY meshes (read) and OBJ meshes (written) here in
Python. Also the sRGB curve and a picture a notebook shows."""

from __future__ import annotations

import os
import re
from typing import List, Sequence, Union

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


def _is_hdr(path: str) -> bool:
    return os.path.splitext(path)[1].lower() == ".hdr"


def _cv2(path: str):
    try:
        import cv2
    except ImportError as e:  # a dependency of the package; missing only in a broken install
        raise ImportError(f"{path}: .hdr images are read and written with OpenCV "
                          "(pip install opencv-python-headless)") from e
    return cv2


def imread(path: PathLike) -> torch.Tensor:
    """Reads an image as a float32 (H, W, C) tensor of linear values, row 0 at the top.
    PNG/JPEG (sRGB) are linearised; EXR and HDR (Radiance RGBE) are returned as stored. C is
    1 (grey), 2 (grey and alpha), 3 (RGB) or 4 (RGBA); HDR images are RGB."""
    path = _existing(path, "image")
    if _is_hdr(path):
        cv2 = _cv2(path)
        bgr = cv2.imread(path, cv2.IMREAD_UNCHANGED)
        if bgr is None or bgr.ndim != 3 or bgr.shape[2] != 3:
            raise OSError(f"{path}: not a readable Radiance HDR (RGBE) image")
        return torch.from_numpy(np.ascontiguousarray(bgr[:, :, ::-1], dtype=np.float32))
    return torch.from_numpy(_core.imread(path))


def _image_array(img, field: str = "image") -> np.ndarray:
    """A (H, W) or (H, W, C) float32 C-contiguous numpy copy or view of an image (C = 1..4)."""
    if isinstance(img, torch.Tensor):
        array = img.detach().to(device="cpu", dtype=torch.float32).contiguous().numpy()
    elif isinstance(img, np.ndarray):
        array = np.ascontiguousarray(img, dtype=np.float32)
    else:
        raise ValueError(f"{field}: expected a torch.Tensor or numpy.ndarray, got {type(img).__name__}")
    if array.ndim not in (2, 3) or (array.ndim == 3 and not 1 <= array.shape[2] <= 4):
        raise ValueError(f"{field}: expected shape (H, W) or (H, W, C) with C in 1..4, "
                         f"got {tuple(array.shape)}")
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise ValueError(f"{field}: is empty, shape {tuple(array.shape)}")
    return array


def imwrite(img: Union[torch.Tensor, np.ndarray], path: PathLike) -> None:
    """Writes a (H, W) or (H, W, C) image (C = 1..4) of linear values: .png (sRGB-encoded,
    clamped to [0, 1], 8-bit), .exr (float32) or .hdr (Radiance RGBE: grey or RGB,
    non-negative, about 1% precision). Accepts torch tensors (any device, any float dtype)
    and numpy arrays; the input is never modified."""
    array = _image_array(img)
    path = os.fspath(path)
    if not _is_hdr(path):
        _core.imwrite(path, array)
        return
    if array.ndim == 2:
        array = array[:, :, None]
    if array.shape[2] not in (1, 3):
        raise ValueError(f"image: a .hdr file holds grey or RGB, got {array.shape[2]} channels")
    if not np.isfinite(array).all() or (array < 0).any():
        raise ValueError(f"image: a .hdr file holds finite non-negative values, got values in "
                         f"[{np.nanmin(array):g}, {np.nanmax(array):g}]")
    rgb = np.broadcast_to(array, array.shape[:2] + (3,))
    cv2 = _cv2(path)
    if not cv2.imwrite(path, np.ascontiguousarray(rgb[:, :, ::-1])):
        raise OSError(f"{path}: cannot write the image")


def to_srgb(img: Union[torch.Tensor, np.ndarray]) -> torch.Tensor:
    """Linear radiance clamped to [0, 1] and encoded with the sRGB curve (what ``imwrite``
    stores in a PNG), as a float tensor of the same shape (differentiable)."""
    x = torch.as_tensor(img).clamp(0.0, 1.0)
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * x.clamp_min(0.0031308) ** (1 / 2.4) - 0.055)


class Picture:
    """An image as an 8-bit sRGB PNG, which Jupyter and IPython show (``_repr_png_``).
    ``png``: the file's bytes; ``save(path)`` writes them."""

    def __init__(self, png: bytes, shape):
        self.png = png
        self.shape = tuple(shape)

    def _repr_png_(self) -> bytes:
        return self.png

    def save(self, path: PathLike) -> None:
        with open(path, "wb") as f:
            f.write(self.png)

    def __repr__(self):
        return f"Picture({self.shape[1]}x{self.shape[0]} PNG, {len(self.png)} bytes)"


def show(img: Union[torch.Tensor, np.ndarray]) -> Picture:
    """A (H, W) or (H, W, C) linear image (C = 1..4) as a ``Picture``: the last expression of a
    notebook cell, or ``IPython.display.display(ep.show(image))``, shows it. Channels as
    ``imwrite`` writes a PNG: sRGB-encoded, clamped, alpha kept linear."""
    array = _image_array(img)
    if array.ndim == 2:
        array = array[:, :, None]
    pixels = to_srgb(torch.from_numpy(array)).numpy()
    if array.shape[2] in (2, 4):  # alpha is not a colour
        pixels[:, :, -1] = np.clip(array[:, :, -1], 0.0, 1.0)
    pixels = np.round(pixels * 255.0).astype(np.uint8)
    order = {1: [0], 2: [0, 1], 3: [2, 1, 0], 4: [2, 1, 0, 3]}[pixels.shape[2]]  # OpenCV: BGR(A)
    if pixels.shape[2] == 2:  # PNG grey + alpha: OpenCV writes it as BGRA
        pixels = pixels[:, :, [0, 0, 0, 1]]
        order = [0, 1, 2, 3]
    ok, data = _cv2("picture").imencode(".png", np.ascontiguousarray(pixels[:, :, order]))
    if not ok:
        raise RuntimeError("image: PNG encoding failed")
    return Picture(data.tobytes(), array.shape[:2])


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


# ---- PLY -------------------------------------------------------------------------------------

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
_PLY_UV_NAMES = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
_PLY_COLOR_NAMES = (("red", "green", "blue"), ("r", "g", "b"))


def _ply_header(path: str, data: bytes):
    end = re.search(rb"(^|\n)end_header[ \t]*\r?\n", data)
    if not data.startswith(b"ply") or end is None:
        raise ValueError(f"{path}: not a PLY file (no 'ply' ... 'end_header' header)")
    fmt, elements = None, []
    for number, line in enumerate(data[:end.start()].decode("ascii", "replace").splitlines(), 1):
        words = line.split()
        where = f"{path}: header line {number}"
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
            if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise ValueError(f"{where}: unknown format '{fmt}'")
        elif words[0] == "element" and len(words) == 3:
            if not words[2].isdigit() or not words[2].isascii():
                raise ValueError(f"{where}: bad element count in {line!r}")
            if any(e[0] == words[1] for e in elements):
                raise ValueError(f"{where}: element '{words[1]}' is declared twice")
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements and len(words) >= 3:
            props = elements[-1][2]
            if words[1] == "list" and len(words) == 5:
                count_type, item_type, name = words[2:]
                if count_type not in _PLY_TYPES or item_type not in _PLY_TYPES:
                    raise ValueError(f"{where}: unknown type in {line!r}")
                if _PLY_TYPES[count_type][0] not in "iu":
                    raise ValueError(f"{where}: a list count must have an integer type, got "
                                     f"'{count_type}'")
                prop = (name, _PLY_TYPES[count_type], _PLY_TYPES[item_type])
            elif len(words) == 3 and words[1] in _PLY_TYPES:
                prop = (words[2], _PLY_TYPES[words[1]], None)
            else:
                raise ValueError(f"{where}: cannot read {line!r}")
            if any(p[0] == prop[0] for p in props):
                raise ValueError(f"{where}: property '{prop[0]}' of element '{elements[-1][0]}' "
                                 "is declared twice")
            if prop[0] in ("vertex_indices", "vertex_index") and prop[2] is not None and \
                    prop[2][0] not in "iu":
                raise ValueError(f"{where}: face indices must have an integer type, got "
                                 f"'{words[3]}'")
            props.append(prop)
        else:
            raise ValueError(f"{where}: cannot read {line!r}")
    if fmt is None:
        raise ValueError(f"{path}: no 'format' line in the header")
    return fmt, elements, end.end()


def _ply_check_count(count: int, row_size: int, left: int, unit: str) -> None:
    """Refuses an element count the rest of the file cannot hold (before allocating for it)."""
    if count * row_size > left:
        raise ValueError(f"declares {count} rows of at least {row_size} {unit} each, but only "
                        f"{left} {unit} are left (the file ends early)")


def _ply_list_count(value, row: int, left: int, unit: str, size: int) -> int:
    k = int(value)
    if k < 0 or k * size > left:
        raise ValueError(f"row {row}: a list of {k} items, but only {left} {unit} are left")
    return k


def _ply_read_ascii(tokens, pos, count, props):
    """Rows of one element from whitespace-separated tokens: {name: array or list of arrays}."""
    n = len(props)
    _ply_check_count(count, n, len(tokens) - pos, "numbers")
    if all(p[2] is None for p in props):
        block = np.array(tokens[pos:pos + count * n], dtype=np.float64).reshape(count, n)
        return {p[0]: block[:, i] for i, p in enumerate(props)}, pos + count * n
    out = {p[0]: [] for p in props}
    for row in range(count):
        for name, _, item in props:
            if pos >= len(tokens):
                raise ValueError(f"row {row}: the file ends early")
            if item is None:
                out[name].append(float(tokens[pos]))
                pos += 1
            else:
                k = _ply_list_count(tokens[pos], row, len(tokens) - pos - 1, "numbers", 1)
                out[name].append(np.array(tokens[pos + 1:pos + 1 + k], dtype=np.float64))
                pos += 1 + k
    return {k: (np.array(v) if props[i][2] is None else v)
            for i, (k, v) in enumerate(out.items())}, pos


def _ply_read_binary(data, pos, count, props, endian):
    def dtype_of(k_lists):
        fields = []
        for (name, t, item), k in zip(props, k_lists):
            if item is None:
                fields.append((name, endian + t))
            else:
                fields.append((name + "#count", endian + t))
                fields.append((name, endian + item, (k,)))
        return np.dtype(fields)

    _ply_check_count(count, dtype_of([0] * len(props)).itemsize, len(data) - pos, "bytes")
    list_props = [p for p in props if p[2] is not None]
    if not list_props:
        dt = dtype_of([None] * len(props))
        rows = np.frombuffer(data, dt, count, pos)
        return {p[0]: rows[p[0]] for p in props}, pos + count * dt.itemsize
    # Fast path: every list of this element has the length of the first row's.
    if count > 0:
        first, offset = [], pos
        for _, t, item in props:
            size = np.dtype(t).itemsize
            if item is None:
                first.append(None)
                offset += size
            else:
                k = _ply_list_count(np.frombuffer(data, endian + t, 1, offset)[0], 0,
                                    len(data) - offset - size, "bytes", np.dtype(item).itemsize)
                first.append(k)
                offset += size + k * np.dtype(item).itemsize
        dt = dtype_of(first)
        if pos + count * dt.itemsize <= len(data):
            rows = np.frombuffer(data, dt, count, pos)
            if all((rows[p[0] + "#count"] == k).all() for p, k in zip(props, first) if k is not None):
                return ({p[0]: (rows[p[0]] if p[2] is None else list(rows[p[0]])) for p in props},
                        pos + count * dt.itemsize)
    out = {p[0]: [] for p in props}
    for row in range(count):
        for name, t, item in props:
            if pos + np.dtype(t).itemsize > len(data):
                raise ValueError(f"row {row}: the file ends early")
            value = np.frombuffer(data, endian + t, 1, pos)[0]
            pos += np.dtype(t).itemsize
            if item is None:
                out[name].append(value)
            else:
                size = np.dtype(item).itemsize
                k = _ply_list_count(value, row, len(data) - pos, "bytes", size)
                out[name].append(np.frombuffer(data, endian + item, k, pos))
                pos += k * size
    return {k: (np.array(v) if props[i][2] is None else v)
            for i, (k, v) in enumerate(out.items())}, pos


def _ply_indices(path: str, values: np.ndarray, first_row: int) -> np.ndarray:
    """Face indices as int64; values that are not integers (an ASCII file) raise."""
    if values.dtype.kind == "f":
        bad = ~np.isfinite(values) | (values != np.round(values)) | (np.abs(values) >= 2**31)
        if bad.any():
            row = first_row + (int(np.flatnonzero(bad.reshape(len(values), -1).any(1))[0])
                               if values.ndim == 2 else 0)
            raise ValueError(f"{path}: element 'face' row {row}: vertex index "
                             f"{float(values[bad].flat[0])!r} is not an integer")
    return values.astype(np.int64)


def _ply_strip_triangles(strips, restart: int) -> np.ndarray:
    """Triangles (M, 3) of triangle strips (index lists; -1, or ``restart``, starts a new strip).
    Triangle j of a strip is (s[j], s[j+1], s[j+2]), its first two corners swapped for odd j so
    that all keep one winding; triangles with a repeated index (used to join strips) are
    dropped."""
    out = []
    for strip in strips:
        strip = np.asarray(strip).astype(np.int64)
        cuts = np.flatnonzero((strip < 0) | (strip == restart))
        for part in np.split(strip, cuts):
            part = part[(part >= 0) & (part != restart)]
            if len(part) < 3:
                continue
            a, b, c = part[:-2], part[1:-1], part[2:]
            odd = (np.arange(len(a)) % 2).astype(bool)
            tri = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], 1)
            out.append(tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])])
    return np.concatenate(out) if out else np.zeros((0, 3), np.int64)


def load_ply(path: PathLike) -> Mesh:
    """Loads a PLY mesh (ASCII or binary, little or big endian) as one Mesh: vertex positions
    (x, y, z), normals (nx, ny, nz) and uvs (u, v; or s, t / texture_u, texture_v) where the
    file has them, one per vertex; polygons are split into triangle fans, triangle strips
    (``element tristrips`` with a ``vertex_indices`` list, -1 between strips) into their
    triangles. uvs are kept as
    stored (v = 0 is the top row of a texture, as Mitsuba reads PLY files). Vertex colours
    (red, green, blue; or r, g, b) become the mesh's ``colors``: integer values divided by their
    type's largest value (255 for uchar), floats as stored, both taken as linear (no sRGB
    decoding). Other elements and properties are skipped."""
    path = _existing(path, "PLY file")
    with open(path, "rb") as f:
        data = f.read()
    fmt, elements, pos = _ply_header(path, data)
    per_vertex = {"x", "y", "z", "nx", "ny", "nz"}.union(*_PLY_UV_NAMES, *_PLY_COLOR_NAMES)
    for element, _, props in elements:
        for prop, _, item in props:
            if element == "vertex" and prop in per_vertex and item is not None:
                raise ValueError(f"{path}: element 'vertex': property '{prop}' is a list "
                                 "(expected one number per vertex)")
            if element == "face" and prop in ("vertex_indices", "vertex_index") and item is None:
                raise ValueError(f"{path}: element 'face': property '{prop}' is not a list")
    values = {}
    tokens = data[pos:].split() if fmt == "ascii" else None
    tpos = 0
    try:
        for name, count, props in elements:
            if fmt == "ascii":
                values[name], tpos = _ply_read_ascii(tokens, tpos, count, props)
            else:
                endian = "<" if fmt == "binary_little_endian" else ">"
                values[name], pos = _ply_read_binary(data, pos, count, props, endian)
    except (ValueError, IndexError, OverflowError) as error:
        raise ValueError(f"{path}: element '{name}': cannot read its data ({error})") from None
    vertex = values.get("vertex")
    if vertex is None or not all(k in vertex for k in "xyz"):
        raise ValueError(f"{path}: no vertex element with x, y, z")
    face = values.get("face", {})
    key = "vertex_indices" if "vertex_indices" in face else "vertex_index"
    strips = values.get("tristrips", {})
    strip_key = "vertex_indices" if "vertex_indices" in strips else "vertex_index"
    if key not in face and strip_key not in strips:
        raise ValueError(f"{path}: no face element with vertex_indices (nor tristrips)")
    with np.errstate(over="ignore", invalid="ignore"):
        vertices = np.stack([vertex[k] for k in "xyz"], 1).astype(np.float32)
    if not np.isfinite(vertices).all():
        bad = int(np.flatnonzero(~np.isfinite(vertices).all(1))[0])
        raise ValueError(f"{path}: element 'vertex' row {bad}: position {vertices[bad].tolist()} "
                         "is not finite (as float32)")
    triangles = []
    if strip_key in strips:
        item = next(p[2] for p in dict((e[0], e[2]) for e in elements)["tristrips"] if p[0] == strip_key)
        restart = np.iinfo(item).max if np.dtype(item).kind == "u" else -1
        triangles.append(_ply_strip_triangles(strips[strip_key], restart))
    polygons = face.get(key, [])
    block = None
    if polygons and len({len(p) for p in polygons}) == 1:  # all faces of one size: vectorised
        block = _ply_indices(path, np.array(polygons).reshape(len(polygons), -1), 0)
    if block is not None and block.shape[1] >= 3:
        k = block.shape[1]
        fans = [np.stack([block[:, 0], block[:, j], block[:, j + 1]], 1) for j in range(1, k - 1)]
        triangles.append(np.stack(fans, 1).reshape(-1, 3))  # each face's triangles together
    else:
        for i, p in enumerate(polygons):
            p = _ply_indices(path, np.asarray(p), i)
            if len(p) < 3:
                raise ValueError(f"{path}: face {i} has {len(p)} vertices (at least 3)")
            triangles.append(np.stack([np.full(len(p) - 2, p[0]), p[1:-1], p[2:]], 1))
    indices = np.concatenate(triangles) if triangles else np.zeros((0, 3), np.int64)
    if indices.size and (indices.min() < 0 or indices.max() >= len(vertices)):
        bad = int(indices.max() if indices.max() >= len(vertices) else indices.min())
        raise ValueError(f"{path}: vertex index {bad} out of range for {len(vertices)} vertices")
    normals = uvs = None
    if all(k in vertex for k in ("nx", "ny", "nz")):
        normals = torch.from_numpy(np.stack([vertex[k] for k in ("nx", "ny", "nz")], 1)
                                   .astype(np.float32))
    for u, v in _PLY_UV_NAMES:
        if u in vertex and v in vertex:
            uvs = torch.from_numpy(np.stack([vertex[u], vertex[v]], 1).astype(np.float32))
            break
    colors = None
    for names in _PLY_COLOR_NAMES:
        if all(k in vertex for k in names):
            # The declared type (ASCII rows are read as float64).
            types = {p[0]: np.dtype(p[1]) for e in elements if e[0] == "vertex" for p in e[2]}
            columns = []
            for k in names:
                t = types[k]
                scale = float(np.iinfo(t).max) if t.kind in "iu" else 1.0
                columns.append(np.asarray(vertex[k], dtype=np.float64) / scale)
            colors = torch.from_numpy(np.stack(columns, 1).astype(np.float32))
            break
    return Mesh(vertices=torch.from_numpy(vertices),
                indices=torch.from_numpy(indices.astype(np.int32)), uvs=uvs, normals=normals,
                colors=colors)


# ---- writing OBJ -----------------------------------------------------------------------------

def _constant(value, field: str, channels: int) -> List[float]:
    """A constant material value as numbers; textures raise (MTL stores only Kd maps here)."""
    if isinstance(value, torch.Tensor):
        t = value.detach().to(torch.float64).reshape(-1)
        if value.dim() > 1 or t.numel() not in (1, channels):
            raise ValueError(f"{field}: a texture cannot be written to an MTL file (only the "
                             "diffuse texture can); pass materials=False to skip materials")
        return (t.tolist() * channels)[:channels] if t.numel() == 1 else t.tolist()
    return [float(value)] * channels


def save_obj(meshes: Union[Mesh, Sequence[Mesh]], path: PathLike, materials: bool = True) -> None:
    """Writes one Mesh or a list of them to an OBJ file that ``load_obj`` reads back: vertices,
    uvs (v flipped back to OBJ's convention), normals, their index arrays. With ``materials``,
    a ``.mtl`` file beside it holds one material per mesh (Kd or a map_Kd EXR texture, Ks,
    Ns from the roughness, Ke for emitters), so that ``load_obj`` gives the meshes back one by
    one; textures other than the diffuse one raise ValueError. Tensors are detached, never
    modified."""
    if isinstance(meshes, Mesh):
        meshes = [meshes]
    if not isinstance(meshes, (list, tuple)) or not meshes:
        raise ValueError("meshes: expected an edgepath.Mesh or a non-empty list of them")
    path = os.fspath(path)
    directory = os.path.dirname(path)
    if directory:
        os.makedirs(directory, exist_ok=True)
    base = os.path.splitext(path)[0]
    stem = os.path.basename(base)
    lines = ["# written by edgepath"]
    mtl = []
    if materials:
        lines.append(f"mtllib {stem}.mtl")
    counts = [0, 0, 0]  # vertices, uvs, normals written so far

    def rows(t, field, width):
        if not isinstance(t, torch.Tensor) or t.dim() != 2 or t.shape[1] != width:
            raise ValueError(f"{field}: expected a tensor of shape (N, {width})")
        return t.detach().to(device="cpu", dtype=torch.float64).numpy()

    for i, mesh in enumerate(meshes):
        f = f"meshes[{i}]"
        if not isinstance(mesh, Mesh):
            raise ValueError(f"{f}: expected an edgepath.Mesh, got {type(mesh).__name__}")
        v = rows(mesh.vertices, f + ".vertices", 3)
        idx = rows(mesh.indices, f + ".indices", 3).astype(np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= len(v)):
            raise ValueError(f"{f}.indices: index out of range for {len(v)} vertices")
        lines.append(f"o mesh_{i}")
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v]
        corners = [idx + 1 + counts[0]]
        counts[0] += len(v)
        for attr, width in (("uvs", 2), ("normals", 3)):
            values = getattr(mesh, attr)
            if values is None:
                corners.append(None)
                continue
            a = rows(values, f"{f}.{attr}", width)
            index_attr = "uv_indices" if attr == "uvs" else "normal_indices"
            ai = getattr(mesh, index_attr)
            ai = idx if ai is None else rows(ai, f"{f}.{index_attr}", 3).astype(np.int64)
            if ai.size and (ai.min() < 0 or ai.max() >= len(a)):
                raise ValueError(f"{f}.{index_attr}: index out of range for {len(a)} {attr}")
            if attr == "uvs":
                lines += [f"vt {s:.9g} {1.0 - t:.9g}" for s, t in a]
                corners.append(ai + 1 + counts[1])
                counts[1] += len(a)
            else:
                lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in a]
                corners.append(ai + 1 + counts[2])
                counts[2] += len(a)
        if materials:
            lines.append(f"usemtl mesh_{i}")
            mtl += _mtl_entry(mesh, i, base, stem)
        vi, ti, ni = corners
        for r in range(len(idx)):
            parts = []
            for k in range(3):
                s = str(vi[r, k])
                if ti is not None or ni is not None:
                    s += "/" + (str(ti[r, k]) if ti is not None else "")
                if ni is not None:
                    s += "/" + str(ni[r, k])
                parts.append(s)
            lines.append("f " + " ".join(parts))
    with open(path, "w") as out:
        out.write("\n".join(lines) + "\n")
    if materials:
        with open(base + ".mtl", "w") as out:
            out.write("\n".join(mtl) + "\n")


def _mtl_entry(mesh: Mesh, i: int, base: str, stem: str) -> List[str]:
    f = f"meshes[{i}]"
    material = mesh.material if mesh.material is not None else \
        Material(diffuse=0.0 if mesh.emission is not None else 0.5)
    kind = getattr(material, "kind", "standard")
    if kind != "standard":
        raise ValueError(f"{f}.material: a {kind} material has no MTL form (save with "
                         "materials=False)")
    out = [f"newmtl mesh_{i}"]
    diffuse = material.diffuse
    if isinstance(diffuse, torch.Tensor) and diffuse.dim() == 3:
        texture = f"{base}_mesh{i}_diffuse.exr"
        imwrite(diffuse, texture)
        out.append(f"map_Kd {stem}_mesh{i}_diffuse.exr")
    else:
        out.append("Kd " + " ".join(f"{x:.9g}" for x in _constant(diffuse, f + ".material.diffuse", 3)))
    out.append("Ks " + " ".join(f"{x:.9g}" for x in _constant(material.specular, f + ".material.specular", 3)))
    r = _constant(material.roughness, f + ".material.roughness", 1)[0]
    out.append(f"Ns {2.0 / max(r, 1e-6) ** 2 - 2.0:.9g}")  # load_obj: roughness sqrt(2 / (Ns + 2))
    if mesh.emission is not None:
        out.append("Ke " + " ".join(f"{x:.9g}" for x in _constant(mesh.emission, f + ".emission", 3)))
    return out
