"""The fuzzer (tests/fuzz/fuzz.py): every input it ever found crashing, hanging or raising
unexpectedly (tests/python/fuzz_regressions/) must now load or fail cleanly, and a bounded
slice of fresh cases must show no abort, hang or unexpected exception. Both run the fuzzer in
a process of its own (it forks a child per case, which the test process must not do: its
thread pools are running)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FUZZ = ROOT / "tests" / "fuzz" / "fuzz.py"
REGRESSIONS = Path(__file__).resolve().parent / "fuzz_regressions"

sys.path.insert(0, str(FUZZ.parent))
import fuzz  # noqa: E402


def _check(outcome: str, detail: str, what: str) -> None:
    assert outcome in ("ok", "error"), f"{what}: {outcome}: {detail}"


@pytest.fixture(scope="module")
def replayed():
    result = subprocess.run([sys.executable, str(FUZZ), "--replay", str(REGRESSIONS)],
                            capture_output=True, text=True, timeout=600)
    outcomes = {}
    for line in result.stdout.splitlines():
        name, outcome, detail = line.split(": ", 2)
        outcomes[name] = (outcome, detail)
    assert outcomes, result.stderr
    return outcomes


@pytest.mark.parametrize("name", sorted(p.name for p in REGRESSIONS.iterdir()))
def test_regression_file(replayed, name):
    assert fuzz.kind_of(name) in fuzz.corpus.KINDS
    _check(*replayed[name], name)


@pytest.mark.slow
def test_fuzz_slice(tmp_path):
    """560 fresh cases (80 per loader), about a minute on two cores."""
    log = tmp_path / "log.jsonl"
    result = subprocess.run([sys.executable, str(FUZZ), "--cases", "560", "--seed", "20260101",
                             "--log", str(log), "-q"], capture_output=True, text=True, timeout=900)
    cases = [json.loads(line) for line in log.read_text().splitlines()]
    assert len(cases) == 560, result.stdout + result.stderr
    counts = {}
    for case in cases:
        counts[case["outcome"]] = counts.get(case["outcome"], 0) + 1
    assert counts.get("ok", 0) > 50 and counts.get("error", 0) > 50, counts  # both are exercised
    bad = [c for c in cases if c["outcome"] not in ("ok", "error")]
    for case in bad:
        _check(case["outcome"], case["detail"],
               f"case {case['case']} of seed {case['seed']} ({case['kind']}, "
               f"{'+'.join(case['mutations'])})")
