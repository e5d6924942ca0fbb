"""ep.load_ply (ASCII, binary little and big endian; positions, normals, uvs; polygons split
into triangles) and ep.save_obj (read back by ep.load_obj)."""

import struct

import pytest
import torch

import edgepath as ep
import edgepath.shapes  # ep.shapes

# A unit square (quad) and a triangle, with normals and uvs.
VERTICES = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0), (0.5, 0.5, 1.0)]
NORMALS = [(0.0, 0.0, 1.0)] * 4 + [(0.0, 1.0, 0.0)]
UVS = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.5, 0.25)]
FACES = [(0, 1, 2, 3), (0, 1, 4)]


def _header(fmt, uv_names=("u", "v"), extra_element=False):
    lines = ["ply", f"format {fmt} 1.0", "comment written by a test", f"element vertex {len(VERTICES)}"]
    lines += [f"property float {n}" for n in ("x", "y", "z", "nx", "ny", "nz")]
    lines += [f"property float {n}" for n in uv_names]
    if extra_element:
        lines += ["element material 1", "property uchar red", "property list uchar int tags"]
    lines += [f"element face {len(FACES)}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(lines) + "\n").encode()


def _write_ply(path, fmt, uv_names=("u", "v"), extra_element=False):
    data = _header(fmt, uv_names, extra_element)
    if fmt == "ascii":
        body = [" ".join(str(x) for x in v + n + t) for v, n, t in zip(VERTICES, NORMALS, UVS)]
        if extra_element:
            body.append("7 2 1 2")
        body += [" ".join(str(x) for x in (len(f),) + f) for f in FACES]
        data += ("\n".join(body) + "\n").encode()
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        for v, n, t in zip(VERTICES, NORMALS, UVS):
            data += struct.pack(e + "8f", *v, *n, *t)
        if extra_element:
            data += struct.pack(e + "BBii", 7, 2, 1, 2)
        for f in FACES:
            data += struct.pack(e + "B" + "i" * len(f), len(f), *f)
    path.write_bytes(data)
    return path


def _corners(mesh, attr="vertices", index_attr="indices"):
    values = getattr(mesh, attr)
    idx = getattr(mesh, index_attr)
    idx = mesh.indices if idx is None else idx
    return values[idx.long()]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("extra", [False, True])
def test_load_ply_formats(tmp_path, fmt, extra):
    mesh = ep.load_ply(_write_ply(tmp_path / "m.ply", fmt, extra_element=extra))
    assert torch.equal(mesh.vertices, torch.tensor(VERTICES))
    assert torch.equal(mesh.normals, torch.tensor(NORMALS))
    assert torch.equal(mesh.uvs, torch.tensor(UVS))
    # the quad as a fan (0 1 2), (0 2 3); then the triangle
    assert mesh.indices.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 4]]
    assert mesh.indices.dtype == torch.int32 and mesh.vertices.dtype == torch.float32


def test_load_ply_uv_names_and_minimal(tmp_path):
    mesh = ep.load_ply(_write_ply(tmp_path / "st.ply", "binary_little_endian", ("s", "t")))
    assert torch.equal(mesh.uvs, torch.tensor(UVS))
    minimal = tmp_path / "min.ply"
    minimal.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\n"
                       "property double y\nproperty double z\nelement face 1\n"
                       "property list uchar uint vertex_index\nend_header\n"
                       "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    m = ep.load_ply(minimal)
    assert m.uvs is None and m.normals is None and m.indices.tolist() == [[0, 1, 2]]
    image = ep.render(ep.Scene(camera=ep.Camera(position=torch.tensor([0.3, 0.3, 2.0]),
                                                look_at=torch.tensor([0.3, 0.3, 0.0]),
                                                resolution=(8, 8)),
                               meshes=[m], envmap=ep.EnvironmentMap(torch.ones(1, 1, 3))), spp=1)
    assert float(image.sum()) > 0


def test_load_ply_quads_and_empty_faces(tmp_path):
    quads = tmp_path / "quads.ply"
    quads.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\n"
                      b"property float y\nproperty float z\nelement face 2\n"
                      b"property list uchar int vertex_indices\nend_header\n"
                      + struct.pack("<18f", 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 2, 0, 0, 2, 1, 0)
                      + struct.pack("<B4i", 4, 0, 1, 2, 3) + struct.pack("<B4i", 4, 1, 4, 5, 2))
    m = ep.load_ply(quads)
    assert m.indices.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]]
    lines = tmp_path / "lines.ply"
    lines.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                     "end_header\n0 0 0\n1 0 0\n2 0 1\n")
    with pytest.raises(ValueError, match="face 0 has 2 vertices"):
        ep.load_ply(lines)


def test_load_ply_tristrips(tmp_path):
    # A 2x3 grid of vertices (0 1 2 over 3 4 5) as one strip of 4 triangles, then, after a -1,
    # a strip whose repeated index (a join between strips) makes a degenerate triangle.
    strip = [3, 0, 4, 1, 5, 2, -1, 2, 2, 5, 6]
    positions = [0, 1, 0, 1, 1, 0, 2, 1, 0, 0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 1, 0]
    # odd triangles of a strip swap their first two corners: one winding throughout
    expected = [[3, 0, 4], [4, 0, 1], [4, 1, 5], [5, 1, 2], [5, 2, 6]]
    header = ("ply\nformat {} 1.0\nelement vertex 7\nproperty float x\nproperty float y\n"
              "property float z\nelement tristrips 1\nproperty list int {} vertex_indices\nend_header\n")
    ascii_file = tmp_path / "strip_ascii.ply"
    ascii_file.write_text(header.format("ascii", "int") + " ".join(map(str, positions)) + "\n"
                          + " ".join(map(str, [len(strip)] + strip)) + "\n")
    binary_file = tmp_path / "strip_binary.ply"  # unsigned indices: -1 is stored as 2^32 - 1
    binary_file.write_bytes(header.format("binary_big_endian", "uint").encode()
                            + struct.pack(">21f", *positions)
                            + struct.pack(f">i{len(strip)}I", len(strip), *[i % 2**32 for i in strip]))
    for path in (ascii_file, binary_file):
        mesh = ep.load_ply(path)
        assert mesh.indices.tolist() == expected
        corners = mesh.vertices[mesh.indices.long()]
        normals = torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        assert (normals[:, 2] < 0).all()


# (file contents, the error message expected)
PLY_ERRORS = [
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
     "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", r"bad\.ply: vertex index 5 out of range for 3 vertices"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1 2\n", "bad.ply"),
    ("solid cube\n", "not a PLY file"),
    ("ply\nformat ascii 1.0\nelement vertex many\nend_header\n", "header line 3: bad element count"),
    ("ply\nformat ascii 1.0\nelement vertex 0\nproperty fancy x\nend_header\n", "header line 4"),
]


def test_load_ply_errors(tmp_path):
    bad = tmp_path / "bad.ply"
    for text, message in PLY_ERRORS:
        bad.write_text(text)
        with pytest.raises(ValueError, match=message):
            ep.load_ply(bad)
    with pytest.raises(FileNotFoundError):
        ep.load_ply(tmp_path / "missing.ply")


def _textured_mesh():
    v, f, uv, n = ep.shapes.sphere(rings=4, segments=6)
    texture = torch.rand(4, 5, 3, generator=torch.Generator().manual_seed(1))
    material = ep.Material(diffuse=texture, specular=torch.tensor([0.04, 0.05, 0.06]),
                           roughness=0.3)
    return ep.Mesh(vertices=v, indices=f, uvs=uv, normals=n, material=material)


def test_save_obj_round_trip(tmp_path):
    sphere = _textured_mesh()
    quad_v, quad_f = ep.shapes.quad([[0, 0, 2], [1, 0, 2], [1, 1, 2], [0, 1, 2]])
    lamp = ep.Mesh(vertices=quad_v, indices=quad_f, emission=torch.tensor([5.0, 4.0, 3.0]))
    before = [t.clone() for t in (sphere.vertices, sphere.uvs, sphere.normals)]
    ep.save_obj([sphere, lamp], tmp_path / "out" / "scene.obj")
    for t, b in zip((sphere.vertices, sphere.uvs, sphere.normals), before):
        assert torch.equal(t, b)  # inputs untouched
    loaded = ep.load_obj(tmp_path / "out" / "scene.obj")
    assert len(loaded) == 2
    s, lamp_back = loaded
    for attr, index_attr in (("vertices", "indices"), ("uvs", "uv_indices"),
                             ("normals", "normal_indices")):
        assert torch.allclose(_corners(s, attr, index_attr), _corners(sphere, attr, index_attr),
                              atol=1e-6), attr
    assert torch.equal(s.material.diffuse, sphere.material.diffuse)   # EXR: exact
    assert torch.allclose(s.material.specular, sphere.material.specular)
    assert s.material.roughness == pytest.approx(0.3, abs=1e-6)
    assert s.emission is None
    assert torch.equal(_corners(lamp_back), _corners(lamp))
    assert torch.equal(lamp_back.emission, lamp.emission)
    assert lamp_back.uvs is None and lamp_back.normals is None


def test_save_obj_single_mesh_without_materials_and_errors(tmp_path):
    m = _textured_mesh()
    ep.save_obj(m, tmp_path / "a.obj", materials=False)
    assert not (tmp_path / "a.mtl").exists()
    (back,) = ep.load_obj(tmp_path / "a.obj")
    assert torch.allclose(_corners(back), _corners(m), atol=1e-6)
    m.emission = torch.rand(2, 2, 3)
    with pytest.raises(ValueError, match=r"meshes\[0\]\.emission: a texture"):
        ep.save_obj(m, tmp_path / "b.obj")
    with pytest.raises(ValueError, match="meshes"):
        ep.save_obj([], tmp_path / "c.obj")
    with pytest.raises(ValueError, match=r"meshes\[0\]\.indices"):
        ep.save_obj(ep.Mesh(vertices=torch.zeros(3, 3), indices=torch.tensor([[0, 1, 3]])),
                    tmp_path / "d.obj")
