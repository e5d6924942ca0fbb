"""The tutorial (docs/tutorial.md) runs as written: its ```python blocks are executed in order
in one namespace, in a temporary directory (it writes images), and what they compute is
checked: the files exist, the optimisations recovered their parameters, and the derivative
image agrees with finite differences and with the closed form the page derives."""

import re
from pathlib import Path

import pytest
import torch

TUTORIAL = Path(__file__).resolve().parents[2] / "docs" / "tutorial.md"
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def tutorial_blocks():
    return BLOCK.findall(TUTORIAL.read_text())


def test_tutorial_has_code():
    assert len(tutorial_blocks()) >= 8


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory):
    """The namespace left by running every block of the tutorial."""
    directory = tmp_path_factory.mktemp("tutorial")
    namespace = {"__name__": "tutorial"}
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(directory)
        for i, code in enumerate(tutorial_blocks()):
            exec(compile(code, f"{TUTORIAL.name}, block {i + 1}", "exec"), namespace)
    namespace["directory"] = directory
    return namespace


def test_first_render_and_files(tutorial):
    assert (tutorial["directory"] / "first.png").stat().st_size > 0
    assert (tutorial["directory"] / "first.exr").stat().st_size > 0
    target = tutorial["target"]  # the last render of the page: the triangle's target
    assert target.shape == (32, 32, 3) and target.dtype == torch.float32


def test_lamp_gradient_is_positive(tutorial):
    grad = tutorial["lamp"].emission.grad
    assert grad is not None and grad.shape == (3,)
    assert (grad > 0).all()


def test_colour_recovered(tutorial):
    colour = tutorial["colour"].detach()
    truth = torch.tensor([0.2, 0.4, 0.8])
    start = torch.tensor([0.5, 0.5, 0.5])
    error = float((colour - truth).norm())
    assert error < 0.25 * float((start - truth).norm()), f"colour {colour.tolist()}"


def test_vertex_recovered(tutorial):
    tip, true_tip = tutorial["tip"].detach(), tutorial["true_tip"]
    start = torch.tensor([0.4, 0.6])
    error = float((tip - true_tip).norm())
    assert error < 0.1 * float((start - true_tip).norm()), f"tip {tip.tolist()}"


def test_derivative_image_matches_finite_differences_and_closed_form(tutorial):
    d, fd, interior = tutorial["d"], tutorial["fd"], tutorial["interior"]
    assert float(interior.abs().sum()) == 0.0
    assert float(d.sum()) == pytest.approx(float(fd.sum()), rel=0.05)
    # Closed form of the page: the projected area grows by 0.8 square units times
    # (W / (2 * 4 * tan(22.5 deg)))^2 pixels per square unit; each such pixel changes by 1.5 - 3.
    pixels_per_unit = 32 / (2 * 4.0 * torch.tan(torch.deg2rad(torch.tensor(22.5, dtype=torch.float64))))
    expected = 0.8 * float(pixels_per_unit) ** 2 * (1.5 - 3.0)
    assert float(d.sum()) == pytest.approx(expected, rel=0.03)


def test_options_block_renders(tutorial):
    image = tutorial["image"]  # the options block renders the triangle scene last
    assert image.shape == (32, 32, 3) and torch.isfinite(image).all()
