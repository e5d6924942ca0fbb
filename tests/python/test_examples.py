"""The scripts in examples/, each run in a reduced form (few iterations, small images) as its
own process, as a user runs it (`python examples/NAME.py`): an import the package forgets
cannot be hidden by a module an earlier test imported."""

import json
import pathlib
import subprocess
import sys

import pytest

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples"


def run(name, tmp_path, *options):
    """Runs examples/NAME.py in tmp_path (its working directory too); returns its figures."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    metrics = tmp_path / "metrics.json"
    done = subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py"), "--output-dir", str(tmp_path),
                           "--quiet", "--metrics", str(metrics), *options],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{name}.py failed:\n{done.stdout}\n{done.stderr}"
    return json.loads(metrics.read_text())


def fell(values, factor=1.0, n=3):
    """The mean of the last n values is below ``factor`` times the mean of the first n."""
    return sum(values[-n:]) / n < factor * sum(values[:n]) / n


def test_single_triangle(tmp_path):
    r = run("single_triangle", tmp_path, "--iterations", "30", "--size", "24", "--spp", "2")
    assert fell(r["loss"], 0.5)
    assert r["error"][-1] < 0.5 * r["error"][0]
    assert (tmp_path / "result.png").is_file() and (tmp_path / "loss.png").is_file()


def test_pose_estimation(tmp_path):
    r = run("pose_estimation", tmp_path, "--iterations", "25", "--size", "32", "--spp", "2")
    assert fell(r["loss"], 0.7)
    assert r["rotation_error"][-1] < r["rotation_error"][0]
    assert r["translation_error"][-1] < r["translation_error"][0]
    assert (tmp_path / "comparison.png").is_file()


def test_shape_optimisation(tmp_path):
    r = run("shape_optimisation", tmp_path, "--iterations", "15", "--size", "24", "--spp", "8")
    assert fell(r["image_loss"], 0.9)
    assert r["surface_distance"][-1] < r["surface_distance"][0]
    assert (tmp_path / "result.png").is_file()
    # One kept scene: its two BVHs (the gradient passes' exact one, the plain renders' fast one)
    # each built once, then refitted as the vertices move, however many steps.
    assert r["build_counts"]["builds"] == 2
    assert r["build_counts"]["refits"] > 0


def test_shadow_occluder(tmp_path):
    r = run("shadow_occluder", tmp_path, "--iterations", "30", "--size", "24", "--spp", "2")
    assert fell(r["loss"], 0.7)
    assert r["error"][-1] < 0.7 * r["error"][0]
    # The plate is out of view: without the shadow-edge term its gradient is exactly zero.
    off = run("shadow_occluder", tmp_path / "off", "--iterations", "3", "--size", "16",
              "--spp", "1", "--no-secondary-edges")
    assert off["error"][-1] == off["error"][0]


def test_material_envmap(tmp_path):
    r = run("material_envmap", tmp_path, "--iterations", "15", "--size", "24", "--spp", "4")
    assert fell(r["loss"], 0.7)
    assert r["material_error"][-1] < r["material_error"][0]
    assert (tmp_path / "envmap_true_vs_recovered.png").is_file()
    # Material and map steps on one kept scene: each of its two BVHs built once, never again.
    assert r["build_counts"]["builds"] == 2 and r["build_counts"]["refits"] == 0


def test_texture_recovery(tmp_path):
    # At 4 spp the loss is mostly the renders' noise (0.0112-0.0129 at the start, within 3% of
    # that after 15 steps, up or down by the seed, while the texel error falls from 0.317 to
    # 0.18); at 16 spp it falls from 0.0044-0.0050 to 0.0025-0.0027.
    r = run("texture_recovery", tmp_path, "--iterations", "15", "--size", "24", "--spp", "16")
    assert fell(r["loss"], 0.9)
    assert r["texel_error"][-1] < r["texel_error"][0]
    assert (tmp_path / "texture_true_vs_recovered.png").is_file()
    assert r["build_counts"]["builds"] == 2 and r["build_counts"]["refits"] == 0


def test_adversarial(tmp_path):
    r = run("adversarial", tmp_path, "--train-per-class", "20", "--epochs", "10",
            "--iterations", "15", "--size", "24", "--spp", "4")
    target, final = r["target"], r["final"]
    raised = final[target] > r["initial"][target]
    assert raised or max(range(len(final)), key=final.__getitem__) == target
    assert len(r["probabilities"]["sphere"]) == 15
    assert (tmp_path / "probabilities.png").is_file()


def test_multiview_distributed_matches_one_process(tmp_path):
    """Two ranks (spawned processes, gloo), each rendering half the views, all-reduce the same
    gradient one process gets from every view (to float rounding: other summation order)."""
    import torch
    options = ("--iterations", "1", "--size", "16", "--spp", "2", "--views", "4")
    two = run("multiview_distributed", tmp_path / "two", *options, "--ranks", "2")
    one = run("multiview_distributed", tmp_path / "one", *options, "--ranks", "1")
    g2, g1 = torch.tensor(two["first_gradient"]), torch.tensor(one["first_gradient"])
    scale = float(g1.abs().max())
    assert scale > 0
    torch.testing.assert_close(g2, g1, rtol=1e-4, atol=1e-5 * scale)
    assert abs(two["loss"][0] - one["loss"][0]) <= 1e-6 * one["loss"][0]
    assert (tmp_path / "two" / "result.png").is_file()


def test_bunny_pose(tmp_path):
    bunny = EXAMPLES.parents[1] / "shared" / "data" / "bunny.ply"
    if not bunny.exists():
        pytest.skip(f"test data not found: {bunny}")
    # 16 steps: the shift error falls from 10.1% to 4.4%. At 12 it reached 6.1% or 7.3% depending
    # on which random samples the edge passes drew, too near the 30% fall asserted.
    r = run("bunny_pose", tmp_path, "--iterations", "16", "--size", "24", "--spp", "2", "--mesh", str(bunny))
    assert fell(r["loss"], 0.8)
    assert r["shift_error"][-1] < 0.7 * r["shift_error"][0]
    assert (tmp_path / "comparison.png").is_file()
