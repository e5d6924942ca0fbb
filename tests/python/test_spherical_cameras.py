"""The fisheye (equidistant) and panorama (equirectangular) cameras: their images against closed
forms (an environment map whose bilinear interpolation is linear between pixel boundaries, so a
pixel's mean is its centre's value; a fisheye's image circle), derivative images of occluders
and of the camera's parameters against finite differences (failing without the primary
boundary terms), reverse mode against forward mode, and an occluder's position recovered
through each."""

import math

import pytest
import torch

import conformance as C
import edgepath as ep
from edgepath import shapes
from edgepath.render import flatten_scene, render_flat, render_options
from test_gradients import assert_autograd_equals_derivative_image


# ---- forward: closed forms -------------------------------------------------------------------

def ramp_envmap(height, width, generator):
    """(height + 1, width / 2, 3) texels: red = v (linear down the rows), green random per
    column, blue random per row. Bilinear interpolation (Mitsuba's: columns at
    u = (i + 0.5) / W_env, rows at v = j / (H_env - 1)) is linear between texels."""
    rows, cols = height + 1, width // 2
    values = torch.empty(rows, cols, 3)
    values[:, :, 0] = torch.linspace(0.0, 1.0, rows)[:, None]
    values[:, :, 1] = 0.3 * torch.rand(cols, generator=generator)[None, :] + 0.2
    values[:, :, 2] = 0.3 * torch.rand(rows, generator=generator)[:, None] + 0.2
    return values


def bilinear_env(values, u, v):
    """The environment's value at (u, v) (float64), as the lookup interpolates it."""
    rows, cols = values.shape[:2]
    values = values.double()
    s = u * cols - 0.5
    i0 = torch.floor(s)
    fs = (s - i0)[..., None]
    i0 = i0.long() % cols
    i1 = (i0 + 1) % cols
    t = (v * (rows - 1)).clamp(0, rows - 1)
    j0 = torch.floor(t).clamp(max=rows - 2)
    ft = (t - j0)[..., None]
    j0 = j0.long()
    top = values[j0, i0] * (1 - fs) + values[j0, i1] * fs
    bottom = values[j0 + 1, i0] * (1 - fs) + values[j0 + 1, i1] * fs
    return top * (1 - ft) + bottom * ft


def env_uv(d):
    """Mitsuba's lat-long coordinates of unit directions d (..., 3)."""
    u = torch.atan2(d[..., 0], -d[..., 2]) / (2 * math.pi) % 1.0
    v = torch.acos(d[..., 1].clamp(-1, 1)) / math.pi
    return u, v


def env_scene(camera_type, resolution, fov=45.0, look_at=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0), seed=0):
    height, width = resolution
    values = ramp_envmap(height, width, torch.Generator().manual_seed(seed))
    camera = ep.Camera(position=torch.zeros(3), look_at=torch.tensor(look_at), up=torch.tensor(up),
                       fov=fov, resolution=resolution, camera_type=camera_type)
    # A scene needs a mesh: a triangle seen edge-on (its plane holds the camera), which no ray
    # meets.
    edge_on = ep.Mesh(vertices=torch.tensor([[1.0, 0.0, 0.5], [2.0, 0.0, 0.5], [1.5, 0.0, 0.9]]),
                      indices=torch.tensor([[0, 1, 2]], dtype=torch.int32))
    return ep.Scene(camera=camera, meshes=[edge_on], envmap=ep.EnvironmentMap(values=values)), values


def test_panorama_matches_the_equirectangular_closed_form():
    # Looking along +z with up +y, the panorama's film point (x, y) sees u = x / W, v = y / H:
    # the environment's columns (at u = (i + 0.5) / (W / 2)) and rows (at v = j / H) fall on
    # pixel boundaries, so each pixel's mean is the value at its centre.
    height, width, spp = 8, 16, 1024
    scene, values = env_scene("panorama", (height, width))
    image = ep.render(scene, spp=spp, max_bounces=0, seed=1).double()
    cx = (torch.arange(width, dtype=torch.float64) + 0.5) / width
    cy = (torch.arange(height, dtype=torch.float64) + 0.5) / height
    expected = bilinear_env(values, cx[None, :].expand(height, width), cy[:, None].expand(height, width))
    # Within a pixel the value is linear: a mean of spp uniform film points has standard
    # deviation |slope| / sqrt(12 spp) (slope per pixel); the slopes are at most the largest
    # step between neighbouring texels.
    green, blue = values[0, :, 1], values[:, 0, 2]
    step = max(float((green.roll(-1) - green).abs().max()) / 2, float(blue.diff().abs().max()), 1.0 / height)
    sigma = step / math.sqrt(12 * spp)
    error = (image - expected).abs()
    print(f"panorama: max error {float(error.max()):.2e} (sigma {sigma:.2e})")
    assert float(error.max()) <= 6 * sigma
    # An equal-area latitude (v = (1 - sin(lat)) / 2) would be off by far more.
    lat = (0.5 - cy) * math.pi
    equal_area = (1 - torch.sin(lat)) / 2
    assert float((equal_area - cy).abs().max()) > 20 * sigma


def fisheye_expected(values, resolution, fov, forward_axes, sub=24):
    """Pixel means of the fisheye's image of the environment, and their standard deviations
    per film sample, by quadrature on a sub x sub grid per pixel (0 outside the image circle).
    forward_axes: (right, up, forward) as rows."""
    height, width = resolution
    R, U, F = (torch.tensor(a, dtype=torch.float64) for a in forward_axes)
    offsets = (torch.arange(sub, dtype=torch.float64) + 0.5) / sub
    px = (torch.arange(width, dtype=torch.float64)[:, None] + offsets[None, :]).reshape(-1)
    py = (torch.arange(height, dtype=torch.float64)[:, None] + offsets[None, :]).reshape(-1)
    X, Y = torch.meshgrid(px, py, indexing="xy")
    nx, ny = 2 * X / width - 1, (1 - 2 * Y / height) * height / width
    r = torch.sqrt(nx * nx + ny * ny)
    theta = r * math.radians(fov) / 2
    s = torch.where(r > 0, torch.sin(theta) / r.clamp(min=1e-12), torch.full_like(r, math.radians(fov) / 2))
    d = (nx * s)[..., None] * R + (ny * s)[..., None] * U + torch.cos(theta)[..., None] * F
    u, v = env_uv(d)
    f = bilinear_env(values, u, v) * (r <= 1)[..., None]
    f = f.reshape(height, sub, width, sub, 3)
    mean = f.mean(dim=(1, 3))
    std = (f.square().mean(dim=(1, 3)) - mean.square()).clamp(min=0).sqrt()
    return mean, std


@pytest.mark.parametrize("fov", [120.0, 250.0])
def test_fisheye_matches_the_equidistant_closed_form(fov):
    height, width, spp = 12, 12, 256
    # Looking up (+y), film right along +x: the environment's latitude is the angle from the axis.
    scene, values = env_scene("fisheye", (height, width), fov=fov, look_at=(0.0, 1.0, 0.0), up=(0.0, 0.0, 1.0))
    axes = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))  # right = forward x up, up, forward
    image = ep.render(scene, spp=spp, max_bounces=0, seed=2).double()
    expected, std = fisheye_expected(values, (height, width), fov, axes)
    error = (image - expected).abs()
    # Monte Carlo noise per pixel plus the quadrature's error: 0.01 where the image circle cuts
    # a pixel (a 24 x 24 grid: a few cells of the pixel's 576 misclassified), 0.001 elsewhere.
    c = (torch.arange(width, dtype=torch.float64) + 0.5 - width / 2).abs()
    near, far = (c - 0.5).clamp(min=0), c + 0.5
    cut = ((near[None, :] ** 2 + near[:, None] ** 2) <= (width / 2) ** 2) & \
          ((far[None, :] ** 2 + far[:, None] ** 2) >= (width / 2) ** 2)
    bound = 6 * std / math.sqrt(spp) + torch.where(cut, 0.01, 0.001)[..., None]
    worst = float((error / bound).max())
    print(f"fisheye {fov}: max error {float(error.max()):.2e}, worst error / bound {worst:.2f}")
    assert worst <= 1.0
    # The corners lie outside the image circle: black.
    assert float(image[0, 0].abs().max()) == 0.0 and float(image[-1, -1].abs().max()) == 0.0
    # The check is sharp: the image of a fov 5% narrower would fail it.
    wrong, _ = fisheye_expected(values, (height, width), fov * 0.95, axes)
    assert float(((image - wrong).abs() / bound).max()) > 2.0


def test_fisheye_does_not_trace_outside_the_image_circle():
    height = width = 16
    spp = 4
    scene, _ = env_scene("fisheye", (height, width), fov=180.0)
    image, stats = render_flat(flatten_scene(scene), render_options(spp=spp, max_bounces=0, seed=0))
    # Pixels wholly outside the circle (their nearest point further than W / 2 from the centre)
    # and wholly inside it (their farthest point nearer).
    c = (torch.arange(width) + 0.5 - width / 2).abs()
    near, far = (c - 0.5).clamp(min=0), c + 0.5
    outside = (near[None, :] ** 2 + near[:, None] ** 2) > (width / 2) ** 2
    inside = (far[None, :] ** 2 + far[:, None] ** 2) < (width / 2) ** 2
    assert bool(outside.any()) and bool(inside.any())
    assert float(image[outside].abs().max()) == 0.0
    assert float(image[inside].sum(dim=-1).min()) > 0.0
    # Only the film samples inside the circle are traced (one camera ray each, no bounces).
    traced = int(stats["camera_rays"])
    print(f"camera rays {traced}: between {int(inside.sum()) * spp} and {int((~outside).sum()) * spp}")
    assert int(inside.sum()) * spp <= traced <= int((~outside).sum()) * spp


def test_bad_camera_parameters_name_the_field():
    scene, _ = env_scene("fisheye", (4, 4), fov=361.0)
    with pytest.raises(ValueError, match="camera.fov"):
        ep.render(scene, spp=1)
    scene.camera.fov = 0.0
    with pytest.raises(ValueError, match="camera.fov"):
        ep.render(scene, spp=1)
    # A panorama ignores fov; a perspective camera keeps its limit of 180 degrees.
    scene.camera.camera_type = "panorama"
    scene.camera.fov = 500.0
    ep.render(scene, spp=1)
    scene.camera.camera_type = "perspective"
    scene.camera.fov = 200.0
    with pytest.raises(ValueError, match="camera.fov"):
        ep.render(scene, spp=1)
    scene.camera.camera_type = "fish-eye"
    with pytest.raises(ValueError, match="camera.camera_type"):
        ep.render(scene, spp=1)


# ---- derivative images against finite differences -----------------------------------------

def quad_mesh(centre, right, up, reflectance):
    c, r, u = (torch.tensor(x, dtype=torch.float32) for x in (centre, right, up))
    v, i = shapes.quad([(c - r - u).tolist(), (c + r - u).tolist(), (c + r + u).tolist(), (c - r + u).tolist()])
    return ep.Mesh(vertices=v, indices=i, material=ep.Material(diffuse=reflectance, specular=0.0, two_sided=True))


def surround_scene(camera_type, fov=200.0, resolution=(10, 20), pixel_filter="box"):
    """Dark quads around the camera under a constant sky: one ahead, one to the side, one above
    and a little behind the camera (across a panorama's seam, near its top row; across the rim of
    a 200 degree fisheye)."""
    meshes = [quad_mesh((0.3, 0.1, 2.0), (0.5, 0, 0), (0, 0.4, 0), 0.1),
              quad_mesh((2.0, -0.3, 0.4), (0, 0, 0.5), (0, 0.6, 0), 0.3),
              quad_mesh((0.0, 1.2, -0.25), (0.8, 0, 0), (0, 0, 0.35), 0.05)]
    camera = ep.Camera(position=torch.zeros(3), look_at=torch.tensor([0.0, 0.0, 1.0]), fov=torch.tensor(fov),
                       resolution=resolution, camera_type=camera_type, pixel_filter=pixel_filter)
    return ep.Scene(camera=camera, meshes=meshes, envmap=ep.EnvironmentMap(values=torch.ones(1, 1, 3)))


# Relative L1 distance between the derivative image and a central finite difference (both at
# 1024 spp): the finite difference's own noise is most of it (see the printed figures).
L1_TOLERANCE = 0.25


def assert_derivative_matches(scene, param, direction, eps, spp=1024, fd_spp=None, tolerance=L1_TOLERANCE):
    d_image = ep.derivative_image(scene, param, direction, spp=spp, seed=1, max_bounces=1)
    fd_image = ep.finite_difference_image(scene, param, direction, eps=eps, spp=fd_spp or spp, seed=2,
                                          max_bounces=1)
    error = C.relative_l1(d_image, fd_image)
    interior = ep.derivative_image(scene, param, direction, spp=spp // 4, seed=1, max_bounces=1,
                                   primary_edges=False)
    interior_error = C.relative_l1(interior, fd_image)
    print(f"relative L1 error {error:.3f} (<= {tolerance}); interior term alone {interior_error:.3f}")
    assert float(fd_image.abs().max()) > 0.05, "the finite difference vanishes, nothing is tested"
    assert error <= tolerance
    assert interior_error > 2 * L1_TOLERANCE


def x_direction(vertices):
    direction = torch.zeros_like(vertices)
    direction[:, 0] = 1.0
    return direction


@pytest.mark.parametrize("camera_type,mesh,axis,pixel_filter", [
    ("fisheye", 0, 0, "box"), ("fisheye", 2, 0, "box"), ("panorama", 2, 2, "gaussian"), ("panorama", 1, 0, "box")])
def test_occluder_derivative_matches_finite_differences(camera_type, mesh, axis, pixel_filter):
    # Mesh 2 lies across the fisheye's rim, and across the panorama's seam near its top: moved
    # along z, its far edge moves on both sides of the seam, and the Gaussian filter's pixels
    # reach across the seam and past the top row.
    scene = surround_scene(camera_type, pixel_filter=pixel_filter,
                           resolution=(16, 16) if camera_type == "fisheye" else (16, 32))
    vertices = scene.meshes[mesh].vertices
    direction = torch.zeros_like(vertices)
    direction[:, axis] = 1.0
    # Near the fisheye's rim the film stretches: a step of 0.04 moves mesh 2's outline across
    # pixel boundaries, and its finite difference is off by itself (relative L1 0.16 from the
    # derivative at 16 x 1024 spp; 0.04 at a step of 0.01). With these steps and sample counts,
    # the error is 0.02-0.10 over 16 pairs of seeds per case.
    eps, fd_spp = (0.01, 32768) if (camera_type, mesh) == ("fisheye", 2) else (0.04, 8192)
    assert_derivative_matches(scene, vertices, direction, eps=eps, fd_spp=fd_spp, tolerance=0.15)


@pytest.mark.parametrize("camera_type", ["fisheye", "panorama"])
def test_uniform_edge_sampling_agrees(camera_type):
    """Edges picked by world length (the baseline) have the same expectation as edges picked
    by the angle they subtend (for a fisheye, of the edges that reach into its field of view:
    here a narrow one, 40 degrees, whose rim cuts the quad ahead)."""
    if camera_type == "fisheye":
        scene = surround_scene("fisheye", fov=40.0, resolution=(16, 16))
        mesh, axis = 0, 0
    else:
        scene = surround_scene("panorama", pixel_filter="gaussian", resolution=(16, 32))
        mesh, axis = 2, 2
    vertices = scene.meshes[mesh].vertices
    direction = torch.zeros_like(vertices)
    direction[:, axis] = 1.0
    height, width = scene.camera.resolution
    importance = ep.derivative_image(scene, vertices, direction, spp=512, seed=1)
    uniform = ep.derivative_image(scene, vertices, direction, spp=512, seed=2, edge_sampling="uniform",
                                  edge_samples=height * width * 2048)
    error = C.relative_l1(uniform, importance)
    print(f"relative L1 distance {error:.3f}")
    assert error < 0.05


@pytest.mark.parametrize("camera_type,name", [("fisheye", "fov"), ("fisheye", "position"),
                                               ("panorama", "look_at")])
def test_camera_derivative_matches_finite_differences(camera_type, name):
    scene = surround_scene(camera_type, resolution=(16, 16) if camera_type == "fisheye" else (16, 32))
    if name == "fov":
        # Per 10 degrees: the image changes by a few percent per degree.
        param = scene.camera.fov
        direction, eps = torch.full_like(param, 10.0), 0.4
    else:
        param = getattr(scene.camera, name)
        direction = torch.tensor([0.3, -0.2, 0.1]) if name == "position" else torch.tensor([0.3, 0.0, 0.0])
        eps = 0.1
    assert_derivative_matches(scene, param, direction, eps)


@pytest.mark.parametrize("camera_type", ["fisheye", "panorama"])
def test_alpha_and_depth_derivatives_match_finite_differences(camera_type):
    """The output channels' boundary terms use the same edge samples: alpha and depth of an
    occluder moved sideways (alpha steps only at its outline)."""
    scene = surround_scene(camera_type, resolution=(16, 16) if camera_type == "fisheye" else (16, 32))
    vertices = scene.meshes[0].vertices
    direction = x_direction(vertices)
    names = ["alpha", "depth"]
    d = ep.derivative_channels(scene, vertices, direction, names, spp=512, seed=1)
    fd = ep.finite_difference_channels(scene, vertices, direction, names, eps=0.04, spp=512, seed=2)
    interior = ep.derivative_channels(scene, vertices, direction, names, spp=64, seed=1, primary_edges=False)
    for name in names:
        error = C.relative_l1(d[name], fd[name])
        print(f"{camera_type} {name}: relative L1 error {error:.3f}, interior alone "
              f"{C.relative_l1(interior[name], fd[name]):.3f}")
        assert float(fd[name].abs().max()) > 0.05
        assert error <= L1_TOLERANCE
        assert C.relative_l1(interior[name], fd[name]) > 2 * L1_TOLERANCE


@pytest.mark.parametrize("camera_type,name", [("fisheye", "occluder"), ("fisheye", "fov"),
                                               ("panorama", "occluder"), ("panorama", "position")])
def test_autograd_equals_derivative_image(camera_type, name):
    scene = surround_scene(camera_type, pixel_filter="tent" if camera_type == "panorama" else "box",
                           resolution=(8, 8) if camera_type == "fisheye" else (6, 12))
    if name == "occluder":
        param = scene.meshes[2].vertices
        direction = x_direction(param)
    elif name == "fov":
        param = scene.camera.fov
        direction = torch.ones_like(param)
    else:
        param = scene.camera.position
        direction = torch.tensor([0.3, -0.2, 0.1])
    assert_autograd_equals_derivative_image(scene, param, direction, f"{camera_type} {name}", spp=4,
                                            max_bounces=1, seed=3)


# ---- inverse rendering -------------------------------------------------------------------------

def test_recover_occluder_position_through_a_fisheye():
    def scene_at(offset):
        scene = surround_scene("fisheye", resolution=(16, 16))
        mesh = scene.meshes[2]  # across the rim
        mesh.vertices = mesh.vertices + torch.stack([offset, torch.zeros(()), torch.zeros(())])
        return scene

    truth, start = 0.0, 0.5
    target = ep.render(scene_at(torch.tensor(truth)), spp=128, seed=100)
    offset = torch.tensor(start, requires_grad=True)
    optimizer = torch.optim.Adam([offset], lr=0.05, betas=(0.6, 0.9))
    history = []
    for step in range(30):
        optimizer.zero_grad()
        image = ep.render(scene_at(offset), spp=32, seed=step)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        history.append(float(offset.detach()))
    estimate = sum(history[-10:]) / 10
    print(f"occluder offset {start} -> {estimate:.3f} (truth {truth})")
    assert abs(estimate - truth) < 0.1 * abs(start - truth)


def test_recover_occluder_position_through_a_panorama():
    # The occluder across the seam, moved along z: its far edge shows on both sides of the film.
    def scene_at(offset):
        scene = surround_scene("panorama", resolution=(16, 32))
        mesh = scene.meshes[2]
        mesh.vertices = mesh.vertices + torch.stack([torch.zeros(()), torch.zeros(()), offset])
        return scene

    truth, start = 0.0, 0.4
    target = ep.render(scene_at(torch.tensor(truth)), spp=128, seed=100)
    offset = torch.tensor(start, requires_grad=True)
    optimizer = torch.optim.Adam([offset], lr=0.04, betas=(0.6, 0.9))
    history = []
    for step in range(30):
        optimizer.zero_grad()
        image = ep.render(scene_at(offset), spp=16, seed=step)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        history.append(float(offset.detach()))
    estimate = sum(history[-10:]) / 10
    print(f"occluder offset {start} -> {estimate:.3f} (truth {truth}): {[round(h, 3) for h in history]}")
    assert abs(estimate - truth) < 0.1 * abs(start - truth)
