"""The command line (edgepath.cli): render, derivative and info on tiny scenes, run through
main(argv) (and once as a process)."""

import io
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import torch

import edgepath as ep
import edgepath.shapes  # ep.shapes
from edgepath import cli

SCENE = """<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="albedo" value="0.2, 0.5, 0.8"/>
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/>
            <rfilter type="box"/></film>
    </sensor>
    <shape type="rectangle" id="floor">
        <bsdf type="diffuse" id="paint"><rgb name="reflectance" value="$albedo"/></bsdf>
    </shape>
    <shape type="rectangle" id="card">
        <transform name="to_world"><scale value="0.4"/><translate z="1"/></transform>
    </shape>
    <shape type="rectangle" id="lamp">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="3" z="1"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 10, 10"/></emitter>
    </shape>
</scene>
"""


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "tiny.xml"
    path.write_text(SCENE)
    return path


def _run(argv, capsys):
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exit:  # argparse refused an argument (status 2)
        code = exit.code
    out, err = capsys.readouterr()
    return code, out, err


def test_render_xml_matches_render(scene_file, tmp_path, capsys):
    out = tmp_path / "out" / "image.exr"
    code, text, err = _run(["render", scene_file, "-o", out], capsys)
    assert code == 0, err
    assert "16x12 at 4 spp, max_bounces 2" in text
    loaded = ep.load_mitsuba(scene_file)
    expected = ep.render(loaded.scene, spp=4, max_bounces=2, seed=0)
    assert torch.equal(ep.imread(out), expected)
    assert float(expected.sum()) > 0


def test_render_in_chunks_with_progress_and_overrides(scene_file, tmp_path, capsys):
    out = tmp_path / "chunks.exr"
    code, text, err = _run(["render", scene_file, "-o", out, "--spp", "6", "--chunk-spp", "4",
                            "--max-bounces", "1", "--seed", "5", "-D", "albedo=0.9, 0.1, 0.1"],
                           capsys)
    assert code == 0, err
    assert "4/6 spp" in err and "6/6 spp" in err  # progress on stderr
    loaded = ep.load_mitsuba(scene_file, albedo="0.9, 0.1, 0.1")
    a = ep.render(loaded.scene, spp=4, max_bounces=1, seed=5)
    b = ep.render(loaded.scene, spp=2, max_bounces=1, seed=6)
    assert torch.allclose(ep.imread(out), (4 * a + 2 * b) / 6, atol=1e-6)
    # -D changed the image: the floor is reddish now
    default = ep.render(ep.load_mitsuba(scene_file).scene, spp=4, max_bounces=1, seed=5)
    assert not torch.allclose(a, default)


def test_render_resolution_and_unknown_parameter(scene_file, tmp_path, capsys):
    out = tmp_path / "small.exr"
    code, _, err = _run(["render", scene_file, "-o", out, "--resolution", "6", "8"], capsys)
    assert code == 0, err
    assert ep.imread(out).shape == (6, 8, 3)
    code, _, err = _run(["render", scene_file, "-o", out, "-D", "albdeo=0.5"], capsys)
    assert code == 1 and "albdeo" in err and "unknown to the file" in err


def test_render_obj_still_works(tmp_path, capsys):
    v, f = ep.shapes.quad([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    ep.save_obj(ep.Mesh(vertices=v, indices=f), tmp_path / "quad.obj")
    out = tmp_path / "quad.png"
    code, text, err = _run(["render", tmp_path / "quad.obj", "-o", out, "--resolution", "8", "10",
                            "--spp", "2"], capsys)
    assert code == 0, err
    assert ep.imread(out).shape == (8, 10, 3)
    code, _, err = _run(["render", tmp_path / "quad.obj", "-D", "x=1"], capsys)
    assert code == 1 and "-D" in err
    code, text, err = _run(["info", tmp_path / "quad.obj"], capsys)
    assert code == 0, err
    assert "meshes: 1, triangles: 2, vertices: 4" in text and "environment: constant" in text
    assert "  mesh_0.vertex_positions  (4, 3)" in text


def test_derivative_writes_exr_and_png(scene_file, tmp_path, capsys):
    out = tmp_path / "d.exr"
    code, text, err = _run(["derivative", scene_file, "--param", "card.vertex_positions",
                            "--direction", "0.5", "0", "0", "-o", out, "--spp", "2"], capsys)
    assert code == 0, err
    loaded = ep.load_mitsuba(scene_file)
    card = loaded.shapes["card"].vertices
    expected = ep.derivative_image(loaded.scene, card, torch.tensor([0.5, 0.0, 0.0]).expand(4, 3),
                                   spp=2, max_bounces=2, seed=0)
    image = ep.imread(out)
    assert torch.equal(image, expected)
    assert float(image.abs().sum()) > 0  # the card's edges move
    png = ep.imread(tmp_path / "d.png")
    assert png.shape == (12, 16, 3)
    # where the derivative is zero the map is white
    zero = image.abs().sum(2) == 0
    assert bool(zero.any()) and torch.allclose(png[zero], torch.ones(3), atol=1e-6)
    assert "colour scale" in text


def test_derivative_of_scalars_and_colours(scene_file, tmp_path, capsys):
    for param, direction in (("sensor.x_fov", ["1"]), ("paint.reflectance.value", ["1", "0", "0"]),
                             ("lamp.emitter.radiance.value", ["1"]), ("sensor.position", ["0.1", "0", "0"])):
        code, _, err = _run(["derivative", scene_file, "--param", param, "--direction", *direction,
                             "-o", tmp_path / f"{param}.exr", "--spp", "1"], capsys)
        assert code == 0, (param, err)
        assert float(ep.imread(tmp_path / f"{param}.exr").abs().sum()) > 0, param
    code, _, err = _run(["derivative", scene_file, "--param", "paint.reflectance.value", "--direction", "1", "2",
                         "-o", tmp_path / "x.exr"], capsys)
    assert code == 1 and "expected 1 or 3 numbers, got 2" in err
    code, _, err = _run(["derivative", scene_file, "--param", "nope", "--direction", "1",
                         "-o", tmp_path / "x.exr"], capsys)
    assert code == 1 and "'nope': not in this scene" in err


def test_diverging_colours():
    values = torch.tensor([[-2.0, -1.0, 0.0, 1.0, 3.0]])
    c = cli.diverging_colours(values, 1.0)
    assert torch.allclose(c[0, 0], torch.tensor([0.0, 0.0, 1.0]))  # saturates at -scale
    assert torch.allclose(c[0, 1], torch.tensor([0.0, 0.0, 1.0]))
    assert torch.allclose(c[0, 2], torch.ones(3))
    assert torch.allclose(c[0, 3], torch.tensor([1.0, 0.0, 0.0]))
    half = cli.diverging_colours(torch.tensor([[0.5]]), 1.0)[0, 0]
    assert half[0] == 1 and 0 < half[1] == half[2] < 1
    assert cli.robust_scale(torch.tensor([0.0, 1.0, 2.0, 3.0, 100.0]), 50) == pytest.approx(2.5)


def test_info(scene_file, capsys):
    code, text, err = _run(["info", scene_file], capsys)
    assert code == 0, err
    assert "meshes: 3, triangles: 6, vertices: 12" in text
    assert "lights: 1 area, environment: none" in text
    assert "bounds: min (-1, -1, 0), max (1, 3, 2)" in text
    assert "camera: perspective, position (0, 0, 4)" in text and "fov 45 deg, 16x12" in text
    assert "render: spp 4, max_bounces 2, seed 0" in text
    for name in ("card.vertex_positions", "paint.reflectance.value", "lamp.emitter.radiance.value",
                 "sensor.position", "sensor.x_fov"):
        assert f"  {name}  " in text
    # The camera's matrix is one parameter; sensor.position is only a --direction of it.
    assert text.count("(4, 4)") == 1 and "sensor.position  (--direction only)" in text


def test_info_thin_lens(capsys):
    scene = Path(__file__).resolve().parent / "references" / "thinlens.xml"
    code, text, err = _run(["info", scene], capsys)
    assert code == 0, err
    assert ("camera: thinlens, position (0, 0, 5)" in text and
            "fov 40 deg, aperture_radius 0.3, focus_distance 5, 48x32" in text)
    for name in ("sensor.aperture_radius", "sensor.focus_distance"):
        assert f"  {name}  ()  1 number" in text


def test_errors_name_the_line(tmp_path, capsys):
    bad = tmp_path / "bad.xml"
    bad.write_text(SCENE.replace('<shape type="rectangle" id="card">', '<shape type="cylinder" id="card">'))
    code, _, err = _run(["info", bad], capsys)
    line = SCENE.splitlines().index('    <shape type="rectangle" id="card">') + 1
    assert code == 1 and f"bad.xml:{line}: <shape type=\"cylinder\" id=\"card\">" in err
    code, _, err = _run(["render", tmp_path / "missing.xml"], capsys)
    assert code == 1 and "not found" in err


def test_command_as_a_process(scene_file, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(Path(ep.__file__).resolve().parents[1]))
    result = subprocess.run([sys.executable, "-m", "edgepath", "info", str(scene_file)],
                            capture_output=True, text=True, env=env, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "triangles: 6" in result.stdout


def test_derivative_matches_finite_differences_of_a_linear_parameter(scene_file, tmp_path, capsys):
    # The image is linear in the floor's albedo (the floor is flat: no path meets it twice), so
    # a finite difference with the same random numbers is exact up to rounding.
    out = tmp_path / "albedo.exr"
    code, _, err = _run(["derivative", scene_file, "--param", "paint.reflectance.value", "--direction",
                         "1", "0", "0", "-o", out, "--spp", "4"], capsys)
    assert code == 0, err
    d = ep.imread(out)
    images = [ep.render(ep.load_mitsuba(scene_file, albedo=a).scene, spp=4, max_bounces=2, seed=0)
              for a in ("0.2, 0.5, 0.8", "0.3, 0.5, 0.8")]
    fd = (images[1] - images[0]) / 0.1
    assert float(d[..., 0].abs().max()) > 0.01
    assert torch.allclose(d, fd, atol=1e-4, rtol=1e-3)
    assert float(d[..., 1:].abs().max()) == 0.0


def test_render_writes_output_channels(scene_file, tmp_path, capsys):
    out = tmp_path / "image.png"
    code, text, err = _run(["render", scene_file, "-o", out, "--channels", "alpha,depth,triangle_id"], capsys)
    assert code == 0, err
    loaded = ep.load_mitsuba(scene_file)
    expected = ep.render_channels(loaded.scene, ["alpha", "depth", "triangle_id"], spp=4, max_bounces=2, seed=0)
    for name, values in expected.items():
        path = tmp_path / f"image.{name}.exr"
        assert str(path) in text
        written = ep.imread(path)
        assert written.shape[:2] == values.shape[:2]
        assert torch.equal(written[..., :1], values.to(torch.float32)[..., :1])
    assert float(expected["alpha"].sum()) > 0 and int((expected["triangle_id"] >= 0).sum()) > 0
    code, text, err = _run(["render", scene_file, "-o", out, "--channels", "alpha,colour"], capsys)
    assert code != 0 and "--channels" in err and "colour" in err


# ---- bad arguments and Ctrl-C ------------------------------------------------------------------

@pytest.fixture
def quad_obj(tmp_path):
    v, f = ep.shapes.quad([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    ep.save_obj(ep.Mesh(vertices=v, indices=f), tmp_path / "quad.obj")
    return tmp_path / "quad.obj"


@pytest.mark.parametrize("args,option", [
    (["--spp", "0"], "--spp"),
    (["--spp", "-3"], "--spp"),
    (["--spp", "lots"], "--spp"),
    (["--fov", "0"], "--fov"),
    (["--fov", "180"], "--fov"),
    (["--fov", "inf"], "--fov"),
    (["--resolution", "100000", "100000"], "--resolution"),
    (["--resolution", "60000", "60000"], "--resolution"),
    (["--resolution", "0", "8"], "--resolution"),
    (["--env", "nan"], "--env"),
    (["--env", "inf"], "--env"),
    (["--channels", ""], "--channels"),
    (["--channels", ","], "--channels"),
    (["--max-bounces", "-1"], "--max-bounces"),
    (["--threads", "0"], "--threads"),
    (["--chunk-spp", "0"], "--chunk-spp"),
    (["--seed", "-1"], "--seed"),
])
def test_bad_arguments_are_one_line_and_exit_2(quad_obj, tmp_path, capsys, args, option):
    with pytest.raises(SystemExit) as info:
        cli.main(["render", str(quad_obj), "-o", str(tmp_path / "out.png"), *args])
    _, err = capsys.readouterr()
    assert info.value.code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines[-1].startswith("edgepath render: error: argument") and option in lines[-1]
    assert not (tmp_path / "out.png").exists()


def test_bad_arguments_of_derivative_and_demo(scene_file, capsys):
    for argv in (["derivative", str(scene_file), "--param", "paint.reflectance", "--direction", "nan"],
                 ["derivative", str(scene_file), "--param", "paint.reflectance", "--direction", "1",
                  "--percentile", "0"],
                 ["demo", "--size", "0"], ["demo", "--iterations", "0"], ["demo", "--size", "100000"]):
        with pytest.raises(SystemExit) as info:
            cli.main(argv)
        _, err = capsys.readouterr()
        assert info.value.code == 2 and "Traceback" not in err and "error: argument" in err, argv


class _CutStderr(io.StringIO):
    """A stderr (terminal or not) where Ctrl-C lands in the first progress line: after its
    text, before its newline (a pipe) or before the next chunk's line (a terminal)."""

    def __init__(self, tty):
        super().__init__()
        self.tty, self.cut = tty, False

    def isatty(self):
        return self.tty

    def write(self, text):
        if not self.cut and " spp, " in self.getvalue() and (text == "\n" or self.tty):
            self.cut = True
            raise KeyboardInterrupt
        return super().write(text)


@pytest.mark.parametrize("tty", [False, True])
def test_interrupted_inside_the_progress_line_says_so_on_a_line_of_its_own(
        quad_obj, tmp_path, monkeypatch, tty):
    stderr = _CutStderr(tty)
    monkeypatch.setattr(sys, "stderr", stderr)
    code = cli.main(["render", str(quad_obj), "-o", str(tmp_path / "out.png"), "--resolution",
                     "4", "4", "--spp", "4", "--chunk-spp", "1", "--threads", "1"])
    assert code == 130
    lines = stderr.getvalue().replace("\r", "\n").strip().splitlines()
    assert lines[-1] == "edgepath: interrupted" and " spp, " in lines[-2], lines
    assert not (tmp_path / "out.png").exists()


def test_ctrl_c_exits_130_with_one_line(quad_obj, tmp_path):
    """SIGINT during a long render (many short chunks, so that it lands in Python code between
    core calls, or in a core call that returns within a chunk): 'edgepath: interrupted' on
    stderr soon after (the exit itself waits for the interpreter's teardown), exit status 130,
    no traceback, no image written."""
    env = dict(os.environ, PYTHONPATH=str(Path(ep.__file__).resolve().parents[1]))
    process = subprocess.Popen(
        [sys.executable, "-m", "edgepath", "render", str(quad_obj), "-o", str(tmp_path / "out.png"),
         "--resolution", "16", "16", "--spp", "10000000", "--chunk-spp", "1", "--threads", "1"],
        stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
        # SIGINT at its default: a shell's background job inherits it ignored (no KeyboardInterrupt)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines, said = [], {}

    def read_stderr():  # keeps the pipe drained; notes when the message comes
        for line in process.stderr:
            lines.append(line)
            if "interrupted" in line:
                said["at"] = time.monotonic()

    try:
        for _ in range(20):  # up to the first progress line: rendering has begun
            line = process.stderr.readline()
            if " spp, " in line or not line:
                break
        assert " spp, " in line, line
        reader = threading.Thread(target=read_stderr)
        reader.start()
        sent = time.monotonic()
        process.send_signal(signal.SIGINT)
        process.wait(timeout=60)
        reader.join(timeout=60)
    finally:
        process.kill()
        process.wait()
    err = "".join(lines)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert err.strip().splitlines()[-1] == "edgepath: interrupted"
    assert said["at"] - sent < 3.0
    assert not (tmp_path / "out.png").exists()
