"""Output channels (ep.render_channels, ep.derivative_channels, ep.finite_difference_channels).

Closed forms: a finely tessellated sphere seen by a perspective camera. The tessellation lies
between two concentric spheres, radius r_in (the nearest face plane) and r_out (the farthest
vertex), so along any ray its depth lies between those of the two spheres; the position, the
normals and the projected area follow with bounds computed from the mesh itself. A pixel's
value is the mean over its camera samples (box filter), so it is compared with the closed
form averaged over the pixel, within the tessellation band plus six standard errors of that
mean (the spread of the closed form inside the pixel over the square root of the samples).
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes

import conformance as C

CENTRE = (0.1, -0.05, 0.0)
RADIUS = 0.5
EYE = (0.0, 0.0, 3.0)
FOV = 30.0


def sphere_scene(resolution=(16, 16), rings=48, segments=96, diffuse=(0.2, 0.4, 0.6)):
    v, i, uv, n = shapes.sphere(center=CENTRE, radius=RADIUS, rings=rings, segments=segments)
    camera = ep.Camera(position=torch.tensor(EYE), look_at=torch.tensor([0.0, 0.0, 0.0]),
                       up=torch.tensor([0.0, 1.0, 0.0]), fov=FOV, resolution=resolution)
    mesh = ep.Mesh(vertices=v, indices=i, uvs=uv, normals=n,
                   material=ep.Material(diffuse=torch.tensor(diffuse)))
    return ep.Scene(camera=camera, meshes=[mesh])


def tessellation_radii(mesh):
    """(r_in, r_out): the smallest distance from the centre to a face's plane, the largest to a
    vertex (float64 from the float32 mesh), and the largest chord between a face's unit normal
    and the unit directions of its vertices."""
    v = mesh.vertices.double() - torch.tensor(CENTRE, dtype=torch.float64)
    tri = v[mesh.indices.long()]
    n = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    keep = n.norm(dim=1) > 0
    tri, n = tri[keep], torch.nn.functional.normalize(n[keep], dim=1)
    r_in = float((tri[:, 0] * n).sum(1).min())
    r_out = float(v.norm(dim=1).max())
    dirs = torch.nn.functional.normalize(tri, dim=2)
    chord = float((dirs - n[:, None, :]).norm(dim=2).max())
    return r_in, r_out, chord


def camera_rays(px, py, resolution):
    """Unit directions of the camera rays through film points (px, py), float64."""
    h, w = resolution
    tx = math.tan(math.radians(FOV) / 2)
    sx = (2 * px / w - 1) * tx
    sy = (1 - 2 * py / h) * tx * h / w
    d = torch.stack([sx, sy, -torch.ones_like(sx)], -1)  # forward (0, 0, -1), right x, up y
    return torch.nn.functional.normalize(d, dim=-1)


def sphere_hit(d, radius):
    """Distance along unit rays d from the eye to the sphere (NaN where they miss)."""
    oc = torch.tensor(EYE, dtype=torch.float64) - torch.tensor(CENTRE, dtype=torch.float64)
    b = (d * oc).sum(-1)
    disc = b * b - (oc @ oc - radius * radius)
    return -b - torch.sqrt(disc)  # NaN where disc < 0


def pixel_grid(resolution, k, borders):
    """Film points of a k x k grid in every pixel: (H, W, k*k) each. With ``borders`` the grid
    runs from edge to edge of the pixel; without, it takes the centres of k x k cells (the
    midpoint rule for the pixel's mean)."""
    h, w = resolution
    s = torch.linspace(0, 1, k, dtype=torch.float64) if borders else (torch.arange(k, dtype=torch.float64) + 0.5) / k
    sy, sx = torch.meshgrid(s, s, indexing="ij")
    py = torch.arange(h, dtype=torch.float64)[:, None, None] + sy.reshape(1, 1, -1)
    px = torch.arange(w, dtype=torch.float64)[None, :, None] + sx.reshape(1, 1, -1)
    return px.expand(h, w, k * k), py.expand(h, w, k * k)


def test_radiance_channel_is_render_and_ids_mark_the_hits():
    scene = sphere_scene(resolution=(12, 14), rings=12, segments=24)
    lamp_v, lamp_i = shapes.quad([[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]])
    scene.meshes.append(ep.Mesh(vertices=lamp_v, indices=lamp_i, emission=torch.tensor([4.0, 4.0, 4.0])))
    out = ep.render_channels(scene, spp=3, seed=5)
    assert list(out) == list(ep.CHANNELS)
    assert torch.equal(out["radiance"], ep.render(scene, spp=3, seed=5))
    for name, width in ep.CHANNELS.items():
        assert tuple(out[name].shape) == (12, 14, width), name
    assert out["mesh_id"].dtype == torch.int32 and out["triangle_id"].dtype == torch.int32
    # The ids are those of the ray through the pixel centre: mesh 0 where it meets the inner
    # sphere, -1 where it misses the outer one, and the triangle it crosses contains the hit.
    r_in, r_out, _ = tessellation_radii(scene.meshes[0])
    ys, xs = torch.meshgrid(torch.arange(12, dtype=torch.float64) + 0.5,
                            torch.arange(14, dtype=torch.float64) + 0.5, indexing="ij")
    d = camera_rays(xs, ys, (12, 14))
    mesh_id, triangle_id = out["mesh_id"][..., 0], out["triangle_id"][..., 0]
    assert bool((mesh_id[torch.isfinite(sphere_hit(d, r_in))] == 0).all())
    assert bool((mesh_id[~torch.isfinite(sphere_hit(d, r_out))] == -1).all())
    assert bool(((triangle_id >= 0) == (mesh_id >= 0)).all()) and bool((mesh_id >= 0).any())
    v = scene.meshes[0].vertices.double()
    tri = v[scene.meshes[0].indices.long()[triangle_id[mesh_id >= 0].long()]]
    eye = torch.tensor(EYE, dtype=torch.float64)
    ray = d[mesh_id >= 0]
    # Barycentrics of the ray's crossing of each triangle's plane (Cramer's rule).
    e1, e2, s_ = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], eye - tri[:, 0]
    det = (-ray * torch.linalg.cross(e1, e2)).sum(1)
    b1 = (-ray * torch.linalg.cross(s_, e2)).sum(1) / det
    b2 = (-ray * torch.linalg.cross(e1, s_)).sum(1) / det
    assert bool(((b1 >= -1e-4) & (b2 >= -1e-4) & (b1 + b2 <= 1 + 1e-4)).all())
    # Where every sample missed, the other channels are zero; the albedo is the material's.
    outside, inside = out["alpha"] == 0, out["alpha"] == 1
    assert bool(outside.any()) and bool(inside.any())
    for name in ("depth", "position", "uv", "albedo", "geometry_normal", "shading_normal"):
        assert bool((out[name][outside.expand_as(out[name])] == 0).all()), name
    albedo = out["albedo"][inside.expand_as(out["albedo"])].reshape(-1, 3)
    assert torch.allclose(albedo, torch.tensor([0.2, 0.4, 0.6]).expand_as(albedo))
    # A subset in another order: the same values.
    some = ep.render_channels(scene, channels=["triangle_id", "depth"], spp=3, seed=5)
    assert list(some) == ["triangle_id", "depth"]
    assert torch.equal(some["depth"], out["depth"]) and torch.equal(some["triangle_id"], out["triangle_id"])


def test_sphere_depth_position_normals_match_the_closed_form():
    resolution, spp = (16, 16), 64
    scene = sphere_scene(resolution)
    r_in, r_out, chord = tessellation_radii(scene.meshes[0])
    assert 0 < RADIUS - r_in < 2e-3 and abs(r_out - RADIUS) < 1e-6
    out = ep.render_channels(scene, channels=["depth", "position", "geometry_normal", "shading_normal"],
                             spp=spp, seed=2)

    # Pixels whose whole footprint meets the inner sphere (no silhouette inside).
    full = torch.isfinite(sphere_hit(camera_rays(*pixel_grid(resolution, 17, True), resolution), r_in)).all(-1)
    assert int(full.sum()) >= 12
    d = camera_rays(*pixel_grid(resolution, 16, False), resolution)
    t_out, t_in = sphere_hit(d, r_out), sphere_hit(d, r_in)
    eye = torch.tensor(EYE, dtype=torch.float64)
    centre = torch.tensor(CENTRE, dtype=torch.float64)
    p = eye + t_out[..., None] * d
    normal = (p - centre) / r_out
    band = (t_in - t_out).amax(-1, keepdim=True)  # the tessellation's depth band in the pixel
    six_se = 6 / math.sqrt(spp)

    def check(name, closed, bound):
        """closed: (H, W, K, C) at the grid points; bound: (H, W, 1), the tessellation's."""
        got = out[name].double()[full]
        mean, spread = closed.mean(2)[full], closed.std(2)[full]
        tol = bound[full] + six_se * spread + 1e-5
        err = (got - mean).abs()
        print(f"{name}: max error {float(err.max()):.3g}, tolerance {float(tol.min()):.3g} .. {float(tol.max()):.3g}")
        assert bool((err <= tol).all()), f"{name}: error {float(err.max()):.3g}"

    check("depth", t_out[..., None], band)
    check("position", p, band)
    # The shading normal points from the centre to the hit (the vertices' normals are their
    # directions): |a/|a| - b/|b|| <= 2 |a - b| / |b|. The face normal adds at most `chord`.
    shading_bound = 2 * band / r_in
    check("shading_normal", normal, shading_bound)
    check("geometry_normal", normal, chord + shading_bound)


def projected_disc_area(radius, resolution):
    """Film area (pixels) of a sphere of the given radius around CENTRE: its silhouette is an
    ellipse on the image plane (a cone of half-angle asin(radius / distance) cut by the plane)."""
    h, w = resolution
    c = torch.tensor(CENTRE, dtype=torch.float64) - torch.tensor(EYE, dtype=torch.float64)
    dist = float(c.norm())
    a = math.asin(radius / dist)
    cos_theta = float(-c[2]) / dist  # angle between the cone's axis and the view direction
    # Plane z = -1 (screen units): semi-axes of the conic section of the cone.
    k = math.cos(a) ** 2 - (1 - cos_theta ** 2)
    semi_major = math.sin(a) * math.cos(a) / k
    semi_minor = math.sin(a) / math.sqrt(k)
    px_per_screen = w / (2 * math.tan(math.radians(FOV) / 2))
    return math.pi * semi_major * semi_minor * px_per_screen ** 2


def test_alpha_sum_is_the_projected_area():
    resolution, spp = (16, 16), 64
    scene = sphere_scene(resolution)
    r_in, r_out, _ = tessellation_radii(scene.meshes[0])
    alpha = ep.render_channels(scene, channels=["alpha"], spp=spp, seed=3)["alpha"].double()
    lo, hi = projected_disc_area(r_in, resolution), projected_disc_area(r_out, resolution)
    # The convex tessellation holds the inner sphere and lies in the outer one; noise: each
    # partly covered pixel's mean has variance <= 1 / (4 spp).
    partial = int(((alpha > 0) & (alpha < 1)).sum())
    noise = 6 * math.sqrt(partial / (4 * spp))
    total = float(alpha.sum())
    assert lo - noise <= total <= hi + noise, (lo, hi, total, noise)
    assert hi - lo < 0.02 * hi  # the band is narrow: the check has teeth


def translate_direction(scene):
    v = scene.meshes[0].vertices
    return v, torch.tensor([1.0, 0.5, 0.0]).expand_as(v).contiguous()


# Mitsuba's gradient metric and thresholds (as tests/python/test_gradients.py).
ERROR_MEAN, ERROR_MAX = 0.02, 0.3


@pytest.mark.parametrize("name", ["alpha", "depth", "geometry_normal"])
def test_silhouette_channels_derivative_matches_finite_differences(name):
    """Translating the sphere moves its outline: alpha's derivative is all boundary term, depth's
    is boundary (the depth against 0 behind) plus interior. Both fail with primary edges off.
    The step is small (a fortieth of a pixel): a pixel the outline only grazes has an alpha
    quadratic in the step, which a central difference with a larger step takes for a slope. (At
    a twentieth, the geometric normal's finite difference was itself off by up to 0.19 of the
    image's largest value, at the outline, against the derivative at 8 seeds on either side;
    max err 0.13-0.28 over 8 seeds. Now 0.06-0.11.)"""
    scene = sphere_scene((12, 12), rings=24, segments=48)
    param, direction = translate_direction(scene)
    fd = ep.finite_difference_channels(scene, param, direction, channels=[name], eps=2.5e-3,
                                       spp=131072, seed=2)[name]
    scale = float(fd.abs().max())
    assert scale > 0
    for edges in (True, False):
        d = ep.derivative_channels(scene, param, direction, channels=[name], spp=64, seed=1,
                                   edge_samples=400000, primary_edges=edges)[name]
        mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
        report = f"{name}, primary edges {edges}: mean err {mean_err:.4f}, max err {max_err:.4f}"
        print(report)
        if edges:
            assert mean_err <= ERROR_MEAN and max_err <= ERROR_MAX, report
        else:
            assert mean_err > ERROR_MEAN and max_err > ERROR_MAX, report


def test_reverse_mode_equals_forward_mode():
    scene = sphere_scene((10, 12), rings=12, segments=24)
    continuous = [n for n in ep.CHANNELS if n not in ep.ID_CHANNELS]
    options = dict(spp=2, seed=7, edge_samples=20000)
    params = {"vertices": translate_direction(scene),
              "camera position": (scene.camera.position, torch.tensor([0.3, -0.2, 0.1]))}
    for label, (param, direction) in params.items():
        d = ep.derivative_channels(scene, param, direction, channels=continuous, **options)
        gen = torch.Generator().manual_seed(4)
        adjoints = {n: torch.rand(d[n].shape, generator=gen) - 0.3 for n in continuous}
        expected = sum(float((adjoints[n].double() * d[n].double()).sum()) for n in continuous)
        param.requires_grad_(True)
        out = ep.render_channels(scene, channels=continuous, backward_seed=options["seed"], **options)
        sum((out[n] * adjoints[n]).sum() for n in continuous).backward()
        got = float((param.grad.double() * direction.double()).sum())
        param.requires_grad_(False)
        param.grad = None
        assert abs(expected) > 1e-2, label
        assert got == pytest.approx(expected, rel=2e-3, abs=1e-5), label


def test_a_silhouette_loss_points_towards_the_target():
    """Matching alpha alone moves the sphere: the gradient of the squared alpha difference with
    respect to a translation points to the target's position (it is all boundary term), and a
    few gradient steps close most of the gap."""
    base = sphere_scene((16, 16), rings=16, segments=32)
    target_offset = torch.tensor([0.15, -0.1, 0.0])
    v0 = base.meshes[0].vertices
    base.meshes[0].vertices = v0 + target_offset
    target = ep.render_channels(base, channels=["alpha"], spp=16, seed=1)["alpha"]
    offset = torch.zeros(3, requires_grad=True)
    optimiser = torch.optim.Adam([offset], lr=0.03)
    for step in range(20):
        base.meshes[0].vertices = v0 + offset
        alpha = ep.render_channels(base, channels=["alpha"], spp=4, seed=step)["alpha"]
        loss = (alpha - target).square().sum()
        optimiser.zero_grad()
        loss.backward()
        if step == 0:
            g = -offset.grad[:2]
            cosine = float(g @ target_offset[:2]) / float(g.norm() * target_offset[:2].norm())
            assert cosine > 0.9, cosine
        optimiser.step()
    error = float((offset.detach() - target_offset)[:2].norm())
    print(f"offset {offset.detach().tolist()}, target {target_offset.tolist()}, error {error:.4f}")
    assert error < 0.25 * float(target_offset[:2].norm()), (offset, error)


def test_edge_on_a_pixel_border_is_counted_once():
    """A square whose sides lie exactly on pixel borders (orthographic, 4 pixels per unit):
    moving its right side by dt adds 4 * height_px * dt to the alpha sum. Counting an edge
    sample in both pixels it touches would double it."""
    v, i = shapes.quad([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, 2.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                       up=torch.tensor([0.0, 1.0, 0.0]), camera_type="orthographic",
                       ortho_scale=1.0, resolution=(8, 8))
    scene = ep.Scene(camera=camera, meshes=[ep.Mesh(vertices=v, indices=i)])
    direction = torch.zeros_like(v)
    direction[[1, 2], 0] = 1.0  # the right side
    d = ep.derivative_channels(scene, v, direction, channels=["alpha"], spp=1, edge_samples=1000)["alpha"]
    assert float(d.sum()) == pytest.approx(4 * 4, rel=1e-4)
    assert float(d[:, 6].sum()) == pytest.approx(16, rel=1e-4) and float(d[:, 5].abs().sum()) == 0.0
    alpha = ep.render_channels(scene, channels=["alpha"], spp=4)["alpha"]
    assert float(alpha.sum()) == 16.0


def test_crop_window_and_environment():
    """A crop renders the crop of the full film's channels (the same samples and centre rays);
    the environment lights the background's radiance but is no surface: alpha and ids stay
    empty there, and the channels' derivatives have the crop's shape."""
    scene = sphere_scene((10, 12), rings=12, segments=24)
    black = ep.render_channels(scene, spp=2, seed=3)
    scene.envmap = ep.EnvironmentMap(values=torch.full((4, 8, 3), 0.5))
    full = ep.render_channels(scene, spp=2, seed=3)
    background = full["alpha"][..., 0] == 0
    assert bool(background.any())
    # the environment's bilinear lookup of a constant, to rounding (its weights (1 - f) and f)
    assert bool(((full["radiance"][background] - 0.5).abs() <= 1e-6).all())
    assert not torch.equal(full["radiance"], black["radiance"])
    for name in ep.CHANNELS:
        if name != "radiance":
            assert torch.equal(full[name], black[name]), name
    scene.camera.crop_window = (3, 2, 6, 5)  # x, y, width, height
    crop = ep.render_channels(scene, spp=2, seed=3)
    for name in ep.CHANNELS:
        assert torch.equal(crop[name], full[name][2:7, 3:9]), name
    v = scene.meshes[0].vertices
    d = ep.derivative_channels(scene, v, torch.ones_like(v), channels=["depth", "uv"], spp=1)
    assert tuple(d["depth"].shape) == (5, 6, 1) and tuple(d["uv"].shape) == (5, 6, 2)


def test_channel_errors_name_the_field():
    scene = sphere_scene((4, 4), rings=4, segments=6)
    with pytest.raises(ValueError, match=r"channels\[1\]: unknown channel 'normal'"):
        ep.render_channels(scene, channels=["alpha", "normal"], spp=1)
    with pytest.raises(ValueError, match=r"channels\[1\]: 'alpha' is asked for twice"):
        ep.render_channels(scene, channels=["alpha", "alpha"], spp=1)
    with pytest.raises(ValueError, match="channels: expected a list"):
        ep.render_channels(scene, channels="alpha", spp=1)
    with pytest.raises(ValueError, match="channels: asks for no channel"):
        ep.render_channels(scene, channels=[], spp=1)
    v = scene.meshes[0].vertices
    with pytest.raises(ValueError, match=r"channels\[0\]: 'mesh_id' is an id and has no derivative"):
        ep.derivative_channels(scene, v, torch.ones_like(v), channels=["mesh_id"], spp=1)
