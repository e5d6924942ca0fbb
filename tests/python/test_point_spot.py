"""Point and spot lights (edgepath.lights.point_light, spot_light): with radius 0 delta lights
(edgepath.PointLight), with a radius small emitting spheres whose radiance has the spot's
profile. A floor they light against the closed form of its irradiance, a scene file against
Mitsuba 3's image, derivative images of every parameter against finite differences, an
occluder's shadow (boundary terms with a radius, none without), and inverse rendering.
The scene: a floor seen from above by an orthographic camera, a square between it and the
light."""

import math
from pathlib import Path

import pytest
import torch

import conformance as C
import edgepath as ep
from edgepath import shapes
from test_sun import assert_occluder_derivative_matches

SCENE_DIR = Path(__file__).resolve().parent / "mitsuba_refs"
ALBEDO = 0.5


def as_vector(v):
    return v if isinstance(v, torch.Tensor) else torch.tensor(v, dtype=torch.float64)


def spot_scene(position=(0.3, 2.0, 0.1), direction=(0.2, -1.0, 0.1), intensity=4.0,
               cutoff=30.0, beam=20.0, radius=0.0, occluder=None, resolution=16,
               ortho_scale=1.5, spot=True) -> ep.Scene:
    """The floor y = 0 (seen from above over [-ortho_scale, ortho_scale]^2) under a spot (or,
    without ``spot``, a point) light; a square at height 0.8 shifted by ``occluder`` if given."""
    fv, fi = shapes.quad([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]])
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=ep.Material(diffuse=ALBEDO, specular=0.0))]
    if spot:
        light = ep.lights.spot_light(as_vector(position), as_vector(direction), intensity, cutoff,
                                     beam, radius=radius)
    else:
        light = ep.lights.point_light(as_vector(position), intensity, radius=radius)
    lights = []
    if isinstance(light, ep.PointLight):
        lights.append(light)
    else:
        meshes.append(light)
    if occluder is not None:
        ov, oi = shapes.quad([[-0.3, 0.8, -0.3], [0.3, 0.8, -0.3], [0.3, 0.8, 0.3], [-0.3, 0.8, 0.3]])
        meshes.append(ep.Mesh(vertices=ov + torch.as_tensor(occluder, dtype=torch.float32),
                              indices=oi, material=ep.Material(diffuse=0.5, specular=0.0)))
    camera = ep.Camera(position=torch.tensor([0.0, 0.5, 0.0]), look_at=torch.zeros(3),
                       up=torch.tensor([0.0, 0, -1]), camera_type="orthographic",
                       ortho_scale=ortho_scale, resolution=(resolution, resolution))
    return ep.Scene(camera=camera, meshes=meshes, point_lights=lights)


def floor_closed_form(position, direction, intensity, cutoff, beam, resolution, ortho_scale,
                      sub=8, spot=True):
    """The floor's radiance under the light, per pixel: the mean over sub x sub points of the
    pixel of albedo / pi * I s(theta) cos / d^2 (s: Mitsuba's spot falloff)."""
    p = torch.tensor(position, dtype=torch.float64)
    a = torch.tensor(direction, dtype=torch.float64)
    a = a / a.norm()
    k = (torch.arange(resolution * sub, dtype=torch.float64) + 0.5) / (resolution * sub)
    coords = (2 * k - 1) * ortho_scale
    # Image right is +x, image down is +z (up = -z on the film).
    z, x = torch.meshgrid(coords, coords, indexing="ij")
    q = torch.stack([x, torch.zeros_like(x), z], -1)
    to = p - q
    d2 = (to * to).sum(-1)
    w = to / d2.sqrt()[..., None]
    cos_n = w[..., 1]
    theta = torch.rad2deg(torch.acos((-w * a).sum(-1).clamp(-1, 1)))
    if spot:
        s = ((cutoff - theta) / (cutoff - beam)).clamp(0, 1)
    else:
        s = torch.ones_like(theta)
    e = ALBEDO / math.pi * intensity * s * cos_n / d2
    return e.reshape(resolution, sub, resolution, sub).mean((1, 3))


@pytest.mark.parametrize("radius, spot", [(0.0, True), (0.0, False), (0.02, True)])
def test_lit_floor_matches_the_closed_form(radius, spot):
    """Pixel by pixel, across the beam, the falloff and the dark outside: a delta light within
    the pixel integration's noise (measured: relative L1 0.005); a sphere of radius 0.02,
    sampled by solid angle, within its tessellation (its projected area varies by about 1%
    with the direction) and the noise (measured at 1024 spp: 0.009 at seed 3; by area, as
    before solid-angle sampling: 0.044, and 0.032 at 4096 spp)."""
    position, direction = (0.3, 2.0, 0.1), (0.2, -1.0, 0.1)
    scene = spot_scene(position, direction, radius=radius, spot=spot, resolution=16)
    image = ep.render(scene, spp=256 if radius == 0 else 1024, seed=1)
    expected = floor_closed_form(position, direction, 4.0, 30.0, 20.0, 16, 1.5, spot=spot)
    lit = image.mean(-1).double()
    error = float((lit - expected).abs().sum() / expected.sum())
    print(f"relative L1 against the closed form: {error:.4f}, sum {float(lit.sum() / expected.sum()):.4f}")
    assert error < (0.01 if radius == 0 else 0.02)
    assert float(lit.sum() / expected.sum()) == pytest.approx(1.0, abs=0.01)
    if spot:
        # Outside the cone, dark (but for a pixel the cone touches between the points above).
        assert float(expected.min()) == 0.0
        assert float(lit[expected == 0].abs().max()) < 1e-3 * float(expected.max())


def test_scene_file_matches_mitsuba():
    """A point and a spot light of radius 0 over a floor and a cube (hard shadows), the direct
    integrator, against Mitsuba 3's image (mitsuba_refs/make_references.py): each channel's
    mean within 1%, Mitsuba's primal metric (mean 0.02, max 0.2 of the direct-light
    conformance scenes) on 2 x 2 blocks of pixels."""
    loaded = ep.load_mitsuba(SCENE_DIR / "point_spot.xml")
    assert set(loaded.point_lights) == {"bulb", "spot"}
    assert len(loaded.scene.point_lights) == 2 and loaded.max_bounces == 1
    ref = ep.imread(SCENE_DIR / "point_spot.exr")[..., :3].float()
    image = loaded.render(spp=256)
    relative = image.mean((0, 1)) / ref.mean((0, 1)) - 1
    blocks = [torch.nn.functional.avg_pool2d(x.permute(2, 0, 1)[None], 2)[0] for x in (image, ref)]
    err = (blocks[0].double() - blocks[1].double()).abs() / blocks[1].double().abs().clamp_min(0.02)
    print("channel means", relative.tolist(), "blocks", float(err.mean()), float(err.max()))
    assert float(relative.abs().max()) < 0.01
    assert float(err.mean()) < 0.02 and float(err.max()) < 0.2


def derivative_and_fd(make, value, direction, eps, spp, seed=2):
    """The derivative image along ``direction`` at ``value`` and the central finite difference
    of step eps along it, both with the random numbers of ``seed``: the same camera samples
    and light samples, so that what differs is the derivative, not the noise."""
    param = torch.tensor(value, dtype=torch.float64, requires_grad=True)
    direction = torch.as_tensor(direction, dtype=torch.float64)
    d_image = ep.derivative_image(make(param), param, direction, spp=spp, seed=seed)
    with torch.no_grad():
        plus = ep.render(make(param.detach() + eps / 2 * direction), spp=spp, seed=seed)
        minus = ep.render(make(param.detach() - eps / 2 * direction), spp=spp, seed=seed)
    return d_image, (plus - minus) / eps


# (name, make(param, radius), value, direction, finite-difference step): every parameter of the
# light, on the floor without an occluder (no shadow edges).
PARAMETERS = [
    ("intensity", lambda x, r: spot_scene(intensity=x, radius=r), 4.0, 1.0, 0.25),
    ("position", lambda x, r: spot_scene(position=x, radius=r), [0.3, 2.0, 0.1], [1.0, 0.3, -0.5], 0.0125),
    ("direction", lambda x, r: spot_scene(direction=x, radius=r), [0.2, -1.0, 0.1], [0.5, 0.0, 0.3], 0.005),
    ("cutoff", lambda x, r: spot_scene(cutoff=x, radius=r), 30.0, 1.0, 0.125),
    ("beam", lambda x, r: spot_scene(beam=x, radius=r), 20.0, 1.0, 0.125),
    ("point position", lambda x, r: spot_scene(position=x, radius=r, spot=False), [0.3, 2.0, 0.1],
     [1.0, 0.3, -0.5], 0.0125),
]
SPHERE_PARAMETERS = [p for p in PARAMETERS if "position" not in p[0]]


@pytest.mark.parametrize("name, make, value, direction, eps", PARAMETERS, ids=[p[0] for p in PARAMETERS])
def test_delta_light_derivatives_match_finite_differences(name, make, value, direction, eps):
    """Radius 0: no boundaries move, the derivative is the interior term; measured relative L1
    0.000 (intensity: linear), 0.005 (position), 0.003 (direction), 0.003 (cutoff), 0.004
    (beam), 0.000 (point light's position); with the steps 4 times as large, 0.7 to 2.3 times
    those, the finite differences' own error."""
    d_image, fd_image = derivative_and_fd(lambda x: make(x, 0.0), value, direction, eps, 64)
    error = C.relative_l1(d_image, fd_image)
    print(f"{name}: relative L1 {error:.4f}")
    assert error < 0.01


@pytest.mark.parametrize("name, make, value, direction, eps", SPHERE_PARAMETERS,
                         ids=[p[0] for p in SPHERE_PARAMETERS])
def test_spot_sphere_derivatives_match_finite_differences(name, make, value, direction, eps):
    """Radius 0.05: the intensity's and the profile's derivatives through the emission the
    light samples see (measured relative L1: 0.000, 0.005, 0.005, 0.004)."""
    d_image, fd_image = derivative_and_fd(lambda x: make(x, 0.05), value, direction, eps, 64)
    error = C.relative_l1(d_image, fd_image)
    print(f"{name}: relative L1 {error:.4f}")
    assert error < 0.015


@pytest.mark.slow
def test_spot_sphere_position_derivative_matches_finite_differences_in_sum():
    """Moving the sphere moves its outline seen from the floor: the boundary terms carry the
    position's derivative, noisily, so it is compared in sum, as sphere_light's, over four seeds.
    Measured at 512 spp, seeds 1 to 4: -12.6, -12.0, -9.9, -9.8 (mean -11.1) against the finite
    difference's -12.1 (4096 spp); at radius 0.05 the spread is larger (8 x 8 pixels at 2048 spp:
    -1.6 to -4.1 against -3.0)."""
    def make(x):
        return spot_scene(position=x, radius=0.1)
    direction = torch.tensor([1.0, 0.3, -0.5], dtype=torch.float64)
    param = torch.tensor([0.3, 2.0, 0.1], dtype=torch.float64, requires_grad=True)
    d_sum = sum(float(ep.derivative_image(make(param), param, direction, spp=512, seed=k).sum())
                for k in range(1, 5)) / 4
    with torch.no_grad():
        fd_image = (ep.render(make(param.detach() + 0.025 * direction), spp=4096, seed=2) -
                    ep.render(make(param.detach() - 0.025 * direction), spp=4096, seed=2)) / 0.05
    fd_sum = float(fd_image.sum())
    print(f"sums: derivative {d_sum:.3f}, finite difference {fd_sum:.3f}")
    assert abs(d_sum - fd_sum) < 0.15 * abs(fd_sum)


def test_occluder_in_front_of_the_spot_sphere_matches_finite_differences():
    """The penumbra moves with the square: the boundary term of secondary edges (the square's
    edges seen from the floor against the small sphere). Measured at 512 spp: relative L1
    0.073 (0.13 when the sphere was sampled by area); 1.0 without the term."""
    assert_occluder_derivative_matches(
        lambda occluder: spot_scene(radius=0.1, occluder=occluder), 0.05, 512, 0.25, 0.5)


def test_occluder_in_front_of_a_delta_light_has_no_boundary_term():
    """Documented: a delta light's hard shadow moves with the square, and the derivative image
    misses it (boundary terms or not, they are the same)."""
    shift = torch.tensor(0.0, dtype=torch.float64, requires_grad=True)

    def make(x):
        return spot_scene(occluder=torch.stack([x, torch.zeros_like(x), torch.zeros_like(x)]))
    d_image = ep.derivative_image(make(shift), shift, torch.ones_like(shift), spp=64, seed=1)
    with torch.no_grad():
        fd = (ep.render(make(shift.detach() + 0.025), spp=64, seed=2) -
              ep.render(make(shift.detach() - 0.025), spp=64, seed=2)) / 0.05
    assert float(fd.abs().sum()) > 1.0
    assert float(d_image.abs().sum()) < 1e-3 * float(fd.abs().sum())


@pytest.mark.parametrize("kwargs, message", [
    (dict(position=[0, 1], direction=[0, -1, 0]), "position"),
    (dict(position=[0, 1, 0], direction=[0, -1, 0], radius=-1.0), "radius"),
    (dict(position=[0, 1, 0], direction=[0, -1, 0], intensity=-1.0), "intensity"),
])
def test_bad_arguments_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ep.lights.spot_light(**kwargs)


@pytest.mark.parametrize("spot, message", [
    (dict(direction=[0.0, 0, 0]), r"point_lights\[0\].spot.direction"),
    (dict(direction=[0.0, -1, 0], cutoff_angle=200.0), r"point_lights\[0\].spot.cutoff_angle"),
    (dict(direction=[0.0, -1, 0], cutoff_angle=20.0, beam_width=20.0), r"point_lights\[0\].spot.beam_width"),
])
def test_bad_spot_names_the_field(spot, message):
    scene = spot_scene()
    scene.point_lights = [ep.PointLight(position=torch.tensor([0.0, 1, 0]), intensity=1.0,
                                        spot=ep.Spot(**spot))]
    with pytest.raises(ValueError, match=message):
        ep.render(scene, spp=1)


def recover(make, truth, start, steps, lr, spp):
    """Adam from ``start`` towards the image of ``truth``: the mean of the last 20 iterates,
    and the losses at the start and there (with the same samples)."""
    target = ep.render(make(truth), spp=256, seed=100)
    x = start.clone().requires_grad_()
    optimizer = torch.optim.Adam([x], lr=lr)
    history = []
    for step in range(steps):
        optimizer.zero_grad()
        loss = (ep.render(make(x), spp=spp, seed=step) - target).square().mean()
        loss.backward()
        optimizer.step()
        history.append(x.detach().clone())
    estimate = torch.stack(history[-20:]).mean(0)
    with torch.no_grad():
        before, after = (float((ep.render(make(t), spp=64, seed=7) - target).square().mean())
                         for t in (start, estimate))
    return estimate, before, after


def test_recover_the_direction_of_a_delta_spot_from_its_lit_region():
    """A spot of radius 0 aimed 0.53 radians away: its direction is recovered from the ellipse
    it lights on the floor (measured: 0.010 radians off, in 60 steps; loss 5.4e-3 -> 4.3e-6)."""
    truth = torch.tensor([0.2, -1.0, 0.1], dtype=torch.float64)
    start = torch.tensor([-0.25, -1.0, -0.2], dtype=torch.float64)
    estimate, before, after = recover(lambda x: spot_scene(direction=x), truth, start, 60, 0.03, 4)
    angle = lambda a: float(torch.acos((a / a.norm()) @ (truth / truth.norm())))
    print(f"loss {before:.4g} -> {after:.4g}; direction {angle(start):.3f} -> {angle(estimate):.4f} rad")
    assert after < 0.05 * before
    assert angle(estimate) < 0.05 * angle(start)


def test_recover_the_position_of_a_spot_sphere_from_its_lit_region():
    """A spot of radius 0.1 moved 0.5 sideways: its position (x and z) is recovered from the
    ellipse it lights, the gradient coming from the boundary terms of its outline seen from the
    floor (measured: 0.003 off, in 100 steps; loss 1.9e-3 -> 8.1e-6)."""
    truth = torch.tensor([0.3, 0.1], dtype=torch.float64)
    start = torch.tensor([-0.1, 0.4], dtype=torch.float64)

    def make(x):
        return spot_scene(position=torch.stack([x[0], torch.full_like(x[0], 2.0), x[1]]), radius=0.1)
    estimate, before, after = recover(make, truth, start, 100, 0.02, 8)
    error, start_error = float((estimate - truth).norm()), float((start - truth).norm())
    print(f"loss {before:.4g} -> {after:.4g}; position error {start_error:.3f} -> {error:.4f}")
    assert after < 0.2 * before
    assert error < 0.15 * start_error


@pytest.mark.parametrize("light, message", [
    (dict(position=torch.tensor([0.0, float("nan"), 0])), r"point_lights\[0\].position"),
    (dict(position=torch.tensor([0.0, 1, 0]), intensity=torch.tensor([1.0, -1, 1])),
     r"point_lights\[0\].intensity"),
    (dict(position=torch.tensor([0.0, 1, 0]), intensity=torch.ones(2)), r"point_lights\[0\].intensity"),
    # A texture's shape is no constant (found by the fuzzer: it was a RuntimeError of reshape).
    (dict(position=torch.tensor([0.0, 1, 0]), intensity=torch.ones(3, 3, 3)),
     r"point_lights\[0\].intensity: a constant must have shape \(3,\) or \(1,\), got \(3, 3, 3\)"),
    (dict(position=torch.zeros(2)), r"point_lights\[0\].position"),
])
def test_bad_point_light_names_the_field(light, message):
    scene = spot_scene()
    scene.point_lights = [ep.PointLight(**light)]
    with pytest.raises(ValueError, match=message):
        ep.render(scene, spp=1)
    scene.point_lights = [spot_scene().meshes[0]]
    with pytest.raises(ValueError, match=r"point_lights\[0\]: expected an edgepath.PointLight"):
        ep.render(scene, spp=1)


def test_profile_seen_by_the_camera_follows_the_camera_rays():
    """A wall filling the view emits with a spot profile: turning the camera changes the
    directions its rays meet the wall from, and the profile's derivative in the direction
    reaches the camera (no outline in view; measured relative L1 0.003)."""
    def make(look):
        qv, qi = shapes.quad([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]])
        wall = ep.Mesh(vertices=qv, indices=qi, emission=torch.tensor([2.0, 2.0, 2.0]),
                       spot=ep.Spot(direction=torch.tensor([0.1, 0.0, 1.0]), cutoff_angle=30.0,
                                    beam_width=5.0))
        camera = ep.Camera(position=torch.tensor([0.0, 0.0, 2.0]), look_at=look, resolution=(16, 16),
                           fov=60.0)
        return ep.Scene(camera=camera, meshes=[wall])
    d_image, fd_image = derivative_and_fd(make, [0.0, 0.0, 0.0], [0.5, 0.2, 0.0], 0.01, 16)
    error = C.relative_l1(d_image, fd_image)
    print(f"relative L1 {error:.4f}")
    assert float(fd_image.abs().sum()) > 100 and error < 0.01


def test_views_and_gradients_of_many_views_see_the_point_lights():
    """``render(cameras=...)`` renders each view as ``render`` does, point lights included, and
    its backward pass reaches them."""
    scene = spot_scene(intensity=torch.tensor(4.0, requires_grad=True))
    views = ep.render(scene, spp=4, seed=3, backward_seed=3, cameras=[scene.camera, scene.camera])
    single = ep.render(scene, spp=4, seed=3, backward_seed=3)
    assert float(single.sum()) > 1.0
    assert torch.equal(views[0], single.detach()) and torch.equal(views[1], single.detach())
    views.sum().backward()
    intensity = scene.point_lights[0].intensity
    # Linear in the intensity: d(sum)/dI = sum / I for each view.
    assert float(intensity.grad) == pytest.approx(2 * float(single.sum()) / 4.0, rel=1e-4)


@pytest.mark.parametrize("max_bounces", [1, 2])
def test_point_lights_only_where_the_path_scatters(max_bounces):
    """A wall beside the floor, lit by a point light too: with one bounce, the paths that go
    on from the floor to the wall end there (no light sampled at the wall), with two they
    sample it. The image is linear in the intensity, so its derivative is the image over the
    intensity, exactly, with the same random numbers."""
    def make(intensity):
        scene = spot_scene(intensity=intensity, spot=False)
        wv, wi = shapes.quad([[1.0, 0, -3], [1.0, 0, 3], [1.0, 2, 3], [1.0, 2, -3]])
        scene.meshes = list(scene.meshes) + [ep.Mesh(vertices=wv, indices=wi,
                                                     material=ep.Material(diffuse=0.8, two_sided=True))]
        return scene
    intensity = torch.tensor(4.0, dtype=torch.float64, requires_grad=True)
    d_image = ep.derivative_image(make(intensity), intensity, torch.ones_like(intensity), spp=16,
                                  seed=2, max_bounces=max_bounces)
    image = ep.render(make(4.0), spp=16, seed=2, max_bounces=max_bounces)
    assert C.relative_l1(d_image, image / 4.0) < 1e-4
