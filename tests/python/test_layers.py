"""The folders of src/ are layers (docs/architecture.md): a file of the core includes only
headers of its own folder and of the folders below it. LAYERS is the one table of them; the
test reads every quoted #include of src/ and fails on one that climbs."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src"
ARCHITECTURE = ROOT / "docs" / "architecture.md"

# Lowest first: each folder may include itself and those before it. The files directly in src/
# (edgepath.h, the public API) sit above them all: PUBLIC.
LAYERS = ["math", "sampling", "scene", "render", "edges", "diff", "io"]
PUBLIC = "public API"

INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.M)


def layer_of(path: Path, src: Path) -> str:
    """The layer of a file of src/: its top folder, or PUBLIC for the files directly in src/."""
    parts = path.relative_to(src).parts
    return parts[0] if len(parts) > 1 else PUBLIC


def rank(layer: str, layers) -> int:
    return len(layers) if layer == PUBLIC else layers.index(layer)


def violations(src: Path, layers=LAYERS):
    """One line per include that climbs a layer, names no file of src/, or comes from a folder
    the table does not know."""
    found = []
    for path in sorted(src.rglob("*")):
        if path.suffix not in (".h", ".cpp"):
            continue
        name = path.relative_to(src).as_posix()
        layer = layer_of(path, src)
        if layer != PUBLIC and layer not in layers:
            found.append(f"{name}: folder '{layer}' is not in the layer table")
            continue
        text = path.read_text()
        for match in INCLUDE.finditer(text):
            target = match.group(1)
            line = text.count("\n", 0, match.start()) + 1
            if not (src / target).is_file():
                found.append(f'{name}:{line}: #include "{target}" names no file of src/')
                continue
            to = layer_of(src / target, src)
            if to != PUBLIC and to not in layers:
                found.append(f'{name}:{line}: #include "{target}": folder \'{to}\' is not in the layer table')
            elif rank(to, layers) > rank(layer, layers):
                found.append(f'{name}:{line}: #include "{target}" climbs from {layer} up to {to}')
    return found


def test_includes_follow_the_layers():
    assert SRC.is_dir()
    problems = violations(SRC)
    assert not problems, "includes that break the layering:\n" + "\n".join(problems)


def test_every_folder_is_a_layer():
    folders = sorted(p.name for p in SRC.iterdir() if p.is_dir())
    assert folders == sorted(LAYERS)


def test_architecture_page_lists_the_layers_in_order():
    # The page's tree of src/: one folder per line, indented by two spaces.
    assert re.findall(r"^  (\w+)/ ", ARCHITECTURE.read_text(), re.M) == LAYERS


def test_check_reports_climbs_unknown_folders_and_missing_files(tmp_path):
    files = {
        "math/vec.h": "",
        "scene/scene.h": '#include "math/vec.h"\n#include "scene/bsdf.h"\n',
        "scene/bsdf.h": "#include <vector>\n",
        "render/path.h": '#include "scene/scene.h"\n',
        "edgepath.h": '#include "render/path.h"\n',
        # the violations
        "scene/camera.h": '#include "math/vec.h"\n  #  include "render/path.h"\n',
        "math/frame.h": '#include "edgepath.h"\n',
        "render/tiles.h": '#include "render/missing.h"\n',
        "extra/thing.cpp": '#include "math/vec.h"\n',
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert violations(tmp_path, ["math", "scene", "render"]) == [
        "extra/thing.cpp: folder 'extra' is not in the layer table",
        'math/frame.h:1: #include "edgepath.h" climbs from math up to public API',
        'render/tiles.h:1: #include "render/missing.h" names no file of src/',
        'scene/camera.h:2: #include "render/path.h" climbs from scene up to render',
    ]
