"""The inverse-rendering demo (``edgepath demo``), reduced: a few iterations on a small film."""

import io
import sys

import pytest

import edgepath.demo as demo_module
from edgepath.cli import main
from edgepath.demo import START, TRUTH, parameter_errors, run_demo

FILES = ["target.png", "start.png", "result.png", "optimisation.gif", "convergence.png"]


def test_demo_reduced_converges_and_writes_its_files(tmp_path):
    result = run_demo(iterations=40, size=32, spp=2, lr=3.0, output_dir=str(tmp_path), progress=False,
                      log=lambda line: None)
    losses, errors = result.history["loss"], result.history["relative_error"]
    assert len(losses) == 40 and errors[0] == pytest.approx(1.0)
    # The loss falls by a large factor, and every parameter group gets closer to the truth.
    assert sum(losses[-5:]) / 5 < 0.2 * sum(losses[:5]) / 5
    assert errors[-1] < 0.5
    start_errors = parameter_errors(START)
    for group, error in result.errors.items():
        assert error < start_errors[group], group
    assert parameter_errors(TRUTH) == {g: 0.0 for g in start_errors}
    for name in FILES:
        assert (tmp_path / name).stat().st_size > 0, name
    assert result.files == [str(tmp_path / name) for name in FILES]


def test_demo_images_and_gif(tmp_path):
    from PIL import Image
    import edgepath as ep
    run_demo(iterations=6, size=24, spp=1, output_dir=str(tmp_path), progress=False, frames=3,
             log=lambda line: None)
    for name in ["target.png", "start.png", "result.png"]:
        assert ep.imread(tmp_path / name).shape == (24, 24, 3)
    with Image.open(tmp_path / "optimisation.gif") as gif:
        assert gif.size == (48, 24)  # target | estimate
        assert gif.n_frames == 4     # every other step of 6, and the last


def test_demo_command_line(tmp_path, capsys):
    assert main(["demo", "--output-dir", str(tmp_path), "--iterations", "3", "--size", "16",
                 "--spp", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "truth:" in out and "result:" in out
    for name in FILES:
        assert (tmp_path / name).is_file(), name
    assert main(["demo", "--output-dir", str(tmp_path / "off"), "--iterations", "1", "--size", "16",
                 "--spp", "1", "--quiet", "--no-secondary-edges"]) == 0


@pytest.mark.parametrize("kwargs, field", [({"iterations": 0}, "iterations"), ({"size": 4}, "size"),
                                            ({"spp": 0}, "spp")])
def test_demo_bad_options(kwargs, field):
    with pytest.raises(ValueError, match=field):
        run_demo(output_dir=None, progress=False, log=lambda line: None, **kwargs)


def test_demo_needs_the_secondary_edges():
    """The lamp's position reaches the image only through visibility (where the lamp's outline
    and the box's shadow fall, seen from the floor and the box): without the secondary-edge
    term the lamp gets no gradient at all and the optimisation goes astray."""
    options = dict(iterations=40, size=32, spp=2, lr=3.0, output_dir=None, progress=False,
                   log=lambda line: None)
    with_edges = run_demo(**options)
    without = run_demo(secondary_edges=False, **options)
    start_light = parameter_errors(START)["light"]
    assert without.errors["light"] == pytest.approx(start_light, abs=1e-6)
    assert with_edges.errors["light"] < 0.3 * start_light
    assert without.history["relative_error"][-1] > 3 * with_edges.history["relative_error"][-1]


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_bar_line_is_finished_when_the_loop_is_interrupted(monkeypatch):
    """Ctrl-C in the second step on a terminal: the bar's line (redrawn in place) still ends in
    a newline, so the command line's 'interrupted' starts a line of its own."""
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    calls, render = [], demo_module.render

    def render_then_interrupt(*args, **kwargs):  # the target, the floor, then the steps
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return render(*args, **kwargs)

    monkeypatch.setattr(demo_module, "render", render_then_interrupt, raising=True)
    with pytest.raises(KeyboardInterrupt):
        run_demo(iterations=3, size=16, spp=1, output_dir=None, progress=True,
                 log=lambda line: None)
    assert " 1/3 " in terminal.getvalue() and terminal.getvalue().endswith("\n")
