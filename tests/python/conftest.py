"""``--seed-shift N``: every seed the Python API hands the core is moved by N (mod 2^64), so that
the statistical tests run on other random numbers. A test that then fails passed because of its
seed, not because its bound holds: measure its statistic over several seeds and give it the
samples its bound needs (docs/installation.md). Without the option nothing changes."""

import sys


def pytest_addoption(parser):
    parser.addoption("--seed-shift", type=int, default=0,
                     help="add this to every seed passed to the renderer (tests' statistical robustness)")


def pytest_configure(config):
    shift = config.getoption("--seed-shift")
    if not shift:
        return
    import edgepath  # noqa: F401  (the module below is loaded with the package)
    render = sys.modules["edgepath.render"]
    core = render.RenderOptions.core

    def shifted(self):
        out = core(self)
        out["seed"] = (out["seed"] + shift) % 2 ** 64
        if "view_seeds" in out:
            out["view_seeds"] = [(s + shift) % 2 ** 64 for s in out["view_seeds"]]
        return out
    render.RenderOptions.core = shifted
