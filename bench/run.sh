#!/usr/bin/env bash
# Runs the benchmark (forward and backward passes), then the kept scene and many-views
# measurement (bench/persist.py), light sampling at equal time (bench/light_sampling.py), the
# backward-pass memory measurement, the secondary-edge samplers' equal-time comparison, the
# secondary term's roulette by class at equal time and, when the mitsuba package is installed
# (pip install -e '.[bench]'), the comparison with Mitsuba 3 (bench/mitsuba_compare.py).
#   bench/run.sh [path/to/edgepath_bench] [benchmark options...]
# Without a path, looks for the binary in the usual build folders. Options go to the binary
# (edgepath_bench --help lists them), e.g.  bench/run.sh --runs 9 --csv bench.csv
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

bin=""
if [[ $# -gt 0 && "$1" != -* ]]; then
    bin="$1"
    shift
else
    for candidate in "$root"/build/py/bench/edgepath_bench "$root"/build/dev/bench/edgepath_bench \
                     "$root"/build/*/bench/edgepath_bench "$root"/build/bench/edgepath_bench; do
        if [[ -x "$candidate" ]]; then
            bin="$candidate"
            break
        fi
    done
fi
if [[ -z "$bin" || ! -x "$bin" ]]; then
    echo "edgepath_bench not found${bin:+ at $bin}; build it first (make build, or cmake --build <dir> --target edgepath_bench)" >&2
    exit 1
fi
"$bin" "$@"
# The scene kept across calls and many views per call, through the Python API (needs the
# package installed: make setup; make bench puts the venv's python first on PATH).
if python -c "import edgepath" 2>/dev/null; then
    python "$root/bench/persist.py"
else
    echo "bench/persist.py skipped: the edgepath package is not importable (make setup)"
fi
# Light sampling at equal time: area against solid-angle sampling (a square lamp, a sphere
# light), as the relative noise per pixel each reaches in area sampling's time.
if python -c "import edgepath" 2>/dev/null; then
    python "$root/bench/light_sampling.py"
else
    echo "bench/light_sampling.py skipped: the edgepath package is not importable (make setup)"
fi
# Memory of a large backward pass, in a process of its own (peak RSS is per process).
"$bin" --backward-memory --size 1024 --spp 16
# Secondary edges: the edge hierarchy against uniform sampling at equal time (a minute or two).
"$bin" --secondary-only --size 32 --spp 8 --seeds 48
# The secondary term's roulette by class (RenderOptions::secondary_survival) against none, at
# equal time: variance of every gradient over seeds times the pass's CPU time (a minute or two).
"$bin" --survival-compare --secondary-survival 0.1 --size 64 --spp 4 --seeds 64 --bounces 1,3
# Side by side with Mitsuba 3, in the project's Python (make bench puts its venv first on PATH);
# without mitsuba it says so in one line.
python="$(command -v python || command -v python3)"
"$python" "$root/bench/mitsuba_compare.py"
