"""Derivative images against Mitsuba 3 references (shared/conformance/mitsuba3).

For the configs whose parameter moves no visibility boundary (the interior term is the whole
gradient), ``ep.derivative_image`` along theta is compared with the ``*_fwd_ref.exr`` finite
difference by Mitsuba's metric: err = |x - ref| / max(|ref|, 0.2) over all values, failing if
mean(err) > error_mean or max(err) > error_max (thresholds from configs.json). The backward
check runs autograd as Mitsuba's test does: adjoint 0.001 everywhere, the gradient of theta
divided by 0.001 * H * W * 3 (the mean of the derivative image) against the mean of the
reference, err = |m - m_ref| / max(|m_ref|, 1) <= error_bwd.

Sample counts are Mitsuba's own (1024 forward, 128 backward), except where noted. Configs taking more than about
ten seconds on two cores carry the ``slow`` mark. Run with ``-s`` to see the numbers.
"""

import time

import pytest
import torch

import edgepath as ep

import conformance as C

if not C.data_available():
    pytest.skip(C.missing_data_reason(), allow_module_level=True)

CONTINUOUS = ["diffuse_albedo", "diffuse_albedo_g_i", "area_light_radiance",
              "directly_visible_area_light_radiance", "constant_emitter_radiance", "crop_window",
              "rotate_shading_normals_plane", "translate_plane_under_envmap"]
# Every emitter of these scenes is the one whose radiance theta offsets from 1.
RADIANCE_ONLY = {"constant_emitter_radiance", "directly_visible_area_light_radiance"}
FWD_SPP = 1024
# Two bounces: our noise at 1024 spp leaves mean err 0.036 of 0.04; twice the samples, 0.026.
FWD_SPP_OVERRIDE = {"diffuse_albedo_g_i": 2048}
BWD_SPP = 128
SLOW = {"diffuse_albedo", "diffuse_albedo_g_i", "constant_emitter_radiance"}
# Configs whose worst pixel is the reference's own noise: Mitsuba's test renders with the
# sampler and seed that made its reference, so that noise cancels there, and not here. Their
# max err is taken over 2x2 block means. crop_window: along the plane's edge (column 26) the
# reference reads 0.205-0.274 where our estimate at 16,384 spp reads 0.233-0.246, so the max
# err per pixel stayed at 0.14-0.24 at 1024-16,384 spp (over 6-12 seeds); over blocks it is
# 0.05-0.09 at 1024 spp.
MAX_ON_BLOCKS = {"crop_window"}
SEED = 0


def _params():
    return [pytest.param(n, id=n, marks=[pytest.mark.slow] if n in SLOW else []) for n in CONTINUOUS]


@pytest.mark.parametrize("name", _params())
def test_derivative_image_matches_mitsuba(name):
    thresholds = C.thresholds(name)
    theta = torch.zeros((), dtype=torch.float64, requires_grad=True)
    scene, param = C.build(name, theta)
    ref = C.load_ref(name, "fwd")
    start = time.perf_counter()
    spp = FWD_SPP_OVERRIDE.get(name, FWD_SPP)
    image = ep.derivative_image(scene, theta, torch.ones((), dtype=torch.float64), spp=spp,
                                max_bounces=param.max_bounces, seed=SEED)
    seconds = time.perf_counter() - start
    assert image.shape == ref.shape
    assert torch.isfinite(image).all()
    mean_err, max_err = C.image_error(image, ref, C.GRADIENT_FLOOR)
    if name in MAX_ON_BLOCKS:
        _, max_err = C.image_error(C.block_means(image, 2), C.block_means(ref, 2), C.GRADIENT_FLOOR)
    report = (f"{name}: spp {spp}, {seconds:.2f} s: mean err {mean_err:.4f} "
              f"(threshold {thresholds['error_mean']}), max err {max_err:.4f}"
              f"{' (2x2 blocks)' if name in MAX_ON_BLOCKS else ''} "
              f"(threshold {thresholds['error_max']}); image sums {float(image.sum()):.5g} "
              f"vs {float(ref.sum()):.5g}")
    print(report)
    assert mean_err <= thresholds["error_mean"], report
    assert max_err <= thresholds["error_max"], report
    if name != "translate_plane_under_envmap":  # true derivative 0: the reference is noise
        # Not a zero image passing through the floor: the sums agree within 3%.
        assert abs(float(image.sum()) / float(ref.sum()) - 1) < 0.03, report
    if name in RADIANCE_ONLY:
        # The image is (1 + theta) times a fixed image: its derivative IS the primal image.
        # (Mitsuba's own finite differences are 1.1-2.2% below its primal here.)
        primal = C.load_ref(name, "primal")
        ratio = float(image.double().mean() / primal.double().mean())
        assert abs(ratio - 1) < 0.005, f"{report}; mean / primal reference mean = {ratio:.4f}"


# Geometry configs whose derivative lives on silhouettes: the same backward check, edges included.
BACKWARD_GEOMETRY = ["translate_rectangle_emitter_on_black", "translate_sphere_emitter_on_black",
                     "scale_sphere_emitter_on_black", "translate_diffuse_rectangle_constant", "translate_camera"]


# crop_window's mean over seeds is 0.075% below the reference's; at 128 spp its error's
# standard deviation is about 0.1% (0.000-0.0019 over 12 seeds, 0.0022 at one more against the
# threshold 0.002), at 2048 spp a quarter of that.
BWD_SPP_OVERRIDE = {"crop_window": 2048}


@pytest.mark.parametrize("name", CONTINUOUS + BACKWARD_GEOMETRY)
def test_backward_matches_mitsuba(name):
    thresholds = C.thresholds(name)
    theta = torch.zeros((), dtype=torch.float64, requires_grad=True)
    scene, param = C.build(name, theta)
    image = ep.render(scene, spp=BWD_SPP_OVERRIDE.get(name, BWD_SPP), max_bounces=param.max_bounces, seed=SEED)
    (image * 0.001).sum().backward()
    m = float(theta.grad) / (0.001 * image.numel())
    m_ref = float(C.load_ref(name, "fwd").double().mean())
    err = abs(m - m_ref) / max(abs(m_ref), 1.0)
    report = f"{name}: backward mean {m:.5g}, reference {m_ref:.5g}, err {err:.2e} (threshold {thresholds['error_bwd']})"
    print(report)
    assert err <= thresholds["error_bwd"], report


# ---- geometry: the boundary term of primary visibility ---------------------------------------

def _config_case(name):
    """Thresholds, theta (0, float64, requires grad), the scene built from it, its parameter,
    the forward reference and the unit direction of theta."""
    theta = torch.zeros((), dtype=torch.float64, requires_grad=True)
    scene, param = C.build(name, theta)
    return (C.thresholds(name), theta, scene, param, C.load_ref(name, "fwd"),
            torch.ones((), dtype=torch.float64))


# spp of the interior term; edge samples fixed (their estimator is stratified along the edges).
GEOMETRY = {"translate_rectangle_emitter_on_black": 64, "translate_sphere_emitter_on_black": 64,
            "scale_sphere_emitter_on_black": 64, "translate_diffuse_rectangle_constant": 256,
            "translate_textured_plane": 2048, "translate_textured_area_emitter": 1024,
            "translate_camera": 1024}
GEOMETRY_EDGE_SAMPLES = 1_000_000
# Configs whose derivative lives on silhouettes in view: the interior term alone must fail.
ON_SILHOUETTES = {"translate_rectangle_emitter_on_black", "translate_sphere_emitter_on_black",
                  "scale_sphere_emitter_on_black", "translate_diffuse_rectangle_constant",
                  "translate_camera"}
# translate_camera's reference (a 2022 render, doubled, see conformance.FWD_REF_SCALE) is too
# noisy for its own max threshold: our central differences differ from it by max err 2.2 (> 1.6).
# Its mean is checked here and the max against our own finite differences below.
MAX_FROM_OWN_FD = {"translate_camera"}
# The sum of a derivative whose silhouettes cancel is noise in the reference: not compared.
SUMS_CANCEL = {"translate_diffuse_rectangle_constant", "translate_camera"}


@pytest.mark.parametrize("name", [pytest.param(n, id=n, marks=[pytest.mark.slow] if GEOMETRY[n] > 1024 else [])
                                  for n in GEOMETRY])
def test_geometry_derivative_image_matches_mitsuba(name):
    thresholds, theta, scene, param, ref, one = _config_case(name)
    start = time.perf_counter()
    image = ep.derivative_image(scene, theta, one, spp=GEOMETRY[name], max_bounces=param.max_bounces, seed=SEED,
                                edge_samples=GEOMETRY_EDGE_SAMPLES)
    seconds = time.perf_counter() - start
    assert torch.isfinite(image).all()

    def failures(img):
        mean_err, max_err = C.image_error(img, ref, C.GRADIENT_FLOOR)
        out = []
        if mean_err > thresholds["error_mean"]:
            out.append(f"mean err {mean_err:.4f} > {thresholds['error_mean']}")
        if name not in MAX_FROM_OWN_FD and max_err > thresholds["error_max"]:
            out.append(f"max err {max_err:.4f} > {thresholds['error_max']}")
        if name not in SUMS_CANCEL and abs(float(img.sum()) / float(ref.sum()) - 1) >= 0.03:
            out.append(f"sum {float(img.sum()):.5g} vs {float(ref.sum()):.5g}")
        return out

    mean_err, max_err = C.image_error(image, ref, C.GRADIENT_FLOOR)
    report = (f"{name}: spp {GEOMETRY[name]}, {seconds:.2f} s: mean err {mean_err:.4f} "
              f"(threshold {thresholds['error_mean']}), max err {max_err:.4f} "
              f"(threshold {thresholds['error_max']}); sums {float(image.sum()):.5g} vs {float(ref.sum()):.5g}")
    print(report)
    assert not failures(image), f"{report}: {failures(image)}"
    if name in ON_SILHOUETTES:
        # The same checks must reject the interior term alone (Mitsuba's mean metric by itself
        # passes an all-zero image for several of these configs).
        interior = ep.derivative_image(scene, theta, one, spp=GEOMETRY[name], max_bounces=param.max_bounces,
                                       seed=SEED, primary_edges=False)
        assert failures(interior), f"{name}: the interior term alone passes too; the check cannot see the edges"
    if name in MAX_FROM_OWN_FD:
        eps = 0.02
        renders = [ep.render(C.build(name, s * eps)[0], spp=8192, max_bounces=param.max_bounces, seed=3)
                   for s in (0.5, -0.5)]
        fd = (renders[0] - renders[1]) / eps
        fd_mean, fd_max = C.image_error(image, fd, C.GRADIENT_FLOOR)
        print(f"{name}: against our finite differences (8192 spp, step {eps}): mean err {fd_mean:.4f}, "
              f"max err {fd_max:.4f}")
        assert fd_mean <= 0.1 and fd_max <= 0.6


# ---- shadows: the boundary term of secondary visibility ---------------------------------------

# Passing today, at these sample counts. translate_self_shadowing_right_angle (a wall's shadow
# on a floor at a right angle, light grazing: max err 0.10 of 0.05 with uniform edge sampling at
# 256 spp) passes with the hierarchy. translate_occluder_area_light: a 32k-triangle sphere
# occluding a 32k-triangle light of radius 0.05 (a light cone of half angle 0.009 rad): rare
# large samples dominate its error (with uniform sampling at 128 spp mean err 0.145, max err 132).
# At 256 spp its image sum is off by 2.0-2.3% (standard deviation over seeds 0-5, mean +0.1%),
# too near the 3% bound on the sum for one seed: 1024 spp (seed 0: -1.25%).
SHADOWS = {"translate_plane_and_area_emitter": 256,
           "translate_textured_area_emitter_illuminating_plane": 256,
           "translate_shadow_receiver_area_light": 256,
           "translate_self_shadowing_right_angle": 256,
           "translate_occluder_area_light": 1024}
SHADOWS_SLOW = {"translate_shadow_receiver_area_light", "translate_self_shadowing_right_angle",
                "translate_occluder_area_light"}
# Configs where the interior and primary terms alone fail (by the metric named): the check sees
# the shadow's edge. (Without secondary edges the self-shadowing config's mean err is 0.002, its
# max err 0.10.)
SHADOW_NEEDED = {"translate_plane_and_area_emitter": "error_mean", "translate_self_shadowing_right_angle": "error_max"}


@pytest.mark.parametrize("name", [pytest.param(n, id=n, marks=[pytest.mark.slow] if n in SHADOWS_SLOW else [])
                                  for n in SHADOWS])
def test_shadow_derivative_image_matches_mitsuba(name):
    thresholds, theta, scene, param, ref, one = _config_case(name)
    image = ep.derivative_image(scene, theta, one, spp=SHADOWS[name], max_bounces=param.max_bounces, seed=SEED)
    mean_err, max_err = C.image_error(image, ref, C.GRADIENT_FLOOR)
    report = (f"{name}: mean err {mean_err:.4f} (threshold {thresholds['error_mean']}), max err {max_err:.4f} "
              f"(threshold {thresholds['error_max']}); sums {float(image.sum()):.5g} vs {float(ref.sum()):.5g}")
    print(report)
    assert mean_err <= thresholds["error_mean"] and max_err <= thresholds["error_max"], report
    assert abs(float(image.sum()) / float(ref.sum()) - 1) < 0.03, report
    if name in SHADOW_NEEDED:
        without = ep.derivative_image(scene, theta, one, spp=SHADOWS[name], max_bounces=param.max_bounces,
                                      seed=SEED, secondary_edges=False)
        mean_without, max_without = C.image_error(without, ref, C.GRADIENT_FLOOR)
        metric = SHADOW_NEEDED[name]
        assert (mean_without if metric == "error_mean" else max_without) > thresholds[metric]
