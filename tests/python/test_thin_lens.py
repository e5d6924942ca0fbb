"""The thin lens camera: its image against Mitsuba 3's ``thinlens`` (a reference rendered once,
tests/python/references), derivative images of the aperture radius, the focus distance and an
out-of-focus occluder against finite differences, and a focus distance recovered by inverse
rendering. The scene: a wall in focus with a dark square on it, a dark square halfway to the
camera out of focus, a constant sky."""

from pathlib import Path

import pytest
import torch

import conformance as C
import edgepath as ep
from edgepath import shapes
from test_gradients import assert_autograd_equals_derivative_image

REFERENCES = Path(__file__).resolve().parent / "references"


def lens_scene(aperture=0.3, focus=4.5, occluder_shift=(0.0, 0.0, 0.0), resolution=(12, 16)) -> ep.Scene:
    def square(centre, half, reflectance):
        c = torch.as_tensor(centre, dtype=torch.float32)
        v, i = shapes.quad([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
        return ep.Mesh(vertices=v + c, indices=i, material=ep.Material(diffuse=reflectance, specular=0.0))
    meshes = [square((0, 0, 0), 3.0, 0.7), square((-0.9, 0.45, 0.02), 0.4, 0.1),
              square(torch.tensor([0.43, -0.2, 2.5]) + torch.tensor(occluder_shift), 0.35, 0.05)]
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, 5.0]), look_at=torch.zeros(3), fov=40.0,
                       resolution=resolution, camera_type="thinlens",
                       aperture_radius=torch.tensor(float(aperture)),
                       focus_distance=torch.as_tensor(focus, dtype=torch.float32))
    return ep.Scene(camera=camera, meshes=meshes, envmap=ep.EnvironmentMap(values=torch.ones(1, 1, 3)))


# ---- forward: Mitsuba 3's thinlens ----------------------------------------------------------

# Thresholds of Mitsuba's primal metric (floor 0.02) for the reference at 8192 spp and edgepath
# at 1024 spp: the conformance configs' usual ones for diffuse scenes.
PRIMAL_MEAN, PRIMAL_MAX = 0.02, 0.3


def test_image_matches_mitsuba_thinlens():
    ref = ep.imread(REFERENCES / "thinlens.exr")[:, :, :3]
    loaded = ep.load_mitsuba(REFERENCES / "thinlens.xml")
    camera = loaded.scene.camera
    assert camera.camera_type == "thinlens"
    assert float(camera.aperture_radius) == pytest.approx(0.3)
    assert float(camera.focus_distance) == pytest.approx(5.0)
    image = ep.render(loaded.scene, spp=1024, max_bounces=loaded.max_bounces, seed=3)
    mean_err, max_err = C.image_error(image, ref, C.PRIMAL_FLOOR)
    print(f"thin lens vs Mitsuba: mean err {mean_err:.4f}, max err {max_err:.4f}")
    assert mean_err <= PRIMAL_MEAN and max_err <= PRIMAL_MAX
    # The blur is what is compared: a pinhole's image fails the same check.
    camera.aperture_radius = 0.0
    pinhole = ep.render(loaded.scene, spp=1024, max_bounces=loaded.max_bounces, seed=3)
    pin_mean, pin_max = C.image_error(pinhole, ref, C.PRIMAL_FLOOR)
    assert pin_mean > PRIMAL_MEAN or pin_max > PRIMAL_MAX


def test_zero_aperture_is_the_pinhole():
    scene = lens_scene(aperture=0.0, resolution=(6, 8))
    lens = ep.render_channels(scene, ["position", "alpha"], spp=4, seed=1)
    scene.camera.camera_type = "perspective"
    pinhole = ep.render_channels(scene, ["position", "alpha"], spp=4, seed=1)
    # The same film points, so the same first hits up to rounding (the path's later random
    # numbers differ: the thin lens draws two more per sample).
    for name in ("position", "alpha"):
        assert torch.allclose(lens[name], pinhole[name], atol=1e-4), name
    assert float(pinhole["alpha"].min()) == 1.0


def test_bad_lens_parameters_name_the_field():
    with pytest.raises(ValueError, match="camera.aperture_radius"):
        ep.render(lens_scene(aperture=-0.1, resolution=(2, 2)), spp=1)
    with pytest.raises(ValueError, match="camera.focus_distance"):
        ep.render(lens_scene(focus=0.0, resolution=(2, 2)), spp=1)


# ---- derivative images against finite differences -----------------------------------------


# Derivative and finite-difference images at 2048 spp are compared by their relative L1
# distance: most of the derivative lies in blurred outlines, where a finite difference with the
# same lens samples still flips visibility, so per-pixel metrics measure its noise. Measured
# (12 x 16 pixels): two finite differences of other seeds differ by 0.14 (aperture), 0.26
# (focus, eps 0.5) and 0.085 (occluder; 0.12 at 1024 spp); the derivative image is 0.11, 0.19
# and 0.06 from one.
# A missing boundary term gives 1.0 (the interior term is near zero for all three).
L1_TOLERANCE = 0.3


def assert_derivative_matches(scene, param, direction, eps, spp=2048):
    d_image = ep.derivative_image(scene, param, direction, spp=spp, seed=1, max_bounces=1)
    fd_image = ep.finite_difference_image(scene, param, direction, eps=eps, spp=spp, seed=2,
                                          max_bounces=1)
    error = C.relative_l1(d_image, fd_image)
    interior = ep.derivative_image(scene, param, direction, spp=spp // 4, seed=1, max_bounces=1,
                                   primary_edges=False)
    interior_error = C.relative_l1(interior, fd_image)
    print(f"relative L1 error {error:.3f} (<= {L1_TOLERANCE}); interior term alone "
          f"{interior_error:.3f}")
    assert float(fd_image.abs().max()) > 0.05, "the finite difference vanishes, nothing is tested"
    assert error <= L1_TOLERANCE
    # The blur's derivative is the boundary term of the camera's edges, per lens point.
    assert interior_error > 2 * L1_TOLERANCE


# The aperture radius and the focus distance move the blur of every silhouette out of focus;
# the occluder (out of focus) moves its blurred outline.
@pytest.mark.slow
@pytest.mark.parametrize("name,eps", [("aperture_radius", 0.1), ("focus_distance", 1.0)])
def test_lens_parameter_derivative_matches_finite_differences(name, eps):
    scene = lens_scene()
    param = getattr(scene.camera, name)
    assert_derivative_matches(scene, param, torch.ones_like(param), eps)


def test_out_of_focus_occluder_derivative_matches_finite_differences():
    scene = lens_scene()
    vertices = scene.meshes[2].vertices
    direction = torch.zeros_like(vertices)
    direction[:, 0] = 1.0
    assert_derivative_matches(scene, vertices, direction, eps=0.05, spp=1024)


@pytest.mark.parametrize("name", ["aperture_radius", "focus_distance", "occluder", "position"])
def test_autograd_equals_derivative_image(name):
    """Reverse mode (the edge pass with an adjoint image) equals forward mode for the same
    random numbers: sum(a * dI/dtheta . dir) = (d sum(a * I) / d theta) . dir."""
    scene = lens_scene()
    if name == "occluder":
        param = scene.meshes[2].vertices
        direction = torch.zeros_like(param)
        direction[:, 0] = 1.0
    else:
        param = getattr(scene.camera, name)
        direction = torch.tensor([0.3, -0.2, 0.1]) if name == "position" else torch.ones_like(param)
    assert_autograd_equals_derivative_image(scene, param, direction, name, spp=4, max_bounces=1,
                                            seed=3)


def test_uniform_edge_sampling_agrees():
    """The baseline edge sampling (every edge by world length, projected per lens point) has
    the same expectation as the importance sampling of film lengths seen from the centre."""
    scene = lens_scene()
    vertices = scene.meshes[2].vertices
    direction = torch.zeros_like(vertices)
    direction[:, 0] = 1.0
    importance = ep.derivative_image(scene, vertices, direction, spp=512, seed=1)
    uniform = ep.derivative_image(scene, vertices, direction, spp=512, seed=2,
                                  edge_sampling="uniform", edge_samples=12 * 16 * 2048)
    error = C.relative_l1(uniform, importance)
    print(f"relative L1 distance {error:.3f}")
    assert error < 0.15


# ---- inverse rendering -------------------------------------------------------------------------

def test_recover_focus_distance():
    truth, start = 4.0, 5.5
    target = ep.render(lens_scene(focus=truth), spp=256, seed=100)
    focus = torch.tensor(start, requires_grad=True)
    history = C.descend(focus, lambda seed: (ep.render(lens_scene(focus=focus), spp=8, seed=seed) - target)
                        .square().mean(), lr=0.1, steps=50)
    estimate = sum(history[-10:]) / 10
    print(f"focus distance {start} -> {estimate:.3f} (truth {truth})")
    # Over 8 other sets of seeds: 4.02 +- 0.035. (30 steps of Adam at lr 0.1 ended on the swing
    # past the truth, at 3.79 +- 0.06.)
    assert abs(estimate - truth) < 0.1 * abs(start - truth)
