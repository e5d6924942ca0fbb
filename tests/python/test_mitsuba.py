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


@needs_data
def test_data_default_points_at_the_reference_data():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = ep.load_mitsuba(SCENES / "translate_textured_plane.xml")
    _assert_same(_flat(default.scene), _flat(_load("translate_textured_plane").scene))


# ---- small scenes written here ----------------------------------------------------------------

SENSOR = """
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="8"/>
            <rfilter type="box"/></film>
    </sensor>"""


def _write(tmp_path, body, sensor=SENSOR, name="scene.xml"):
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<scene version="3.0.0">{sensor}\n{body}\n</scene>\n')
    return path


def _line_of(path, text):
    for i, line in enumerate(Path(path).read_text().splitlines(), 1):
        if text in line:
            return i
    raise AssertionError(text)


UNSUPPORTED = [
    ('<shape type="cylinder"/>', "unsupported shape type 'cylinder'"),
    ('<emitter type="point"><point name="position" value="0, 1, 0"/></emitter>',
     "unsupported emitter type 'point'"),
    ('<shape type="rectangle"><bsdf type="dielectric"/></shape>', "unsupported bsdf type 'dielectric'"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/>'
     '</bsdf></shape>', "unsupported texture type 'checkerboard'"),
    ('<integrator type="volpath"/>', "unsupported integrator type 'volpath'"),
    ('<medium type="homogeneous"/>', "unsupported element"),
    ('<shape type="rectangle"><float name="radius" value="2"/></shape>',
     "property 'radius' of shape 'rectangle' is not supported"),
    ('<shape type="rectangle"><bsdf type="roughconductor"><float name="alpha_u" value="0.1"/>'
     '<float name="alpha_v" value="0.2"/></bsdf></shape>', "anisotropic roughness"),
    ('<shape type="rectangle"><bsdf type="roughconductor"><string name="material" value="Hg"/>'
     '</bsdf></shape>', "conductor material 'Hg' is not supported"),
    ('<shape type="rectangle"><bsdf type="roughplastic"><boolean name="nonlinear" value="true"/>'
     '</bsdf></shape>', "nonlinear=true is not supported"),
    ('<shape type="rectangle"><bsdf type="twosided"><bsdf type="diffuse"/><bsdf type="diffuse"/>'
     '</bsdf></shape>', "twosided takes exactly one BSDF"),
    ('<shape type="rectangle"><transform name="to_world"><shear value="1"/></transform></shape>',
     "unsupported transform operation"),
    ('<shape type="rectangle"><emitter type="spot"/></shape>', "unsupported emitter type 'spot'"),
    ('<shape type="rectangle"><ref id="nowhere"/></shape>', "unknown id 'nowhere'"),
    ('<emitter type="constant"/>\n<emitter type="constant"><float name="radiance" value="2"/></emitter>',
     "only one environment emitter"),
    ('<shape type="rectangle"><spectrum name="x" value="400:1, 500:2"/></shape>',
     "property 'x' of shape 'rectangle' is not supported"),
    ('<shape type="rectangle"><emitter type="area"><spectrum name="radiance" value="400:1"/>'
     '</emitter></shape>', "wavelength:value pairs are not supported"),
    ('<integrator type="path"><boolean name="hide_emitters" value="true"/></integrator>',
     "hide_emitters is not supported"),
]


@pytest.mark.parametrize("body, message", UNSUPPORTED)
def test_unsupported_elements_name_the_element_and_line(tmp_path, body, message):
    # The offending element sits on the last line of the body, after a few others.
    path = _write(tmp_path, '<shape type="rectangle"/>\n\n' + body)
    with pytest.raises(ep.MitsubaError) as info:
        ep.load_mitsuba(path)
    text = str(info.value)
    assert message in text
    assert text.startswith(f"{path}:{_line_of(path, body.splitlines()[-1])}: <")


@pytest.mark.parametrize("sensor, message", [
    (SENSOR.replace('type="perspective"', 'type="thinlens"'), "unsupported sensor type 'thinlens'"),
    (SENSOR.replace('type="box"', 'type="tent"'), "unsupported rfilter type 'tent'"),
    (SENSOR.replace('<rfilter type="box"/>', '<integer name="banner" value="1"/>'),
     "property 'banner' of film 'hdrfilm' is not supported"),
    (SENSOR.replace('<lookat', '<scale x="-1"/><lookat'), "mirrors the image"),
    (SENSOR.replace('<float name="fov" value="40"/>', '<float name="fov" value="40"/>'
                    '<string name="focal_length" value="35mm"/>'), "give fov or focal_length"),
    (SENSOR.replace('"hdrfilm">', '"specfilm">'), "unsupported film type 'specfilm'"),
])
def test_unsupported_sensor_parts(tmp_path, sensor, message):
    path = _write(tmp_path, '<shape type="rectangle"/>', sensor=sensor)
    with pytest.raises(ep.MitsubaError, match=message) as info:
        ep.load_mitsuba(path)
    line = int(str(info.value).split(":")[1])
    assert _line_of(path, "<sensor") <= line <= _line_of(path, "</sensor>")


def test_malformed_xml_names_the_line(tmp_path):
    path = _write(tmp_path, '<shape type="rectangle">\n<bsdf type="diffuse">\n</shape>')
    with pytest.raises(ep.MitsubaError, match=r"scene\.xml:\d+: malformed XML"):
        ep.load_mitsuba(path)


def test_substitution_defaults_and_keyword_overrides(tmp_path):
    body = """
    <default name="albedo" value="0.25, 0.5, 0.75"/>
    <default name="kind" value="rectangle"/>
    <default name="s" value="2"/>
    <shape type="$kind" id="thing">
        <transform name="to_world"><scale value="$s"/></transform>
        <bsdf type="diffuse" id="paint"><rgb name="reflectance" value="$albedo"/></bsdf>
    </shape>"""
    path = _write(tmp_path, body)
    a = ep.load_mitsuba(path)
    assert torch.equal(a.bsdfs["paint"].diffuse, torch.tensor([0.25, 0.5, 0.75]))
    assert float(a.shapes["thing"].vertices.abs().max()) == 2.0
    assert a.shapes["thing"].indices.shape == (2, 3)
    b = ep.load_mitsuba(path, albedo=(0.1, 0.2, 0.3), s=3, kind="cube")
    assert torch.allclose(b.bsdfs["paint"].diffuse, torch.tensor([0.1, 0.2, 0.3]))
    assert float(b.shapes["thing"].vertices.abs().max()) == 3.0
    assert b.shapes["thing"].indices.shape == (12, 3)
    with pytest.raises(ep.MitsubaError, match="unknown to the file"):
        ep.load_mitsuba(path, albdeo=0.5)
    undefined = _write(tmp_path, '<shape type="rectangle"><transform name="to_world">'
                                 '<scale value="$size"/></transform></shape>', name="u.xml")
    with pytest.raises(ep.MitsubaError, match=r"u\.xml:\d+: <scale>: undefined parameter \$size"):
        ep.load_mitsuba(undefined)
    assert float(ep.load_mitsuba(undefined, size=0.5).scene.meshes[0].vertices.abs().max()) == 0.5
