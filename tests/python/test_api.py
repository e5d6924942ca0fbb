"""The public Python API: rendering, determinism, validation, caller safety, files, CLI."""

import math
from pathlib import Path

import numpy as np
import pytest
import torch

import edgepath as ep
from edgepath.render import flatten_scene

# The conformance data set lives in the folder beside the repository.
SHARED = Path(__file__).resolve().parents[3] / "shared"
CONFORMANCE = SHARED / "conformance" / "mitsuba3"
needs_conformance = pytest.mark.skipif(
    not CONFORMANCE.is_dir(), reason=f"conformance data not found at {CONFORMANCE}")


def make_scene(resolution=(256, 256), **camera_args):
    """The README example: a red triangle at z = 0 facing the camera at z = -5, lit by a
    square lamp behind the camera (z = -7) that faces +z."""
    camera = dict(position=torch.tensor([0., 0., -5.]), look_at=torch.tensor([0., 0., 0.]),
                  up=torch.tensor([0., 1., 0.]), fov=45.0, resolution=resolution)
    camera.update(camera_args)
    cam = ep.Camera(**camera)
    red = ep.Material(diffuse=torch.tensor([0.8, 0.2, 0.2]))
    tri = ep.Mesh(vertices=torch.tensor([[-1.7, 1., 0.], [1., 1., 0.], [-0.5, -1., 0.]]),
                  indices=torch.tensor([[0, 1, 2]], dtype=torch.int32), material=red)
    lamp = ep.Mesh(vertices=torch.tensor([[-2., -2., -7.], [2., -2., -7.], [2., 2., -7.], [-2., 2., -7.]]),
                   indices=torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32),
                   material=ep.Material(diffuse=torch.zeros(3)),
                   emission=torch.tensor([20., 20., 20.]))
    return ep.Scene(camera=cam, meshes=[tri, lamp], envmap=None)


def pixel_of(point, resolution=(256, 256), position=(0., 0., -5.), fov=45.0):
    """(row, col) of a world point for a camera at `position` looking along +z, up +y
    (image right is world -x)."""
    h, w = resolution
    d = [p - c for p, c in zip(point, position)]
    tx = math.tan(math.radians(fov) / 2)
    px = (1 + (-d[0]) / (d[2] * tx)) / 2 * w
    py = (1 - d[1] / (d[2] * tx * h / w)) / 2 * h
    return int(py), int(px)


def to_world_look_at(origin, target, up):
    """Mitsuba's look_at matrix: columns x = cross(up, z) (image left), y, z = forward, origin."""
    origin, target, up = (torch.tensor(v, dtype=torch.float64) for v in (origin, target, up))
    z = torch.nn.functional.normalize(target - origin, dim=0)
    x = torch.nn.functional.normalize(torch.linalg.cross(up, z), dim=0)
    y = torch.linalg.cross(z, x)
    m = torch.eye(4, dtype=torch.float64)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m


# ---- rendering ------------------------------------------------------------------------------

def test_readme_example_renders():
    img = ep.render(make_scene(), spp=16, max_bounces=1, seed=0)
    assert img.shape == (256, 256, 3)
    assert img.dtype == torch.float32
    assert torch.isfinite(img).all()
    assert (img >= 0).all()
    # The triangle's centroid is lit (and red); the corner sees nothing.
    r, c = pixel_of((-0.4, 1 / 3, 0.0))
    patch = img[r - 3:r + 4, c - 3:c + 4]
    assert patch.mean() > 0.05
    assert patch[..., 0].mean() > 2 * patch[..., 1].mean()
    assert img[0, 0].abs().sum() == 0


def test_same_seed_same_image_whatever_the_threads():
    scene = make_scene(resolution=(48, 64))
    a = ep.render(scene, spp=4, seed=3, num_threads=1)
    b = ep.render(scene, spp=4, seed=3, num_threads=2)
    c = ep.render(scene, spp=4, seed=3)
    assert torch.equal(a, b)
    assert torch.equal(a, c)


def test_different_seed_different_image():
    scene = make_scene(resolution=(48, 64))
    assert not torch.equal(ep.render(scene, spp=2, seed=0), ep.render(scene, spp=2, seed=1))


def test_crop_window_gives_crop_size_and_matching_pixels():
    full = ep.render(make_scene(resolution=(64, 64)), spp=8, seed=0)
    crop = ep.render(make_scene(resolution=(64, 64), crop_window=(20, 8, 24, 16)), spp=8, seed=0)
    assert crop.shape == (16, 24, 3)
    # Same region of the film; noise differs, means agree.
    assert torch.allclose(crop.mean(), full[8:24, 20:44].mean(), rtol=0.1, atol=1e-3)


def test_to_world_matches_look_at_camera():
    m = to_world_look_at((0., 0., -5.), (0., 0., 0.), (0., 1., 0.))
    a = ep.render(make_scene(resolution=(32, 32)), spp=4, seed=0)
    b = ep.render(make_scene(resolution=(32, 32), position=None, look_at=None, up=None,
                             to_world=m), spp=4, seed=0)
    assert (a - b).abs().mean() < 1e-3


def test_orthographic_envmap_and_options_render():
    scene = make_scene(resolution=(32, 32), camera_type="orthographic", ortho_scale=2.0,
                       pixel_filter="gaussian", fov=torch.tensor(45.0))
    scene.envmap = ep.EnvironmentMap(values=torch.full((8, 16, 3), 0.5), scale=2.0,
                                     to_world=torch.eye(4))
    for sampling in ("mis", "light", "bsdf"):
        img = ep.render(scene, spp=2, max_bounces=2, seed=1, sampling=sampling)
        assert img.shape == (32, 32, 3)
        assert torch.isfinite(img).all()
        assert img.mean() > 0


# ---- lists and numpy arrays --------------------------------------------------------------

def test_lists_and_numpy_arrays_are_taken_where_tensors_are():
    """The README scene written with lists, tuples and numpy arrays (ints too, where a
    float is meant) renders the same image as with tensors, and leaves the inputs as given."""
    reference = ep.render(make_scene(resolution=(24, 24)), spp=2, seed=3)
    vertices = np.array([[-1.7, 1., 0.], [1., 1., 0.], [-0.5, -1., 0.]])
    indices = [[0, 1, 2]]
    cam = ep.Camera(position=[0, 0, -5], look_at=(0, 0, 0), up=np.array([0., 1., 0.]),
                    fov=np.float32(45.0), resolution=(24, 24))
    tri = ep.Mesh(vertices=vertices, indices=indices,
                  material=ep.Material(diffuse=[0.8, 0.2, 0.2], roughness=np.array(0.5)))
    lamp = ep.Mesh(vertices=[[-2, -2, -7], [2, -2, -7], [2, 2, -7], [-2, 2, -7]],
                   indices=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32),
                   material=ep.Material(diffuse=[0, 0, 0]), emission=[20, 20, 20])
    scene = ep.Scene(cam, [tri, lamp])
    image = ep.render(scene, spp=2, seed=3)
    assert torch.equal(image, reference)
    assert isinstance(tri.vertices, np.ndarray) and vertices.dtype == np.float64
    assert tri.material.diffuse == [0.8, 0.2, 0.2] and cam.position == [0, 0, -5]
    # A list never requires grad: the loss reaches the tensors only.
    colour = torch.tensor([0.5, 0.5, 0.5], requires_grad=True)
    tri.material.diffuse = colour
    ep.render(scene, spp=1).sum().backward()
    assert colour.grad is not None and (colour.grad > 0).all()


def test_a_list_holding_tensors_is_refused_rather_than_detached():
    scene = make_scene(resolution=(8, 8))
    x = torch.tensor(0.0, requires_grad=True)
    scene.camera.position = [x, 0.0, -5.0]
    with pytest.raises(ValueError, match=r"camera\.position: a list holding tensors.*torch\.stack"):
        ep.render(scene, spp=1)


# ---- validation -----------------------------------------------------------------------------

def render_small(scene):
    return ep.render(scene, spp=1)


@pytest.mark.parametrize("mutate, field", [
    (lambda s: setattr(s.meshes[0], "vertices", torch.zeros(3, 2)), r"meshes\[0\]\.vertices"),
    (lambda s: setattr(s.meshes[0], "vertices", torch.zeros(3, 3, dtype=torch.int32)),
     r"meshes\[0\]\.vertices"),
    (lambda s: setattr(s.meshes[0], "vertices", [[0., 0.], [0., 0., 0.]]), r"meshes\[0\]\.vertices"),
    (lambda s: setattr(s.meshes[0], "vertices", [[0., 0., "x"]] * 3), r"meshes\[0\]\.vertices"),
    (lambda s: setattr(s.meshes[0], "vertices", {"x": 0}), r"meshes\[0\]\.vertices"),
    (lambda s: setattr(s.meshes[0], "vertices", torch.zeros(3, 3, device="meta")),
     r"meshes\[0\]\.vertices: .*device"),
    (lambda s: setattr(s.meshes[0], "indices", torch.tensor([[0., 1., 2.]])), r"meshes\[0\]\.indices"),
    (lambda s: setattr(s.meshes[0], "indices", torch.tensor([[0, 1, 2, 0]])), r"meshes\[0\]\.indices"),
    (lambda s: setattr(s.meshes[0], "indices", torch.tensor([[0, 1, 2**40]])),
     r"meshes\[0\]\.indices"),
    (lambda s: s.meshes[0].vertices.__setitem__((1, 2), float("nan")), r"meshes\[0\]\.vertices"),
    (lambda s: s.meshes[1].vertices.__setitem__((0, 0), float("inf")), r"meshes\[1\]\.vertices"),
    (lambda s: setattr(s.meshes[0], "indices", torch.tensor([[0, 1, 7]], dtype=torch.int32)),
     r"meshes\[0\]\.indices: index 7 out of range"),
    (lambda s: setattr(s.meshes[0], "uvs", torch.zeros(3, 3)), r"meshes\[0\]\.uvs"),
    (lambda s: setattr(s.meshes[0], "uv_indices", torch.zeros(2, 3, dtype=torch.int32)),
     r"meshes\[0\]\.uv_indices"),
    (lambda s: setattr(s.meshes[1], "emission", torch.ones(2)), r"meshes\[1\]\.emission"),
    (lambda s: setattr(s.meshes[1], "emission", torch.tensor([1., float("nan"), 1.])),
     r"meshes\[1\]\.emission"),
    (lambda s: setattr(s.meshes[0].material, "diffuse", torch.ones(2)),
     r"meshes\[0\]\.material\.diffuse"),
    (lambda s: setattr(s.meshes[0].material, "diffuse", torch.tensor([0.5, -1.0, 0.5])),
     r"meshes\[0\]\.material\.diffuse"),  # a value the core rejects, named for the mesh
    (lambda s: setattr(s.meshes[0].material, "roughness", torch.ones(3)),
     r"meshes\[0\]\.material\.roughness"),
    (lambda s: setattr(s.meshes[0].material, "roughness", torch.tensor([1e25])),
     r"meshes\[0\]\.material\.roughness: value 1e\+25 at flat index 0 is out of range"),
    (lambda s: setattr(s.meshes[0], "material", "red"), r"meshes\[0\]\.material"),
    (lambda s: setattr(s, "meshes", []), r"meshes: the scene has no meshes"),
    (lambda s: setattr(s, "meshes", [s.meshes[0], "lamp"]), r"meshes\[1\]"),
    (lambda s: setattr(s.camera, "resolution", (0, 64)), r"camera\.resolution"),
    (lambda s: setattr(s.camera, "resolution", (64.0, 64)), r"camera\.resolution"),
    (lambda s: setattr(s.camera, "position", torch.zeros(2)), r"camera\.position"),
    (lambda s: setattr(s.camera, "camera_type", "cylindrical"), r"camera\.camera_type"),
    (lambda s: setattr(s.camera, "pixel_filter", "lanczos"), r"camera\.pixel_filter"),
    (lambda s: setattr(s.camera, "fov", torch.ones(2)), r"camera\.fov"),
    (lambda s: setattr(s.camera, "to_world", torch.eye(4)), r"camera"),
    (lambda s: setattr(s.camera, "crop_window", (0, 0, 0, 4)), r"camera\.crop_window"),
    (lambda s: setattr(s, "envmap", ep.EnvironmentMap(values=torch.ones(4, 4))), r"envmap\.values"),
    (lambda s: setattr(s, "envmap", ep.EnvironmentMap(values=torch.ones(4, 4, 3),
                                                      to_world=torch.eye(2))), r"envmap\.to_world"),
])
def test_bad_input_raises_value_error_naming_the_field(mutate, field):
    scene = make_scene(resolution=(16, 16))
    mutate(scene)
    with pytest.raises(ValueError, match=field):
        render_small(scene)


def test_unused_vertex_with_zero_normal_renders_and_used_one_is_rejected():
    # Scans have vertices no face uses; a normal computation gives them a zero normal. Only a
    # normal some triangle uses must have a direction.
    scene = make_scene(resolution=(16, 16))
    tri = scene.meshes[0]
    tri.normals = torch.tensor([[0., 0., -1.]] * 3)
    reference = ep.render(scene, spp=4, seed=3)
    tri.vertices = torch.cat([tri.vertices, torch.tensor([[5., 5., 5.]])])
    tri.normals = torch.cat([tri.normals, torch.zeros(1, 3)])
    assert torch.equal(ep.render(scene, spp=4, seed=3), reference)
    tri.normals[1] = 0.0
    with pytest.raises(ValueError, match=r"meshes\[0\]\.normals: normal 1 \(of triangle 0\) is zero"):
        render_small(scene)


def test_empty_mesh_is_rejected():
    scene = make_scene(resolution=(16, 16))
    scene.meshes[0].vertices = torch.zeros(0, 3)
    scene.meshes[0].indices = torch.zeros(0, 3, dtype=torch.int32)
    with pytest.raises(ValueError, match=r"meshes\[0\]\.(vertices|indices)"):
        render_small(scene)


@pytest.mark.parametrize("kwargs, field", [
    (dict(spp=0), "spp"), (dict(spp=1.5), "spp"), (dict(max_bounces=-1), "max_bounces"),
    (dict(seed=-1), "seed"), (dict(num_threads=0), "num_threads"), (dict(sampling="path"), "sampling"),
])
def test_bad_render_options(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ep.render(make_scene(resolution=(8, 8)), **kwargs)


def test_not_a_scene():
    with pytest.raises(ValueError, match="scene"):
        ep.render("scene.xml")


# ---- the caller's tensors -------------------------------------------------------------------

def test_caller_tensors_unchanged_and_float32_inputs_not_copied():
    scene = make_scene(resolution=(16, 16))
    tri, lamp = scene.meshes
    tri.vertices = tri.vertices.to(torch.float64).requires_grad_()
    tri.indices = tri.indices.to(torch.int64)
    tri.material.diffuse = torch.tensor([0.8, 0.2, 0.2], dtype=torch.float64)
    lamp.indices = lamp.indices.to(torch.int64)
    inputs = [tri.vertices, tri.indices, tri.material.diffuse, lamp.vertices, lamp.indices,
              lamp.emission, scene.camera.position, scene.camera.look_at, scene.camera.up]
    clones = [t.detach().clone() for t in inputs]

    img = render_small(scene)
    assert img.shape == (16, 16, 3)
    for t, c in zip(inputs, clones):
        assert t.dtype == c.dtype
        assert torch.equal(t.detach(), c)
    assert tri.vertices.requires_grad and tri.vertices.grad is None

    flat = flatten_scene(scene)
    assert flat.meshes[0]["vertices"].dtype == torch.float32
    assert flat.meshes[0]["indices"].dtype == torch.int32
    # float32 contiguous inputs reach the core as views, not copies.
    assert flat.meshes[1]["vertices"].data_ptr() == lamp.vertices.data_ptr()
    assert flat.meshes[0]["vertices"].data_ptr() != tri.vertices.data_ptr()


# ---- files ----------------------------------------------------------------------------------

def test_imwrite_imread_round_trip(tmp_path):
    img = torch.rand(5, 7, 3)
    img[0, 0] = torch.tensor([4.0, -1.0, 0.5])  # EXR keeps it, PNG clamps
    ep.imwrite(img, tmp_path / "a.exr")
    back = ep.imread(tmp_path / "a.exr")
    assert back.shape == (5, 7, 3) and back.dtype == torch.float32
    assert torch.equal(back, img)

    ep.imwrite(img, str(tmp_path / "a.png"))
    back = ep.imread(tmp_path / "a.png")
    assert back.shape == (5, 7, 3)
    assert torch.allclose(back, img.clamp(0, 1), atol=1.2 / 255)

    ep.imwrite(img.numpy().astype(np.float64)[:, :, 0], tmp_path / "grey.exr")  # numpy, (H, W)
    assert ep.imread(tmp_path / "grey.exr").shape == (5, 7, 1)


def test_image_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        ep.imread(tmp_path / "missing.png")
    with pytest.raises(ValueError):
        ep.imwrite(torch.zeros(4, 4, 5), tmp_path / "a.exr")
    with pytest.raises(ValueError, match="unsupported"):
        ep.imwrite(torch.zeros(4, 4, 3), tmp_path / "a.bmp")
    (tmp_path / "bad.exr").write_text("not an image")
    with pytest.raises(OSError, match="bad.exr"):
        ep.imread(tmp_path / "bad.exr")


def test_load_obj_with_materials_and_texture(tmp_path):
    ep.imwrite(torch.full((2, 4, 3), 0.25), tmp_path / "wood.exr")
    (tmp_path / "scene.mtl").write_text(
        "newmtl wood\nKd 0.5 0.5 0.5\nKs 0.1 0.1 0.1\nNs 48\nmap_Kd wood.exr\n"
        "newmtl light\nKd 0 0 0\nKe 10 10 10\n")
    (tmp_path / "scene.obj").write_text(
        "mtllib scene.mtl\n"
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
        "usemtl wood\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n"
        "usemtl light\nf 1 2 4\n")
    meshes = ep.load_obj(tmp_path / "scene.obj")
    assert len(meshes) == 2
    wood, light = meshes
    assert wood.vertices.shape == (4, 3) and wood.indices.shape == (2, 3)
    assert wood.indices.dtype == torch.int32
    assert wood.uvs.shape == (4, 2) and wood.normals.shape == (1, 3)
    # v flipped: the corner at (-1, -1) had vt (0, 0) and now has uv (0, 1).
    corner = (wood.vertices[wood.indices.reshape(-1)] == torch.tensor([-1., -1., 0.])).all(dim=1)
    k = int(torch.nonzero(corner)[0])
    assert wood.uvs[wood.uv_indices.reshape(-1)[k]].tolist() == [0.0, 1.0]
    assert wood.material.diffuse.shape == (2, 4, 3)
    assert torch.allclose(wood.material.diffuse, torch.tensor(0.25))
    assert wood.material.roughness == pytest.approx(math.sqrt(2 / 50))
    assert wood.emission is None
    assert light.emission.tolist() == [10.0, 10.0, 10.0]
    assert light.uvs is None and light.normals is None and light.vertices.shape == (3, 3)


@needs_conformance
def test_load_conformance_rectangle():
    (mesh,) = ep.load_obj(CONFORMANCE / "meshes" / "rectangle.obj")
    assert mesh.indices.shape == (2, 3)
    assert mesh.normals is None and mesh.material is None
    corners = mesh.vertices[mesh.indices.reshape(-1)]
    uvs = mesh.uvs[mesh.uv_indices.reshape(-1)]
    assert torch.allclose(uvs, (corners[:, :2] + 1) / 2)


@needs_conformance
def test_read_conformance_exr():
    img = ep.imread(CONFORMANCE / "refs" / "test_diffuse_albedo_image_primal_ref.exr")
    assert img.dim() == 3 and img.shape[2] == 3 and torch.isfinite(img).all()


# ---- command line ---------------------------------------------------------------------------

def test_cli_help_and_demo(tmp_path, capsys):
    from edgepath.cli import main
    with pytest.raises(SystemExit) as exit_info:
        main(["render", "--help"])
    assert exit_info.value.code == 0
    assert "--spp" in capsys.readouterr().out
    assert main(["demo", "--output-dir", str(tmp_path), "--spp", "1", "--size", "16",
                 "--iterations", "1", "--quiet"]) == 0
    assert ep.imread(tmp_path / "result.png").shape == (16, 16, 3)


def test_python_api_page_names_every_public_name():
    page = (Path(__file__).resolve().parents[2] / "docs" / "python-api.md").read_text()
    missing = [name for name in ep.__all__ if f"`{name}`" not in page and f"`ep.{name}" not in page]
    assert not missing, f"docs/python-api.md does not name {missing}"


def test_shapes_box_is_closed_and_outward_facing():
    vertices, indices = ep.shapes.box(center=(1.0, 2.0, 3.0), half=(0.5, 0.25, 1.0))
    assert vertices.shape == (8, 3) and indices.shape == (12, 3) and indices.dtype == torch.int32
    assert torch.equal(vertices.min(0).values, torch.tensor([0.5, 1.75, 2.0]))
    assert torch.equal(vertices.max(0).values, torch.tensor([1.5, 2.25, 4.0]))
    tri = vertices[indices.long()]
    normals = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = ((tri.mean(1) - torch.tensor([1.0, 2.0, 3.0])) * normals).sum(1)
    assert bool((outward > 0).all())
    # Closed: the area-weighted normals sum to zero, and every edge is shared by two triangles.
    assert float(normals.sum(0).abs().max()) < 1e-5
    edges = torch.cat([indices[:, [0, 1]], indices[:, [1, 2]], indices[:, [2, 0]]]).sort(1).values
    assert bool((torch.unique(edges, dim=0, return_counts=True)[1] == 2).all())
