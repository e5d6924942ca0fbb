"""The scripts in examples/, each run in a reduced form (few iterations, small images)."""

import importlib
import pathlib
import sys

import pytest

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def load():
    sys.path.insert(0, str(EXAMPLES))
    try:
        yield lambda name: importlib.import_module(name)
    finally:
        sys.path.remove(str(EXAMPLES))


def run(load, name, tmp_path, *options):
    return load(name).main(["--output-dir", str(tmp_path), "--quiet", *options])


def fell(values, factor=1.0, n=3):
    """The mean of the last n values is below ``factor`` times the mean of the first n."""
    return sum(values[-n:]) / n < factor * sum(values[:n]) / n


def test_single_triangle(load, tmp_path):
    r = run(load, "single_triangle", tmp_path, "--iterations", "30", "--size", "24", "--spp", "2")
    assert fell(r["loss"], 0.5)
    assert r["error"][-1] < 0.5 * r["error"][0]
    assert (tmp_path / "result.png").is_file() and (tmp_path / "loss.png").is_file()


def test_pose_estimation(load, tmp_path):
    r = run(load, "pose_estimation", tmp_path, "--iterations", "25", "--size", "32", "--spp", "2")
    assert fell(r["loss"], 0.7)
    assert r["rotation_error"][-1] < r["rotation_error"][0]
    assert r["translation_error"][-1] < r["translation_error"][0]
    assert (tmp_path / "comparison.png").is_file()


def test_shape_optimisation(load, tmp_path):
    r = run(load, "shape_optimisation", tmp_path, "--iterations", "15", "--size", "24", "--spp", "8")
    assert fell(r["image_loss"], 0.9)
    assert r["surface_distance"][-1] < r["surface_distance"][0]
    assert (tmp_path / "result.png").is_file()


def test_shadow_occluder(load, tmp_path):
    r = run(load, "shadow_occluder", tmp_path, "--iterations", "30", "--size", "24", "--spp", "2")
    assert fell(r["loss"], 0.7)
    assert r["error"][-1] < 0.7 * r["error"][0]
    # The plate is out of view: without the shadow-edge term its gradient is exactly zero.
    off = run(load, "shadow_occluder", tmp_path / "off", "--iterations", "3", "--size", "16",
              "--spp", "1", "--no-secondary-edges")
    assert off["error"][-1] == off["error"][0]


def test_material_envmap(load, tmp_path):
    r = run(load, "material_envmap", tmp_path, "--iterations", "15", "--size", "24", "--spp", "4")
    assert fell(r["loss"], 0.7)
    assert r["material_error"][-1] < r["material_error"][0]
    assert (tmp_path / "envmap_true_vs_recovered.png").is_file()


def test_texture_recovery(load, tmp_path):
    r = run(load, "texture_recovery", tmp_path, "--iterations", "15", "--size", "24", "--spp", "4")
    assert fell(r["loss"], 0.9)
    assert r["texel_error"][-1] < r["texel_error"][0]
    assert (tmp_path / "texture_true_vs_recovered.png").is_file()


def test_adversarial(load, tmp_path):
    r = run(load, "adversarial", tmp_path, "--train-per-class", "20", "--epochs", "10",
            "--iterations", "15", "--size", "24", "--spp", "4")
    target = r["target"]
    raised = float(r["final"][target]) > float(r["initial"][target])
    assert raised or int(r["final"].argmax()) == target
    assert len(r["probabilities"]["sphere"]) == 15
    assert (tmp_path / "probabilities.png").is_file()
