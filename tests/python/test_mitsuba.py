"""ep.load_mitsuba: the conformance scenes as Mitsuba XML files (tests/python/scenes) give the
same scenes as conformance.build, and what lies outside the supported subset raises an error
naming the element and its line."""

import math
import warnings
from pathlib import Path

import pytest
import torch

import conformance
import edgepath as ep
from edgepath.render import flatten_scene

SCENES = Path(__file__).resolve().parent / "scenes"

needs_data = pytest.mark.skipif(not conformance.data_available(),
                                reason=conformance.missing_data_reason())


def _assert_same(a, b, where="flat"):
    """Same structure, equal numbers and tensors (within 1e-6) of two flattened scenes."""
    if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
        assert isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor), where
        assert tuple(a.shape) == tuple(b.shape), f"{where}: {tuple(a.shape)} != {tuple(b.shape)}"
        if a.dtype.is_floating_point:
            assert torch.allclose(a.double(), b.double(), rtol=0, atol=1e-6), \
                f"{where}: max diff {float((a.double() - b.double()).abs().max())}"
        else:
            assert torch.equal(a, b), where
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), f"{where}: {a.keys()} != {b.keys()}"
        for k in a:
            _assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert a == pytest.approx(b, abs=1e-6), f"{where}: {a} != {b}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _flat(scene):
    f = flatten_scene(scene)
    return {"camera": f.camera, "materials": f.materials, "meshes": f.meshes, "envmap": f.envmap,
            "size": (f.height, f.width),
            "params": {str(k): v.detach() for k, v in f.params.items()}}


def _load(name, **params):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # clamped bitmaps load as repeat (identical here)
        return ep.load_mitsuba(SCENES / f"{name}.xml", data=conformance.DATA_DIR, **params)


@needs_data
@pytest.mark.parametrize("name", conformance.config_names())
def test_conformance_scene_files_match_hand_built(name):
    loaded = _load(name)
    built, param = conformance.build(name)
    _assert_same(_flat(loaded.scene), _flat(built))
    assert loaded.max_bounces == param.max_bounces
    assert loaded.spp == 64
    ids = [s["id"] for s in conformance.config(name)["scene"]["shapes"]
           if s["id"] not in conformance.SCENE_CORRECTIONS.get(name, {}).get("drop_shapes", ())]
    assert loaded.shape_ids == ids
    # Same images (at most 128 x 128 here), 1 spp, a fixed seed.
    small = {"spp": 1, "max_bounces": param.max_bounces, "seed": 7}
    a = ep.render(loaded.scene, **small)
    b = ep.render(built, **small)
    assert torch.equal(a, b)
    assert float(a.abs().sum()) > 0
