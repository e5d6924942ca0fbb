"""Primal images against Mitsuba 3 references (shared/conformance/mitsuba3).

Every config with reference images is rendered at theta = 0 and compared with its
``*_primal_ref.exr`` by Mitsuba's metric: err = |x - ref| / max(|ref|, 0.02) over all values,
failing if mean(err) > error_mean or max(err) > error_max (thresholds from configs.json).
Run with ``-s`` (or ``-rA``) to see each config's numbers.

The sample counts below are the smallest (powers of two) at which the check passes with a
margin at seed 0; configs that need more than about ten seconds on two cores carry the
``slow`` mark (deselect them with ``-m "not slow"``). Environment variables:
EDGEPATH_CONFORMANCE_SPP_SCALE multiplies every sample count; EDGEPATH_CONFORMANCE_OUT names
a folder to receive our image, the reference and the error map of each config (EXR and PNG).
"""

import os
import time
from pathlib import Path

import pytest
import torch

import edgepath as ep

import conformance as C

if not C.data_available():
    pytest.skip(C.missing_data_reason(), allow_module_level=True)

# Samples per pixel for the primal check. Mitsuba's own test uses 1024 (4096 or 16768 for
# a few); the references were rendered with far more, so their noise is small next to ours.
SPP = {
    "diffuse_albedo": 256,
    "diffuse_albedo_g_i": 256,
    "area_light_radiance": 4096,
    "directly_visible_area_light_radiance": 4096,
    "constant_emitter_radiance": 1024,
    "crop_window": 1024,
    "rotate_shading_normals_plane": 4096,
    "translate_textured_plane": 64,
    "translate_plane_under_envmap": 2048,
    "translate_diffuse_rectangle_constant": 256,
    "translate_rectangle_emitter_on_black": 256,
    "translate_sphere_emitter_on_black": 256,
    "scale_sphere_emitter_on_black": 2048,
    "translate_occluder_area_light": 1024,
    "translate_shadow_receiver_area_light": 2048,
    "translate_plane_and_area_emitter": 2048,
    "translate_self_shadowing_right_angle": 256,
    "translate_camera": 256,
    "translate_textured_area_emitter": 1024,
    "translate_plane_under_textured_area_emitter": 2048,
    "translate_textured_area_emitter_illuminating_plane": 1024,
}
SLOW = {"area_light_radiance", "rotate_shading_normals_plane",
        "translate_shadow_receiver_area_light", "translate_plane_and_area_emitter"}
SEED = 0


def _spp(name: str) -> int:
    scale = float(os.environ.get("EDGEPATH_CONFORMANCE_SPP_SCALE", "1"))
    return max(1, int(round(SPP[name] * scale)))


def _params():
    out = []
    for name in C.config_names():
        marks = [pytest.mark.slow] if name in SLOW else []
        out.append(pytest.param(name, id=name, marks=marks))
    return out


def _dump(name: str, image: torch.Tensor, ref: torch.Tensor) -> None:
    folder = os.environ.get("EDGEPATH_CONFORMANCE_OUT")
    if not folder:
        return
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    err = C.error_map(image, ref, C.PRIMAL_FLOOR).to(torch.float32)
    for suffix, img in (("ours", image), ("ref", ref), ("err", err)):
        ep.imwrite(img, out / f"{name}_primal_{suffix}.exr")
        ep.imwrite(img, out / f"{name}_primal_{suffix}.png")


def test_every_config_has_a_sample_count():
    assert set(C.config_names()) <= set(SPP), "add the new configs to SPP"


@pytest.mark.parametrize("name", _params())
def test_primal_matches_mitsuba(name):
    if name not in SPP:
        pytest.skip("no sample count chosen for this config yet")
    thresholds = C.thresholds(name)
    spp = _spp(name)
    scene, param = C.build(name, 0.0)
    ref = C.load_ref(name, "primal")

    start = time.perf_counter()
    image = ep.render(scene, spp=spp, max_bounces=param.max_bounces, seed=SEED)
    seconds = time.perf_counter() - start
    _dump(name, image, ref)

    assert image.shape == ref.shape
    assert torch.isfinite(image).all()
    mean_err, max_err = C.image_error(image, ref, C.PRIMAL_FLOOR)
    report = (f"{name}: spp {spp}, {seconds:.2f} s: mean err {mean_err:.4f} "
              f"(threshold {thresholds['error_mean']}), max err {max_err:.4f} "
              f"(threshold {thresholds['error_max']})")
    if name in C.SCENE_CORRECTIONS:
        report += " [scene corrected: " + C.SCENE_CORRECTIONS[name]["reason"][:60] + "...]"
    print(report)
    assert mean_err <= thresholds["error_mean"], report
    assert max_err <= thresholds["error_max"], report


@pytest.mark.parametrize("name", _params())
def test_theta_moves_only_the_described_tensors(name):
    """build(name, theta) changes exactly the tensors its Parameter names, as configs.json
    says theta enters; finite differences and gradients rely on it."""
    eps = 1e-2
    base, param = C.build(name, 0.0)
    moved, moved_param = C.build(name, eps)
    assert param.tensors, f"{name}: theta enters no tensor"
    assert set(param.tensors) == set(moved_param.tensors)

    def fields(scene):
        out = {"camera.to_world": scene.camera.to_world}
        if scene.envmap is not None:
            out["envmap.values"] = scene.envmap.values
        for i, m in enumerate(scene.meshes):
            out[f"meshes[{i}].vertices"] = m.vertices
            out[f"meshes[{i}].normals"] = m.normals
            out[f"meshes[{i}].emission"] = m.emission
            out[f"meshes[{i}].material.diffuse"] = m.material.diffuse
        return out

    before, after = fields(base), fields(moved)
    for key, a in before.items():
        b = after[key]
        if key not in param.tensors:
            assert (a is None and b is None) or torch.equal(a, b), f"{name}: {key} moved"
            continue
        assert a is param.tensors[key]
        delta = (b.double() - a.double())
        if param.kind in ("albedo_offset", "emission_offset", "envmap_offset"):
            assert torch.allclose(delta, torch.full_like(delta, eps), atol=1e-6)
        elif param.kind == "translate":
            expected = torch.tensor(param.direction, dtype=torch.float64) * eps
            assert torch.allclose(delta, expected.expand_as(delta), atol=1e-6)
        elif param.kind == "scale":
            assert torch.allclose(delta, a.double() * eps, atol=1e-6)
        elif param.kind == "rotate_normals":
            # (0, 0, 1) tilts towards +x by eps degrees about +y.
            angle = torch.deg2rad(torch.tensor(eps, dtype=torch.float64))
            expected = torch.stack([torch.sin(angle), torch.zeros((), dtype=torch.float64),
                                    torch.cos(angle)])
            assert torch.allclose(b.double(), expected.expand_as(b), atol=1e-6)
        elif param.kind == "camera_translate":
            expected = a.double()[:3, 0] * eps  # along camera-local +x
            assert torch.allclose(delta[:3, 3], expected, atol=1e-6)
            assert torch.equal(delta[:, :3], torch.zeros(4, 3, dtype=torch.float64))
        else:
            raise AssertionError(f"{name}: unknown parameter kind {param.kind}")

    theta = torch.zeros((), requires_grad=True)
    _, grad_param = C.build(name, theta)
    for key, t in grad_param.tensors.items():
        assert t.requires_grad, f"{name}: {key} is not differentiable in theta"
