"""Every code block of README.md and docs/*.md runs, as written: a page's ```python blocks in
order in one namespace, its ```sh blocks with bash, its ```xml scene files with
ep.load_mitsuba, all in a scratch folder that holds the files the pages name (scene.xml, the
example of docs/scene-files.md, with its meshes/bunny.obj; mesh.obj). A block that cannot run
here (C++ declarations, a formula, a full build) says so in a visible line just above it,
"*Not run as a test: REASON.*"; any other block fails this test. docs/tutorial.md's blocks
run in test_docs_tutorial.py, which also checks what they compute, and docs/cpp-api.md's
example program in the ctest cmake_package_consumer."""

import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import edgepath as ep
from edgepath import shapes

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
RUN_ELSEWHERE = {"tutorial.md": "test_docs_tutorial.py"}
# The ctest cmake_package_consumer builds and runs docs/cpp-api.md's example program, which
# tests/cmake_package/run.cmake finds by how it starts.
CPP_RUNNER = ROOT / "tests" / "cmake_package" / "run.cmake"
CPP_EXAMPLE = "// Renders an emissive triangle"
FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", re.S | re.M)
MARKER = re.compile(r"\*Not run as a test: .{8,}\*\s*$", re.S)


def blocks(page):
    """(language, code, line, reason or None) of each fenced block of a page."""
    text = page.read_text()
    out = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip("\n")
        paragraph = before[before.rfind("\n\n") + 2:] if "\n\n" in before else before
        marked = MARKER.fullmatch(paragraph.strip()) is not None
        line = text.count("\n", 0, m.start()) + 1
        out.append((m.group(1).strip(), m.group(2), line, paragraph.strip() if marked else None))
    return out


def runnable(page, language):
    return [(code, line) for lang, code, line, reason in blocks(page)
            if lang == language and reason is None]


def page_id(page):
    return page.relative_to(ROOT).as_posix()


def test_every_block_runs_or_says_why():
    unrunnable = []
    for page in PAGES:
        for language, code, line, reason in blocks(page):
            built = language == "cpp" and code.startswith(CPP_EXAMPLE)
            if reason is None and language not in ("python", "sh", "xml") and not built:
                unrunnable.append(f"{page_id(page)}:{line} ({language or 'no language'})")
    assert not unrunnable, ("blocks neither run by this test nor marked '*Not run as a test: "
                            f"REASON.*': {unrunnable}")
    assert f"```cpp\\n{CPP_EXAMPLE}" in CPP_RUNNER.read_text()
    counts = {page_id(p): len(blocks(p)) for p in PAGES}
    assert counts["README.md"] >= 4 and counts["docs/python-api.md"] >= 10


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A folder with the files the pages' examples name."""
    directory = tmp_path_factory.mktemp("docs")
    xml = [code for lang, code, _, _ in blocks(ROOT / "docs" / "scene-files.md") if lang == "xml"]
    (directory / "scene.xml").write_text(xml[0])
    (directory / "meshes").mkdir()
    v, i, _, _ = shapes.sphere(radius=0.4, rings=12, segments=24)
    ep.save_obj(ep.Mesh(v, i), directory / "meshes" / "bunny.obj", materials=False)
    v, i = shapes.box(half=(0.5, 0.5, 0.5))
    ep.save_obj(ep.Mesh(v, i), directory / "mesh.obj", materials=False)
    return directory


PYTHON_PAGES = [p for p in PAGES if runnable(p, "python") and p.name not in RUN_ELSEWHERE]
SHELL_PAGES = [p for p in PAGES if runnable(p, "sh")]
XML_PAGES = [p for p in PAGES if runnable(p, "xml")]


@pytest.mark.parametrize("page", PYTHON_PAGES, ids=page_id)
def test_python_blocks_run(page, workdir, monkeypatch):
    monkeypatch.chdir(workdir)
    namespace = {"__name__": "__docs__"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # approximations the scene file loads with
        for code, line in runnable(page, "python"):
            exec(compile(code, f"{page_id(page)}, block at line {line}", "exec"), namespace)


@pytest.mark.slow
@pytest.mark.parametrize("page", SHELL_PAGES, ids=page_id)
def test_shell_blocks_run(page, workdir):
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ["PATH"])
    for code, line in runnable(page, "sh"):
        done = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", code], cwd=workdir, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, (f"{page_id(page)}, block at line {line}:\n{code}\n"
                                      f"{done.stdout}\n{done.stderr}")


@pytest.mark.parametrize("page", XML_PAGES, ids=page_id)
def test_scene_file_blocks_load(page, workdir, tmp_path):
    for k, (code, line) in enumerate(runnable(page, "xml")):
        path = workdir / f"block_{k}.xml"
        path.write_text(code)
        loaded = ep.load_mitsuba(path)
        assert loaded.scene.meshes, f"{page_id(page)}, block at line {line}"


def test_pages_left_to_another_test_run_there():
    for page, test in RUN_ELSEWHERE.items():
        assert (Path(__file__).parent / test).read_text().count(page) >= 1
