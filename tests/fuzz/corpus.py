"""Valid seed files for the fuzzer, one small family per loader, and the mutations applied to
them. Everything here is deterministic: a case is a function of (seed, case number)."""

from __future__ import annotations

import io
import os
import random
import re
import struct
import zlib
from typing import Callable, Dict, List, Tuple

# The loaders the fuzzer exercises, in the order cases cycle through them; each maps to the
# extension its files get.
KINDS = {"obj": ".obj", "ply_ascii": ".ply", "ply_binary": ".ply", "xml": ".xml",
         "png": ".png", "jpeg": ".jpg", "exr": ".exr", "api": ".json", "placed": ".json"}

# ---- seed files ------------------------------------------------------------------------------

_OBJ = """# a unit quad and a tetrahedron, with uvs and normals
mtllib seed.mtl
v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
usemtl grey
f 1/1/1 2/2/1 3/3/1 4/4/1
o tetra
v 0 0 0.5
v 0.5 0 0.5
v 0 0.5 0.5
v 0 0 1
usemtl lamp
f 5/1/1 6/2/1 7/3/1
f 5/1/1 6/2/1 8/4/1
f 6/2/1 7/3/1 8/4/1
f -1/-1/-1 -2/-2/-1 -4/-4/-1
"""

_MTL = """newmtl grey
Kd 0.5 0.5 0.5
Ks 0.04 0.04 0.04
Ns 100
newmtl lamp
Kd 0 0 0
Ke 4 4 4
"""

_XML = """<?xml version="1.0" encoding="utf-8"?>
<scene version="3.0.0">
    <default name="spp" value="4"/>
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
            <rfilter type="gaussian"/></film>
    </sensor>
    <bsdf type="diffuse" id="paint">
        <texture type="bitmap" name="reflectance"><string name="filename" value="seed.png"/></texture>
    </bsdf>
    <shape type="obj" id="mesh">
        <string name="filename" value="seed.obj"/>
        <ref id="paint"/>
        <transform name="to_world"><rotate y="1" angle="30"/><scale value="0.5"/></transform>
    </shape>
    <shape type="ply" id="bunny">
        <string name="filename" value="seed.ply"/>
        <bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf>
        <transform name="to_world"><translate x="1" y="0.2" z="-0.5"/></transform>
    </shape>
    <shape type="sphere">
        <point name="center" x="-1" y="0.5" z="0"/><float name="radius" value="0.3"/>
        <bsdf type="twosided"><bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.2, 0.4, 0.8"/></bsdf></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="5, 5, 5"/></emitter>
    </shape>
    <emitter type="envmap">
        <string name="filename" value="seed.exr"/><float name="scale" value="0.5"/>
    </emitter>
</scene>
"""


def _ply_mesh():
    vertices = [(-1, -1, 0, 0, 0, 1, 0, 0), (1, -1, 0, 0, 0, 1, 1, 0), (1, 1, 0, 0, 0, 1, 1, 1),
                (-1, 1, 0, 0, 0, 1, 0, 1), (0, 0, 1, 0, 0, 1, 0.5, 0.5)]
    faces = [(0, 1, 2, 3), (0, 1, 4), (1, 2, 4), (2, 3, 4)]
    return vertices, faces


def _ply_header(fmt: str, nv: int, nf: int) -> str:
    props = "".join(f"property float {p}\n" for p in ("x", "y", "z", "nx", "ny", "nz", "u", "v"))
    return (f"ply\nformat {fmt} 1.0\ncomment fuzz seed\nelement vertex {nv}\n{props}"
            f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n")


def ply_ascii() -> bytes:
    vertices, faces = _ply_mesh()
    lines = [" ".join(f"{x:g}" for x in v) for v in vertices]
    lines += [" ".join(str(x) for x in (len(f),) + f) for f in faces]
    return (_ply_header("ascii", len(vertices), len(faces)) + "\n".join(lines) + "\n").encode()


def ply_binary(big_endian: bool = False) -> bytes:
    vertices, faces = _ply_mesh()
    e = ">" if big_endian else "<"
    out = _ply_header("binary_big_endian" if big_endian else "binary_little_endian",
                      len(vertices), len(faces)).encode()
    for v in vertices:
        out += struct.pack(e + "8f", *v)
    for f in faces:
        out += struct.pack(e + "B" + "i" * len(f), len(f), *f)
    return out


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png(width: int = 6, height: int = 4, colour_type: int = 2) -> bytes:
    """An 8-bit PNG (colour type 2 RGB, 6 RGBA, 0 grey) with a gradient."""
    channels = {0: 1, 2: 3, 6: 4}[colour_type]
    rows = b"".join(b"\0" + bytes((x * 40 + y * 60 + c * 20) % 256 for x in range(width)
                                  for c in range(channels)) for y in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) +
            png_chunk(b"IDAT", zlib.compress(rows)) + png_chunk(b"IEND", b""))


def jpeg(progressive: bool = False, width: int = 16, height: int = 12) -> bytes:
    from PIL import Image
    image = Image.new("RGB", (width, height))
    image.putdata([((x * 16) % 256, (y * 20) % 256, (x * y * 7) % 256)
                   for y in range(height) for x in range(width)])
    out = io.BytesIO()
    image.save(out, "JPEG", quality=80, progressive=progressive)
    return out.getvalue()


def exr(path: str) -> None:
    import torch

    import edgepath as ep
    values = torch.linspace(0.0, 2.0, 4 * 8 * 3).reshape(4, 8, 3)
    ep.imwrite(values, path)


def write_seeds(directory: str) -> Dict[str, List[str]]:
    """Writes the seed files into ``directory``; returns {kind: [file names]}. The XML seed
    refers to seed.obj, seed.ply, seed.png and seed.exr beside it."""
    files = {
        "seed.obj": _OBJ.encode(), "seed.mtl": _MTL.encode(), "seed.xml": _XML.encode(),
        "seed.ply": ply_ascii(), "seed_le.ply": ply_binary(False), "seed_be.ply": ply_binary(True),
        "seed.png": png(), "seed_rgba.png": png(5, 3, 6), "seed_grey.png": png(4, 4, 0),
        "seed.jpg": jpeg(False), "seed_prog.jpg": jpeg(True),
    }
    files["seed_api.json"] = b"[]"  # the API's scene (fuzz.py: _api_scene) as it is
    files["seed_placed.json"] = b"{}"  # and where it is (fuzz.py: _placed_case)
    for name, data in files.items():
        with open(os.path.join(directory, name), "wb") as f:
            f.write(data)
    exr(os.path.join(directory, "seed.exr"))
    return {"obj": ["seed.obj"], "ply_ascii": ["seed.ply"],
            "ply_binary": ["seed_le.ply", "seed_be.ply"], "xml": ["seed.xml"],
            "png": ["seed.png", "seed_rgba.png", "seed_grey.png"],
            "jpeg": ["seed.jpg", "seed_prog.jpg"], "exr": ["seed.exr"], "api": ["seed_api.json"],
            "placed": ["seed_placed.json"]}


# ---- mutations -------------------------------------------------------------------------------

_HUGE = [b"1e19", b"-1e19", b"1e39", b"-1e308", b"1e308", b"nan", b"inf", b"-inf", b"NaN",
         b"4294967296", b"2147483648", b"-2147483649", b"99999999999999999999", b"-1", b"0",
         b"1e-45", b"0x10", b"1.5", b"", b"-0", b"+", b"."]
_NUMBER = re.compile(rb"[-+]?\d+(\.\d*)?([eE][-+]?\d+)?")


def _lines(data: bytes) -> List[bytes]:
    return data.split(b"\n")


def flip_bytes(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if b:
            i = rng.randrange(len(b))
            b[i] = rng.choice([b[i] ^ (1 << rng.randrange(8)), rng.randrange(256), 0, 0xFF])
    return bytes(b)


def truncate(rng: random.Random, data: bytes) -> bytes:
    return data[:rng.randrange(len(data))] if data else data


def duplicate_line(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    return b"\n".join(lines[:i + 1] + [lines[i]] * rng.choice([1, 1, 2, 50]) + lines[i + 1:])


def swap_lines(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


def delete_line(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    del lines[rng.randrange(len(lines))]
    return b"\n".join(lines)


def replace_number(rng: random.Random, data: bytes) -> bytes:
    """A number in the text replaced by a huge, non-finite or malformed one."""
    matches = list(_NUMBER.finditer(data))
    if not matches:
        return flip_bytes(rng, data)
    m = rng.choice(matches)
    return data[:m.start()] + rng.choice(_HUGE) + data[m.end():]


def overwrite_word(rng: random.Random, data: bytes) -> bytes:
    """A 1-, 2- or 4-byte field of a binary file set to an extreme value."""
    size = rng.choice([1, 2, 4])
    if len(data) < size:
        return data
    i = rng.randrange(len(data) - size + 1)
    value = rng.choice([0, 1, 2**(8 * size) - 1, 2**(8 * size - 1), 2**(8 * size - 1) - 1])
    return data[:i] + value.to_bytes(size, rng.choice(["big", "little"])) + data[i + size:]


def insert_bytes(rng: random.Random, data: bytes) -> bytes:
    i = rng.randrange(len(data) + 1)
    junk = rng.choice([bytes(rng.randrange(256) for _ in range(rng.randint(1, 16))),
                       "\u00e9\u4e2d".encode("utf-16"), b"\0" * 8, data[i:i + 64] * 4])
    return data[:i] + junk + data[i:]


def nest_xml(rng: random.Random, data: bytes) -> bytes:
    """An element wrapped in thousands of levels of nesting."""
    i = data.find(b"<shape")
    if i < 0:
        return data
    depth = rng.choice([50, 2000, 20000])
    tag = rng.choice([b"bsdf", b"shape", b"transform", b"x"])
    return data[:i] + (b"<" + tag + b">") * depth + (b"</" + tag + b">") * depth + data[i:]


def png_size(rng: random.Random, data: bytes) -> bytes:
    """The IHDR's width and height set to large values, with a valid CRC (so that the decoder
    gets past the chunk check to the allocation)."""
    if data[12:16] != b"IHDR":
        return overwrite_word(rng, data)
    w, h = rng.choice([(60000, 60000), (2**31 - 1, 1), (1, 2**31 - 1), (16384, 16384), (0, 5),
                       (65536, 4097)])
    ihdr = struct.pack(">II", w, h) + data[24:29]
    return data[:8] + png_chunk(b"IHDR", ihdr) + data[33:]


def jpeg_size(rng: random.Random, data: bytes) -> bytes:
    """The frame header's (SOF) height and width set to large values."""
    for marker in (b"\xff\xc0", b"\xff\xc2", b"\xff\xc1"):
        i = data.find(marker)
        if i >= 0:
            h, w = rng.choice([(60000, 60000), (65535, 65535), (16384, 16384), (0, 16)])
            return data[:i + 5] + struct.pack(">HH", h, w) + data[i + 9:]
    return overwrite_word(rng, data)


TEXT_MUTATIONS: List[Callable] = [flip_bytes, truncate, duplicate_line, swap_lines, delete_line,
                                  replace_number, replace_number, insert_bytes]
BINARY_MUTATIONS: List[Callable] = [flip_bytes, flip_bytes, truncate, overwrite_word,
                                    overwrite_word, insert_bytes, duplicate_line, swap_lines]
EXTRA = {"xml": [nest_xml], "png": [png_size], "jpeg": [jpeg_size],
         "ply_binary": [replace_number], "exr": [truncate]}


# The Python API's inputs: which object of the scene (fuzz.py: _api_scene), which of its fields,
# and what is done to the value there (fuzz.py: API_MUTATIONS).
API_FIELDS = {"floor": ["vertices", "indices", "uvs"], "box": ["vertices", "indices", "normals", "colors"],
              "lamp": ["vertices", "indices", "emission"],
              "camera": ["position", "look_at", "up", "fov", "aperture_radius", "focus_distance",
                         "ortho_scale", "filter_stddev", "filter_radius", "to_world", "crop_window"],
              "envmap": ["values", "scale"],
              "floor_material": ["diffuse", "specular", "roughness", "normal_map", "ior"],
              "box_material": ["diffuse", "roughness", "ior"], "point_light": ["position", "intensity"],
              "spot": ["direction", "cutoff_angle", "beam_width"]}
API_MUTATIONS = ["nan", "inf", "-inf", "huge", "tiny", "negate", "zero", "empty", "float64", "float16",
                 "int64", "int32", "bool", "unsqueeze", "flatten", "transpose", "strided", "index_big",
                 "index_negative", "index_2**40", "meta", "first_value", "expand", "coplanar", "repeat_row",
                 "offset_tiny", "permute", "large", "one_large", "subnormal"]
# Other forms of the API scene, valid and not (fuzz.py: _api_variant): a case may start from one
# or two of them ({"target": "variant", "field": name, "value": value}) before its changes.
API_VARIANTS = {
    "camera_type": ["orthographic", "thinlens", "fisheye", "panorama", "pinhole"],
    "pixel_filter": ["gaussian", "tent", "mitchell"],
    "crop_window": [[1, 1, 3, 2], [0, 0, 8, 6], [7, 5, 1, 1], [0, 0, 0, 0], [-1, 0, 2, 2], [0, 0, 9, 6],
                    [2, 2, -1, 1], [1.5, 0, 2, 2]],
    "resolution": [[1, 1], [1, 9], [9, 1], [0, 4], [-1, 3], [2.5, 3]],
    "to_world": ["look_at", "scaled", "mirrored", "singular", "sheared"],
    "floor_kind": ["plastic", "conductor", "dielectric", "metal"],
    "box_kind": ["standard", "plastic", "conductor"],
    "two_sided": [True, "yes"],
    "nonlinear": [True],
    "max_bounces": [0, 1, 5],
    # the entry point (fuzz.py: _api_call): two views, channels, a derivative image, options
    "call": ["views", "channels", "derivative", "options"],
}


def mutate_api(data: bytes, rng: random.Random) -> Tuple[bytes, List[str]]:
    """One to three changes of the API scene's values, appended to the list ``data`` holds;
    where the list is still empty, first (one time in two) one or two of the scene's variants."""
    import json
    changes = json.loads(data)
    names = []
    if not changes and rng.random() < 0.5:
        for field in rng.sample(sorted(API_VARIANTS), rng.choice([1, 1, 2])):
            value = rng.choice(API_VARIANTS[field])
            changes.append({"target": "variant", "field": field, "value": value})
            names.append(f"variant.{field}={value}")
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        target = rng.choice(sorted(API_FIELDS))
        change = {"target": target, "field": rng.choice(API_FIELDS[target]),
                  "mutation": rng.choice(API_MUTATIONS), "index": rng.randrange(64)}
        changes.append(change)
        names.append(f"{change['target']}.{change['field']}:{change['mutation']}")
    return json.dumps(changes).encode(), names


# The valid forms of the API scene that the placed kind moves (a subset of API_VARIANTS; one
# camera change at most: an orthographic camera's to_world columns would be lengths).
PLACED_VARIANTS = {
    "camera": [("camera_type", "orthographic"), ("camera_type", "thinlens"), ("camera_type", "fisheye"),
               ("camera_type", "panorama"), ("to_world", "look_at"), ("to_world", "scaled")],
    "pixel_filter": [("pixel_filter", "gaussian"), ("pixel_filter", "tent")],
    "floor_kind": [("floor_kind", "plastic"), ("floor_kind", "conductor"), ("floor_kind", "dielectric"),
                   ("two_sided", True), ("nonlinear", True)],
    "box_kind": [("box_kind", "standard"), ("box_kind", "plastic"), ("box_kind", "conductor")],
    "max_bounces": [("max_bounces", 1), ("max_bounces", 5)],
    # the entry point (fuzz.py: _placed_render): two views, output channels, a derivative image
    "call": [("call", "views"), ("call", "channels"), ("call", "derivative")],
}


def place_api(rng: random.Random) -> Tuple[bytes, List[str]]:
    """A placed case (fuzz.py: _placed_case): up to three of the API scene's valid forms, a
    rotation or none, a scale from 3e-10 to 3e10 (the scene spans 2 units: from its least
    extent, 1e-10, to coordinates of 1e11, within their bound 1e12) and a shift of up to a
    thousand times the scale (and 5e11) along each axis, or none."""
    import json
    forms = [rng.choice(PLACED_VARIANTS[group]) for group in rng.sample(sorted(PLACED_VARIANTS), rng.randrange(4))]
    scale = 10.0 ** rng.uniform(-9.5, 10.5)
    shift = [0.0, 0.0, 0.0] if rng.random() < 0.5 else \
        [rng.choice([-1, 1]) * min(scale * 10.0 ** rng.uniform(-1, 3), 5e11) for _ in range(3)]
    # A rotation (a unit quaternion, uniform over rotations) one time in two.
    rotation = [1.0, 0.0, 0.0, 0.0]
    if rng.random() < 0.5:
        q = [rng.gauss(0.0, 1.0) for _ in range(4)]
        rotation = [x / sum(y * y for y in q) ** 0.5 for x in q]
    case = {"variants": forms, "scale": scale, "shift": shift, "rotation": rotation}
    names = [f"{field}={value}" for field, value in forms] + [f"scale={scale:.3g}"]
    if any(shift):
        names.append("shift=(" + ", ".join(f"{x:.3g}" for x in shift) + ")")
    if rotation[0] != 1.0:
        names.append("rotation=(" + ", ".join(f"{x:.3f}" for x in rotation) + ")")
    return json.dumps(case).encode(), names


def mutate(kind: str, data: bytes, rng: random.Random) -> Tuple[bytes, List[str]]:
    """One to three mutations of ``data``; returns the bytes and the mutations' names."""
    if kind == "api":
        return mutate_api(data, rng)
    if kind == "placed":
        return place_api(rng)
    text = kind in ("obj", "ply_ascii", "xml")
    choices = (TEXT_MUTATIONS if text else BINARY_MUTATIONS) + EXTRA.get(kind, [])
    names = []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        mutation = rng.choice(choices)
        data = mutation(rng, data)
        names.append(mutation.__name__)
    return data, names
