"""Hostile and broken files: every loader ends in an error that names the file (and the line
or element where there is one), never a silent wrong mesh or image, a raw Python error with
no file name, or a huge allocation."""

import contextlib
import resource
import struct
import sys
import zlib
from pathlib import Path

import pytest
import torch

import edgepath as ep

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fuzz"))
import corpus  # noqa: E402  (the fuzzer's seed files)


@contextlib.contextmanager
def memory_cap(extra_bytes=512 << 20):
    """Caps this process's address space at what it maps now plus ``extra_bytes``, so that a
    decoder that believed a file's declared size fails here instead of exhausting memory."""
    with open("/proc/self/status") as f:
        mapped = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (mapped + extra_bytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def write(path, data):
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


# ---- OBJ ------------------------------------------------------------------------------------

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize("body,line,words", [
    (TRIANGLE + "f 1 2\n", 4, "at least 3 vertices"),
    (TRIANGLE + "f 1 2 3\nf 3\n", 5, "at least 3 vertices"),
    ("v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", 2, "'x'"),
    ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", 2, "at least 3 numbers"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n", 3, "'nan'"),
    ("v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n", 2, "'1e39'"),
    (TRIANGLE + "vt 0.5 abc\nf 1/1 2/1 3/1\n", 4, "'abc'"),
    (TRIANGLE + "f 1 2 three\n", 4, "'three'"),
    (TRIANGLE + "f 1 2 0\n", 4, "'0'"),
    (TRIANGLE + "f 1/1/ 2 3\n", 4, "'1/1/'"),
])
def test_obj_bad_lines_name_the_line(tmp_path, body, line, words):
    path = write(tmp_path / "bad.obj", body)
    with pytest.raises(OSError) as info:
        ep.load_obj(path)
    message = str(info.value)
    assert f"bad.obj:{line}:" in message and words in message


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "binary"])
def test_obj_binary_or_utf16_file_is_an_error(tmp_path, encoding):
    text = TRIANGLE + "f 1 2 3\n"
    data = bytes(range(256)) * 4 if encoding == "binary" else text.encode(encoding)
    path = write(tmp_path / "mesh.obj", data)
    with pytest.raises(OSError, match=r"mesh\.obj:1: .*(binary or UTF-16)"):
        ep.load_obj(path)


def test_obj_real_variants_still_load(tmp_path):
    """What the checks must not refuse: a byte order mark, CRLF line ends, tabs, comments,
    negative indices, w and vertex colours, v//vn corners, polygons."""
    body = ("\ufeff# comment\r\nv 0 0 0 1\r\nv 1 0 0 0.5 0.5 0.5\r\nv\t1 1 0\r\nv 0 1 0\r\n"
            "vn 0 0 1\r\nvt 0\r\nf -4//1 -3//1 -2//1 -1//1\r\n")
    meshes = ep.load_obj(write(tmp_path / "ok.obj", body.encode("utf-8")))
    assert len(meshes) == 1 and meshes[0].indices.shape == (2, 3)


# ---- PLY ------------------------------------------------------------------------------------

def ply_header(fmt="ascii", nv=3, nf=1, count_type="uchar", index_type="int", extra=""):
    return (f"ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
            f"property float z\n{extra}element face {nf}\n"
            f"property list {count_type} {index_type} vertex_indices\nend_header\n")


VERTS_ASCII = "0 0 0\n1 0 0\n0 1 0\n"
VERTS_BINARY = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)


@pytest.mark.parametrize("data,words", [
    # list counts larger than the data
    (ply_header() + VERTS_ASCII + "5 0 1 2\n", "element 'face'"),
    (ply_header("binary_little_endian", count_type="int").encode() + VERTS_BINARY +
     struct.pack("<4i", 2**31 - 1, 0, 1, 2), "element 'face'"),
    (ply_header("binary_little_endian", count_type="int").encode() + VERTS_BINARY +
     struct.pack("<4i", -3, 0, 1, 2), "element 'face'"),
    # element counts larger than the data (an OverflowError or a hang before)
    (ply_header("binary_little_endian", nf=10**20).encode() + VERTS_BINARY, "element 'face'"),
    (ply_header(nv=10**12) + VERTS_ASCII, "element 'vertex'"),
    # float indices
    (ply_header(index_type="float") + VERTS_ASCII + "3 0 1 2\n", "header line 8"),
    (ply_header(count_type="float") + VERTS_ASCII + "3 0 1 2\n", "header line 8"),
    (ply_header() + VERTS_ASCII + "3 0 1.5 2\n", "element 'face' row 0"),
    # duplicated properties and elements
    (ply_header(extra="property float y\n") + VERTS_ASCII + "3 0 1 2\n", "header line 7"),
    (ply_header(extra="element vertex 1\nproperty float x\n") + VERTS_ASCII + "3 0 1 2\n",
     "header line 7"),
    # malformed headers (IndexError, TypeError before)
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty\nend_header\n0\n", "header line 4"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty list\nend_header\n0\n", "header line 4"),
    ("ply\nformat ascii 1.0\nelement vertex x\nend_header\n", "header line 3"),
    # lists where numbers belong, and numbers where lists belong (a TypeError before)
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\n"
     "property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
     "2 0 1 0 0\n", "property 'x' is a list"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     "property float z\nelement face 1\nproperty int vertex_indices\nend_header\n"
     + VERTS_ASCII + "0\n", "property 'vertex_indices' is not a list"),
    # non-finite positions
    (ply_header() + "nan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "element 'vertex' row 0"),
    (ply_header() + "0 0 0\n1e39 0 0\n0 1 0\n3 0 1 2\n", "element 'vertex' row 1"),
])
def test_ply_bad_files_name_the_file_and_element(tmp_path, data, words):
    path = write(tmp_path / "bad.ply", data)
    with pytest.raises(ValueError) as info:
        ep.load_ply(path)
    assert "bad.ply" in str(info.value) and words in str(info.value)


# ---- images ---------------------------------------------------------------------------------

def png_declaring(width, height):
    """A 68-byte PNG whose (valid) header declares width x height RGB pixels."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + corpus.png_chunk(b"IHDR", ihdr) +
            corpus.png_chunk(b"IDAT", zlib.compress(b"\0" * 16)) + corpus.png_chunk(b"IEND", b""))


def jpeg_declaring(height, width):
    data = corpus.jpeg()
    i = data.find(b"\xff\xc0")  # baseline frame header: length, precision, height, width
    return data[:i + 5] + struct.pack(">HH", height, width) + data[i + 9:]


@pytest.mark.parametrize("name,data", [
    ("huge.png", png_declaring(60000, 60000)),
    ("wide.png", png_declaring(1000000, 1000)),
    ("huge.jpg", jpeg_declaring(60000, 60000)),
    ("big.png", png_declaring(16384, 16384)),  # allowed size, but not in 68 bytes
], ids=["png-60000", "png-wide", "jpeg-60000", "png-16384"])
def test_images_declaring_huge_sizes_fail_before_allocating(tmp_path, name, data):
    path = write(tmp_path / name, data)
    with memory_cap(), pytest.raises(OSError) as info:
        ep.imread(path)
    assert name in str(info.value) and "declares" in str(info.value)


def test_jpeg_of_huge_declared_size_within_the_cap_fails_without_its_memory(tmp_path):
    """16384 x 16384 is allowed, but the data ends after the first rows: the error comes before
    the 3 GiB the declared size would take."""
    path = write(tmp_path / "tall.jpg", jpeg_declaring(16384, 16384))
    with memory_cap(), pytest.raises(OSError, match="tall.jpg"):
        ep.imread(path)


@pytest.mark.parametrize("progressive", [False, True])
@pytest.mark.parametrize("kept", [0.7, 0.9])
def test_truncated_jpeg_is_an_error_not_grey(tmp_path, progressive, kept):
    data = corpus.jpeg(progressive, 96, 64)  # mostly scan data: the cut falls inside it
    whole = write(tmp_path / "whole.jpg", data)
    assert ep.imread(whole).shape == (64, 96, 3)
    cut = write(tmp_path / "cut.jpg", data[:int(len(data) * kept)])
    with pytest.raises(OSError, match="cut.jpg: Premature end of JPEG file"):
        ep.imread(cut)


def test_exr_channel_names_that_are_not_utf8(tmp_path):
    path = tmp_path / "names.exr"
    ep.imwrite(torch.ones(2, 3), path)  # one channel, "Y"
    data = path.read_bytes()
    i = data.index(b"chlist")
    j = data.index(b"Y\x00", i)
    write(path, data[:j] + b"\xe9\x00" + data[j + 2:])
    with pytest.raises(OSError) as info:
        ep.imread(path)
    assert "names.exr" in str(info.value) and "\\xe9" in str(info.value)


# ---- Mitsuba XML ----------------------------------------------------------------------------

SCENE_HEAD = """<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="45"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
    </sensor>
"""


@pytest.mark.parametrize("body,words", [
    ("<shape type=\"rectangle\">" + "<transform name=\"to_world\">" * 5000 +
     "</transform>" * 5000 + "</shape>", r"scene.xml:5: <transform>: elements nested deeper"),
    ('<bsdf type="twosided" id="a"><ref id="a"/></bsdf>\n<shape type="rectangle"><ref id="a"/></shape>',
     r"scene.xml:5: <ref id=\"a\">: refers to an element that contains it"),
    ('<bsdf type="twosided" id="a"><ref id="b"/></bsdf><bsdf type="twosided" id="b"><ref id="a"/>'
     '</bsdf>\n<shape type="rectangle"><ref id="a"/></shape>', r"scene.xml:5: <ref id=\"[ab]\">"),
    ('<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="inf"/></transform>'
     '</shape>', r"scene.xml:5: <rotate>: expected finite numbers \(as float32\), got 'inf'"),
    ('<shape type="rectangle"><transform name="to_world"><rotate x="nan" angle="30"/></transform>'
     '</shape>', r"scene.xml:5: <rotate>: expected finite numbers"),
    ('<shape type="sphere"><float name="radius" value="1e400"/></shape>', r"scene.xml:5: <float"),
    ('<shape type="rectangle"><bsdf type="roughconductor"><float name="alpha" value="-1e308"/>'
     '</bsdf></shape>', r"scene.xml:5: <float name=\"alpha\">: expected finite numbers \(as float32\)"),
])
def test_mitsuba_hostile_structure_names_file_and_line(tmp_path, body, words):
    path = write(tmp_path / "scene.xml", SCENE_HEAD + body + "\n</scene>\n")
    with pytest.raises(ep.MitsubaError, match=words):
        ep.load_mitsuba(path)


def test_mitsuba_unknown_encoding(tmp_path):
    path = write(tmp_path / "scene.xml", '<?xml version="1.0" encoding="klingon"?>\n' + SCENE_HEAD +
                 '<shape type="rectangle"/>\n</scene>\n')
    with pytest.raises(ep.MitsubaError, match=r"scene.xml:1: unknown encoding: klingon"):
        ep.load_mitsuba(path)


def test_mitsuba_nesting_real_scenes_use_still_loads(tmp_path):
    path = write(tmp_path / "scene.xml", SCENE_HEAD +
                 '<shape type="rectangle"><bsdf type="twosided"><bsdf type="diffuse">'
                 '<rgb name="reflectance" value="0.5"/></bsdf></bsdf></shape>\n</scene>\n')
    assert len(ep.load_mitsuba(path).scene.meshes) == 1
