"""Vertex colours (``Mesh(colors=...)``) and the channels barycentrics, vertex_color, roughness,
specular and material_id.

Closed forms: on a triangle in the plane z = 0 the barycentrics, and the interpolated colour,
are affine in the hit point (x, y, 0), so their means over a pixel's camera samples (a pixel
inside the triangle) are the affine functions of the mean position (the position channel, the
same samples); an orthographic camera puts that mean near the pixel centre. Under a uniform white environment, a diffuse surface with nothing
above it shows its albedo (docs/conventions.md), here diffuse times colour.
"""

import struct

import numpy as np
import pytest
import torch

import edgepath as ep

import conformance as C

# Mitsuba's gradient metric and thresholds (as tests/python/test_gradients.py).
ERROR_MEAN, ERROR_MAX = 0.02, 0.3


def ortho_camera(resolution=(8, 8)):
    """Sees x and y in [-1, 1] (a square film), looking down -z."""
    return ep.Camera(position=torch.tensor([0.0, 0.0, 2.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                     up=torch.tensor([0.0, 1.0, 0.0]), camera_type="orthographic", ortho_scale=1.0,
                     resolution=resolution)


def white_sky():
    return ep.EnvironmentMap(values=torch.ones(4, 8, 3))


def pixel_centres(resolution):
    """World (x, y) of the pixel centres of ortho_camera, float64, each (H, W)."""
    h, w = resolution
    x = (2 * (torch.arange(w, dtype=torch.float64) + 0.5) / w - 1).expand(h, w)
    y = (1 - 2 * (torch.arange(h, dtype=torch.float64) + 0.5) / h)[:, None].expand(h, w)
    return x, y


# One triangle covering the whole view: b1 = (x + 1.2) / 5.2, b2 = (y + 1.2) / 5.2.
BIG_TRIANGLE = torch.tensor([[-1.2, -1.2, 0.0], [4.0, -1.2, 0.0], [-1.2, 4.0, 0.0]])
BIG_COLORS = torch.tensor([[0.9, 0.1, 0.3], [0.2, 0.8, 0.4], [0.5, 0.6, 1.0]])


def test_colours_interpolate_and_multiply_the_diffuse_reflectance():
    res = (8, 8)
    diffuse = torch.tensor([0.5, 0.8, 0.6])
    mesh = ep.Mesh(BIG_TRIANGLE, torch.tensor([[0, 1, 2]]), colors=BIG_COLORS,
                   material=ep.Material(diffuse=diffuse, roughness=0.3, specular=0.0))
    scene = ep.Scene(ortho_camera(res), [mesh], envmap=white_sky())
    out = ep.render_channels(scene, ["radiance", "albedo", "vertex_color", "barycentrics",
                                     "roughness", "specular", "material_id", "position"],
                             spp=256, seed=1)
    x, y = pixel_centres(res)
    p = out["position"].double()
    # The mean of uniform samples over a pixel (a quarter unit wide): within 6 standard errors.
    assert torch.allclose(p[..., 0], x, atol=6 * 0.25 / (12 * 256) ** 0.5)
    assert torch.allclose(p[..., 1], y, atol=6 * 0.25 / (12 * 256) ** 0.5)
    b1, b2 = (p[..., 0] + 1.2) / 5.2, (p[..., 1] + 1.2) / 5.2
    b = torch.stack([b1, b2], -1)
    c = BIG_COLORS.double()
    colour = (1 - b1 - b2)[..., None] * c[0] + b1[..., None] * c[1] + b2[..., None] * c[2]
    assert torch.allclose(out["barycentrics"].double(), b, atol=2e-6)
    assert torch.allclose(out["vertex_color"].double(), colour, atol=2e-6)
    assert torch.allclose(out["albedo"].double(), colour * diffuse.double(), atol=2e-6)
    assert bool((out["roughness"] == 0.3).all()) and bool((out["specular"] == 0).all())
    assert bool((out["material_id"] == 0).all())
    # The radiance is the albedo, up to the light samples' noise (a relative standard deviation
    # of about 0.017 per pixel at 256 samples, measured).
    ratio = out["radiance"] / out["albedo"]
    print(f"radiance / albedo: mean {float(ratio.mean()):.4f}, max |ratio - 1| {float((ratio - 1).abs().max()):.4f}")
    assert abs(float(ratio.mean()) - 1) < 0.01 and float((ratio - 1).abs().max()) < 0.1
    # Colours are used, never modified.
    assert torch.equal(mesh.colors, torch.tensor([[0.9, 0.1, 0.3], [0.2, 0.8, 0.4], [0.5, 0.6, 1.0]]))


def test_material_channels_by_kind_and_material_ids_by_object():
    """Material ids number the distinct Material objects in the order the meshes first use
    them; roughness is 0 on a mirror and glass, specular 0 on glass; a mesh without colours has
    vertex colour 1."""
    res = (6, 6)
    shared = ep.Material(diffuse=0.4, specular=torch.tensor([0.1, 0.2, 0.3]), roughness=0.25)
    mirror = ep.Material(kind="conductor", specular=torch.tensor([0.9, 0.8, 0.7]))
    glass = ep.Material(kind="dielectric", ior=1.5)

    def strip(x0, x1, material):  # a vertical band of the view, x in [x0, x1]
        v = torch.tensor([[x0, -1.5, 0.0], [x1, -1.5, 0.0], [x1, 1.5, 0.0], [x0, 1.5, 0.0]])
        return ep.Mesh(v, torch.tensor([[0, 1, 2], [0, 2, 3]]), material=material)

    # Each strip exactly one pixel column wide: with borders a hundredth of a unit inside
    # (at +-0.66, +-0.34), some 4% of a column's samples fell on its neighbours' strips, and a
    # seed now and then gave the mirror's column a roughness of 0.0625.
    third = 1.0 / 3.0
    meshes = [strip(-1.0, -2 * third, shared), strip(-2 * third, -third, mirror), strip(-third, 0.0, shared),
              strip(0.0, third, glass), strip(third, 2 * third, None)]  # x > 2/3: nothing
    out = ep.render_channels(ep.Scene(ortho_camera(res), meshes),
                             ["material_id", "mesh_id", "roughness", "specular", "vertex_color"], spp=4)
    # Pixel columns 0..5 have centres at x = -5/6, -1/2, -1/6, 1/6, 1/2, 5/6.
    assert out["mesh_id"][0, :, 0].tolist() == [0, 1, 2, 3, 4, -1]
    assert out["material_id"][0, :, 0].tolist() == [0, 1, 0, 2, 3, -1]
    assert out["roughness"][0, :, 0].tolist() == pytest.approx([0.25, 0, 0.25, 0, 0.5, 0])
    expected_specular = [[0.1, 0.2, 0.3], [0.9, 0.8, 0.7], [0.1, 0.2, 0.3], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
    assert torch.allclose(out["specular"][0], torch.tensor(expected_specular))
    assert out["vertex_color"][0].tolist() == [[1.0] * 3] * 5 + [[0.0] * 3]


def seam_scene(resolution=(12, 12)):
    """A square bigger than the view, two triangles whose shared diagonal has different colours
    on each side (duplicated vertices at the same positions): a colour seam. Returns the scene
    and a direction moving the diagonal (both copies of its vertices) within the plane."""
    v = torch.tensor([[-1.5, -1.5, 0.0], [1.5, -1.5, 0.0], [1.5, 1.5, 0.0],
                      [-1.5, -1.5, 0.0], [1.5, 1.5, 0.0], [-1.5, 1.5, 0.0]])
    colors = torch.tensor([[0.9, 0.2, 0.1], [0.8, 0.3, 0.2], [0.7, 0.2, 0.3],
                           [0.1, 0.3, 0.9], [0.2, 0.5, 0.8], [0.3, 0.6, 0.7]])
    mesh = ep.Mesh(v, torch.tensor([[0, 1, 2], [3, 4, 5]]), colors=colors,
                   material=ep.Material(diffuse=0.8))
    direction = torch.zeros_like(v)
    direction[[0, 3]] = torch.tensor([0.4, -0.2, 0.0])
    direction[[2, 4]] = torch.tensor([0.3, -0.5, 0.0])
    return ep.Scene(ortho_camera(resolution), [mesh], envmap=white_sky()), direction


def test_colour_seam_derivative_matches_finite_differences():
    """Moving the seam changes the albedo inside the triangles (the colours' interpolation) and
    across the seam (the boundary term of a crease between coplanar faces); without primary
    edges only the interior part remains and the check fails."""
    scene, direction = seam_scene()
    param = scene.meshes[0].vertices
    fd = ep.finite_difference_channels(scene, param, direction, channels=["albedo"], eps=1e-2,
                                       spp=16384, seed=2)["albedo"]
    scale = float(fd.abs().max())
    assert scale > 0
    for edges in (True, False):
        d = ep.derivative_channels(scene, param, direction, channels=["albedo"], spp=16, seed=1,
                                   edge_samples=200000, primary_edges=edges)["albedo"]
        mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
        report = f"primary edges {edges}: mean err {mean_err:.4f}, max err {max_err:.4f}"
        print(report)
        if edges:
            assert mean_err <= ERROR_MEAN and max_err <= ERROR_MAX, report
        else:
            assert mean_err > ERROR_MEAN and max_err > ERROR_MAX, report


def test_radiance_derivative_in_the_colours_matches_finite_differences():
    scene, _ = seam_scene((10, 10))
    colors = scene.meshes[0].colors
    direction = torch.tensor([[0.5, -0.3, 0.2], [0.1, 0.4, -0.6], [-0.2, 0.3, 0.5],
                              [0.6, 0.1, -0.1], [-0.4, 0.5, 0.3], [0.2, -0.5, 0.4]])
    fd = ep.finite_difference_image(scene, colors, direction, eps=1e-2, spp=64, seed=3)
    d = ep.derivative_image(scene, colors, direction, spp=64, seed=3)
    scale = float(fd.abs().max())
    mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
    print(f"colours: mean err {mean_err:.5f}, max err {max_err:.5f}")
    assert scale > 0.1 and mean_err <= ERROR_MEAN and max_err <= ERROR_MAX


def test_radiance_derivative_at_a_colour_seam_matches_finite_differences():
    """The rendered image (lit by the sky) in the seam's vertices: the colour's interpolation
    inside the triangles (through the BSDF's diffuse reflectance) and the seam's boundary
    term."""
    scene, direction = seam_scene((10, 10))
    param = scene.meshes[0].vertices
    fd = ep.finite_difference_image(scene, param, direction, eps=1e-2, spp=8192, seed=2)
    d = ep.derivative_image(scene, param, direction, spp=64, seed=1, edge_samples=100000)
    scale = float(fd.abs().max())
    mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
    print(f"radiance in the vertices: mean err {mean_err:.4f}, max err {max_err:.4f}")
    assert scale > 0.5 and mean_err <= ERROR_MEAN and max_err <= ERROR_MAX


@pytest.mark.parametrize("name", ["barycentrics", "vertex_color", "roughness", "specular"])
def test_new_channels_derivatives_match_finite_differences(name):
    """The barycentrics and the vertex colour in the vertices of a triangle inside the view
    (interior term and its outline's boundary term); roughness and specular in their textures
    (interior only)."""
    v = torch.tensor([[-0.7, -0.6, 0.0], [0.8, -0.5, 0.1], [-0.1, 0.75, -0.1]])
    rough = torch.tensor([[[0.2], [0.6]], [[0.4], [0.9]]])
    spec = torch.tensor([[[0.3, 0.1, 0.2], [0.05, 0.4, 0.15]], [[0.25, 0.35, 0.1], [0.2, 0.3, 0.45]]])
    mesh = ep.Mesh(v, torch.tensor([[0, 1, 2]]), uvs=torch.tensor([[0.1, 0.2], [0.8, 0.3], [0.4, 0.9]]),
                   colors=BIG_COLORS, material=ep.Material(roughness=rough, specular=spec))
    scene = ep.Scene(ortho_camera((10, 10)), [mesh])
    gen = torch.Generator().manual_seed(5)
    param = {"barycentrics": v, "vertex_color": v, "roughness": rough, "specular": spec}[name]
    direction = torch.rand(param.shape, generator=gen) - 0.5
    geometric = name in ("barycentrics", "vertex_color")
    if geometric:
        direction[:, 2] = 0.0
    # The outline's finite difference needs many samples; the textures' values are linear in
    # their texels, so there the same samples give the same mean.
    fd_spp = 65536 if geometric else 1024
    fd = ep.finite_difference_channels(scene, param, direction, channels=[name], eps=1e-2,
                                       spp=fd_spp, seed=2)[name]
    spp, seed = (16, 1) if geometric else (fd_spp, 2)
    d = ep.derivative_channels(scene, param, direction, channels=[name], spp=spp, seed=seed,
                               edge_samples=200000)[name]
    scale = float(fd.abs().max())
    mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
    print(f"{name}: mean err {mean_err:.4f}, max err {max_err:.4f}")
    assert scale > 0 and mean_err <= ERROR_MEAN and max_err <= ERROR_MAX


def grid_mesh(n):
    """An n x n grid of vertices over [-1.2, 1.2]^2 in z = 0, two triangles per cell."""
    t = torch.linspace(-1.2, 1.2, n)
    y, x = torch.meshgrid(t, t, indexing="ij")
    v = torch.stack([x.reshape(-1), y.reshape(-1), torch.zeros(n * n)], 1)
    faces = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            faces += [[a, b, e], [a, e, d]]
    return v, torch.tensor(faces, dtype=torch.int32)


def test_recover_vertex_colours_from_an_image():
    """Gradient descent on the squared image difference recovers the colours of a 3 x 3 grid
    from one image under a white sky."""
    v, f = grid_mesh(3)
    gen = torch.Generator().manual_seed(0)
    target_colors = 0.15 + 0.8 * torch.rand(9, 3, generator=gen)
    camera = ortho_camera((16, 16))
    target_scene = ep.Scene(camera, [ep.Mesh(v, f, colors=target_colors)], envmap=white_sky())
    target = ep.render(target_scene, spp=32, seed=1)
    colors = torch.full((9, 3), 0.5, requires_grad=True)
    scene = ep.Scene(camera, [ep.Mesh(v, f, colors=colors)], envmap=white_sky())
    optimiser = torch.optim.Adam([colors], lr=0.05)
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimiser, gamma=0.95)
    start = float((colors.detach() - target_colors).abs().mean())
    for step in range(60):
        loss = (ep.render(scene, spp=4, seed=step) - target).square().sum()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        with torch.no_grad():
            colors.clamp_(min=0.0)
    error = float((colors.detach() - target_colors).abs().mean())
    print(f"mean colour error {start:.4f} -> {error:.4f}")
    assert error < 0.1 * start, (start, error)


def test_ply_vertex_colours(tmp_path):
    ascii_ply = tmp_path / "a.ply"
    ascii_ply.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                         "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                         "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                         "0 0 0 255 0 51\n1 0 0 0 255 0\n0 1 0 102 204 153\n3 0 1 2\n")
    mesh = ep.load_ply(ascii_ply)
    expected = torch.tensor([[255, 0, 51], [0, 255, 0], [102, 204, 153]], dtype=torch.float64) / 255
    assert mesh.colors.dtype == torch.float32
    assert torch.allclose(mesh.colors.double(), expected, atol=1e-7)
    binary_ply = tmp_path / "b.ply"
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
              "property float y\nproperty float z\nproperty float r\nproperty float g\nproperty float b\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n").encode()
    rows = [(0, 0, 0, 0.25, 0.5, 2.0), (1, 0, 0, 0.0, 1.0, 0.125), (0, 1, 0, 0.75, 0.0, 0.5)]
    body = b"".join(struct.pack("<6f", *r) for r in rows) + struct.pack("<B3i", 3, 0, 1, 2)
    binary_ply.write_bytes(header + body)
    mesh = ep.load_ply(binary_ply)
    assert mesh.colors.tolist() == [list(r[3:]) for r in rows]
    # No colour properties: no colours.
    plain = tmp_path / "c.ply"
    plain.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                     "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    assert ep.load_ply(plain).colors is None


def test_colour_errors_name_the_field():
    v, f = BIG_TRIANGLE, torch.tensor([[0, 1, 2]])
    camera = ortho_camera((4, 4))

    def render(colors):
        ep.render(ep.Scene(camera, [ep.Mesh(v, f), ep.Mesh(v, f, colors=colors)]), spp=1)

    with pytest.raises(ValueError, match=r"meshes\[1\]\.colors: expected shape \(3, 3\), got \(2, 3\)"):
        render(BIG_COLORS[:2])
    with pytest.raises(ValueError, match=r"meshes\[1\]\.colors: expected a floating-point tensor"):
        render(torch.ones(3, 3, dtype=torch.int64))
    bad = BIG_COLORS.clone()
    bad[1, 2] = float("nan")
    with pytest.raises(ValueError, match=r"meshes\[1\]\.colors: value nan at flat index 5 is not finite"):
        render(bad)
    with pytest.raises(ValueError, match=r"meshes\[1\]\.colors: value -0\.\d+ at flat index 0 is negative"):
        render(BIG_COLORS - torch.tensor([1.4, 0.0, 0.0]))
    assert not bool(torch.isnan(BIG_COLORS).any())
