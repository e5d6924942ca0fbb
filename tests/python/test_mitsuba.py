"""ep.load_mitsuba: the conformance scenes as Mitsuba XML files (tests/python/scenes) give the
same scenes as conformance.build, and what lies outside the supported subset raises an error
naming the element and its line."""

import math
import re
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
        return ep.load_mitsuba(SCENES / f"{name}.xml", **params)  # meshes/ and textures/ beside


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


def test_scene_files_need_only_the_repository():
    """Every file a scene names lies under tests/python/scenes (the scenes load without the
    reference data), and the copies there are the reference data's, byte for byte."""
    for path in sorted(SCENES.glob("*.xml")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ep.load_mitsuba(path)
        for name in re.findall(r'name="filename" value="\$data/([^"]+)"', path.read_text()):
            assert (SCENES / name).is_file(), f"{path.name}: {name}"
    if conformance.data_available():
        for copy in sorted((SCENES / "meshes").glob("*")) + sorted((SCENES / "textures").glob("*")):
            original = conformance.DATA_DIR / copy.parent.name / copy.name
            assert copy.read_bytes() == original.read_bytes(), copy.name


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
    ('<emitter type="projector"><float name="scale" value="2"/></emitter>',
     "unsupported emitter type 'projector'"),
    ('<shape type="rectangle"><bsdf type="thindielectric"/></shape>',
     "unsupported bsdf type 'thindielectric'"),
    ('<shape type="rectangle"><bsdf type="twosided"><bsdf type="dielectric"/></bsdf></shape>',
     "twosided cannot hold a dielectric"),
    ('<shape type="rectangle"><bsdf type="dielectric"><float name="int_ior" value="20"/>'
     '</bsdf></shape>', "must be in [0.1, 10]"),
    ('<shape type="rectangle"><bsdf type="dielectric"><rgb name="specular_transmittance" '
     'value="0.5"/></bsdf></shape>', "specular_transmittance other than 1 is not supported"),
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
    ('<shape type="rectangle"><bsdf type="roughplastic"><float name="alpha" value="0"/>'
     '</bsdf></shape>', "a roughplastic needs alpha > 0"),
    ('<shape type="rectangle"><bsdf type="plastic"><float name="int_ior" value="1.0"/>'
     '</bsdf></shape>', "must be in [0.1, 10] and differ from 1"),
    ('<shape type="rectangle"><bsdf type="twosided"><bsdf type="diffuse"/><bsdf type="diffuse"/>'
     '</bsdf></shape>', "twosided takes exactly one BSDF"),
    ('<shape type="rectangle"><bsdf type="normalmap"><bsdf type="diffuse"/></bsdf></shape>',
     'normalmap needs a <texture name="normalmap">'),
    ('<shape type="rectangle"><bsdf type="normalmap"><rgb name="normalmap" value="0.5, 0.5, 1"/>'
     '<bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf></shape>', "normalmap takes exactly one BSDF"),
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
    ('<integrator type="direct"><integer name="max_depth" value="3"/></integrator>',
     "the direct integrator has no max_depth"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap"/></bsdf></shape>',
     "a texture inside a <bsdf> needs a name"),
    ('<shape type="rectangle"><bsdf type="diffuse"><rgb name="reflectance" value="1, 2"/></bsdf></shape>',
     "expected 1 or 3 numbers, got 2"),
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
    (SENSOR.replace('type="perspective"', 'type="pinhole"'), "unsupported sensor type 'pinhole'"),
    (SENSOR.replace('type="perspective"', 'type="thinlens"'), "aperture_radius is required"),
    (SENSOR.replace('type="box"/>', 'type="tent"><float name="radius" value="0.25"/></rfilter>'),
     r"radius 0.25: must be in \[0.5, 100\) pixels"),
    (SENSOR.replace('<float name="fov" value="40"/>', '<float name="fov" value="40"/>'
                    '<float name="focus_distance" value="0"/>'), "focus_distance must be > 0"),
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


# ---- elements of the subset ---------------------------------------------------------------------

def _face_normals(mesh):
    v, i = mesh.vertices.double(), mesh.indices.long()
    return torch.linalg.cross(v[i[:, 1]] - v[i[:, 0]], v[i[:, 2]] - v[i[:, 0]])


def test_analytic_shapes(tmp_path):
    body = """
    <shape type="sphere" id="ball"><point name="center" x="1" y="2" z="3"/><float name="radius" value="0.5"/></shape>
    <shape type="disk" id="disk"><transform name="to_world"><scale value="2"/><translate z="-1"/></transform></shape>
    <shape type="cube" id="box"/>
    <shape type="cube" id="inside"><boolean name="flip_normals" value="true"/></shape>
    <shape type="rectangle" id="rect"><transform name="to_world"><rotate x="1" angle="90"/></transform></shape>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    ball = s.shapes["ball"]
    centre = torch.tensor([1.0, 2.0, 3.0])
    assert torch.allclose((ball.vertices - centre).norm(dim=1), torch.tensor(0.5), atol=1e-6)
    fn = _face_normals(ball)
    corners = ball.vertices[ball.indices.long()].double().mean(1) - centre.double()
    assert bool(((fn * corners).sum(1) > 0).all())  # counter-clockwise seen from outside
    assert torch.allclose(ball.normals, (ball.vertices - centre) / 0.5, atol=1e-5)
    assert ball.uvs.min() >= 0 and ball.uvs.max() <= 1
    disk = s.shapes["disk"]
    assert torch.allclose(disk.vertices[:, 2], torch.tensor(-1.0))
    assert float(disk.vertices[:, :2].norm(dim=1).max()) == pytest.approx(2.0)
    assert bool((_face_normals(disk)[:, 2] > 0).all()) and disk.normals is None
    box, inside = s.shapes["box"], s.shapes["inside"]
    assert box.indices.shape == (12, 3) and float(box.vertices.abs().max()) == 1.0
    out = (_face_normals(box) * box.vertices[box.indices.long()].double().mean(1)).sum(1)
    assert bool((out > 0).all())
    assert torch.equal(_face_normals(inside), -_face_normals(box))
    rect = s.shapes["rect"]  # rotated +90 degrees about x: +z turns into -y
    assert torch.allclose(_face_normals(rect)[:, 1], torch.tensor(-4.0, dtype=torch.float64))


def test_transforms_compose_in_order(tmp_path):
    body = """
    <shape type="rectangle" id="a"><transform name="to_world">
        <scale x="2" y="3"/><rotate value="0 0 1" angle="90"/><translate value="10 0 0"/>
    </transform></shape>
    <shape type="rectangle" id="b"><transform name="to_world">
        <matrix value="0 -3 0 10  2 0 0 0  0 0 1 0  0 0 0 1"/></transform></shape>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    # (x, y) -> scale (2x, 3y) -> rotate (-3y, 2x) -> translate (10 - 3y, 2x)
    v = torch.tensor([[-1.0, -1, 0], [1, -1, 0], [-1, 1, 0], [1, 1, 0]])
    expected = torch.stack([10 - 3 * v[:, 1], 2 * v[:, 0], v[:, 2]], 1)
    assert torch.allclose(s.shapes["a"].vertices, expected, atol=1e-6)
    assert torch.allclose(s.shapes["b"].vertices, expected, atol=1e-6)


@pytest.mark.parametrize("axis, tan_x", [
    ("x", math.tan(math.radians(30))),
    ("y", math.tan(math.radians(30)) * 12 / 8),
    ("diagonal", math.tan(math.radians(30)) * 12 / math.hypot(12, 8)),
    ("smaller", math.tan(math.radians(30)) * 12 / 8),   # the 8 px height is the smaller side
    ("larger", math.tan(math.radians(30))),
])
def test_fov_axes(tmp_path, axis, tan_x):
    sensor = SENSOR.replace('value="40"/>', f'value="60"/><string name="fov_axis" value="{axis}"/>')
    s = ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=sensor))
    assert math.tan(math.radians(float(s.scene.camera.fov)) / 2) == pytest.approx(tan_x, rel=1e-6)


def test_default_focal_length_and_film(tmp_path):
    sensor = '<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="64"/>' \
             '<integer name="height" value="64"/></film></sensor>'
    s = ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=sensor))
    c = s.scene.camera
    assert float(c.fov) == pytest.approx(34.02205717235932, abs=1e-4)  # 50 mm, diagonal
    assert c.pixel_filter == "gaussian" and c.filter_stddev == 0.5  # Mitsuba's default filter
    assert s.max_bounces is None and s.spp == 4  # no integrator; the default sampler
    bare = _write(tmp_path, '<shape type="rectangle"/>', sensor='<sensor type="perspective"/>',
                  name="bare.xml")
    assert ep.load_mitsuba(bare).scene.camera.resolution == (576, 768)


def test_unbounded_depth_renders_with_the_command_lines_bounces(tmp_path):
    from edgepath.cli import DEFAULT_MAX_BOUNCES
    sensor = '<sensor type="perspective"><transform name="to_world"><lookat origin="0 0 -4" ' \
             'target="0 0 0" up="0 1 0"/></transform><film type="hdrfilm"><integer name="width" ' \
             'value="8"/><integer name="height" value="8"/></film></sensor>'
    shapes = '<shape type="rectangle"><transform name="to_world"><scale value="3"/>' \
             '<translate z="1"/></transform><bsdf type="twosided"><bsdf type="diffuse"/></bsdf>' \
             '</shape><shape type="sphere"><float name="radius" ' \
             'value="0.5"/></shape><emitter type="constant"/>'
    s = ep.load_mitsuba(_write(tmp_path, shapes, sensor=sensor))
    assert s.max_bounces is None and DEFAULT_MAX_BOUNCES == 2
    image = s.render(spp=32)
    assert torch.equal(image, ep.render(s.scene, spp=32, max_bounces=2, seed=s.seed))
    # the second bounce adds light (about 1% here; at 2 spp it could add none by chance: only
    # the paths that reach the sphere from the backdrop, and see the sky past it, bring any)
    assert float(image.sum()) > float(ep.render(s.scene, spp=32, max_bounces=1, seed=s.seed).sum())


def test_thin_lens_sensor(tmp_path):
    lens = '<float name="aperture_radius" value="0.2"/><float name="focus_distance" value="3.5"/>'
    sensor = SENSOR.replace('type="perspective">', 'type="thinlens">' + lens)
    loaded = ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=sensor))
    c = loaded.scene.camera
    assert c.camera_type == "thinlens" and float(c.fov) == pytest.approx(40)
    names = loaded.parameters()  # Mitsuba's names (mi.traverse)
    assert names["sensor.aperture_radius"] is c.aperture_radius
    assert names["sensor.focus_distance"] is c.focus_distance
    assert float(c.aperture_radius) == pytest.approx(0.2)
    assert float(c.focus_distance) == pytest.approx(3.5)
    # As Mitsuba: the focus distance defaults to the far clip distance.
    sensor = SENSOR.replace('type="perspective">', 'type="thinlens"><float name="aperture_radius" '
                            'value="0.1"/><float name="far_clip" value="50"/>')
    c = ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=sensor,
                                   name="b.xml")).scene.camera
    assert float(c.focus_distance) == pytest.approx(50)
    bad = SENSOR.replace('type="perspective">', 'type="thinlens"><float name="aperture_radius" '
                         'value="0.1"/><float name="focus_distance" value="-1"/>')
    with pytest.raises(ep.MitsubaError, match="focus_distance -1.0: must be > 0"):
        ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=bad, name="c.xml"))


def test_directional_emitter(tmp_path):
    body = """<shape type="rectangle" id="floor"><transform name="to_world"><scale value="2"/></transform></shape>
    <emitter type="directional" id="sun"><vector name="direction" value="0, 0, -2"/>
        <rgb name="irradiance" value="3, 2, 1"/><float name="angular_diameter" value="1"/></emitter>
    <emitter type="directional"><transform name="to_world"><lookat origin="0 0 0" target="1 0 -1"/></transform></emitter>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    assert s.shape_ids == ["floor", "sun", "sun_1"]
    image = s.render(spp=64, max_bounces=1)
    # The floor (reflectance 0.5) faces the first sun (irradiance (3, 2, 1)) and receives the
    # second's irradiance 1 at 45 degrees.
    expected = 0.5 / math.pi * (torch.tensor([3.0, 2, 1]) + math.cos(math.pi / 4))
    assert torch.allclose(image.mean((0, 1)), expected, rtol=2e-2)  # one light sampled of two
    _assert_emitter_errors(tmp_path, "directional", [
        ('<vector name="direction" value="0 0 -1"/><transform name="to_world"><scale value="1"/></transform>',
         "direction or to_world"),
        ('<vector name="direction" value="0 0 0"/>', "the direction is zero"),
        ('<float name="angular_diameter" value="0"/>', "angular_diameter 0.0"),
        ('<float name="intensity" value="1"/>', "property 'intensity' of emitter"),
    ])


def _assert_emitter_errors(tmp_path, kind, cases):
    """Each (body, message): an emitter of ``kind`` with that body raises the message."""
    for bad, message in cases:
        path = _write(tmp_path, f'<shape type="rectangle"/><emitter type="{kind}">{bad}</emitter>',
                      name="bad.xml")
        with pytest.raises(ep.MitsubaError, match=message):
            ep.load_mitsuba(path)


def test_point_emitter(tmp_path):
    body = """<shape type="rectangle" id="floor"/>
    <emitter type="point" id="bulb"><point name="position" value="0, 0, 2"/>
        <rgb name="intensity" value="8, 4, 2"/><float name="radius" value="0.05"/></emitter>
    <emitter type="point"><transform name="to_world"><translate z="3"/></transform></emitter>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    assert s.shape_ids == ["floor", "bulb", "point_1"]
    bulb, default = s.shapes["bulb"], s.shapes["point_1"]
    box_centre = (bulb.vertices.min(0).values + bulb.vertices.max(0).values) / 2
    assert torch.allclose(box_centre, torch.tensor([0.0, 0, 2]), atol=1e-6)
    assert float((bulb.vertices - torch.tensor([0.0, 0, 2])).norm(dim=1).max()) == pytest.approx(0.05, rel=1e-5)
    # The default radius: 1e-3 of the shapes' bounds (the unit square: radius sqrt(2)).
    radius = float((default.vertices - torch.tensor([0.0, 0, 3])).norm(dim=1).max())
    assert radius == pytest.approx(1e-3 * math.sqrt(2), rel=1e-3)
    # Pixels (1..2, 3..4) see the floor (reflectance 0.5; 12 x 8 pixels, fov 40, from z = 5);
    # each light gives a floor point E = I h / d^3 at height h, distance d.
    image = s.render(spp=1024, max_bounces=1)
    t = math.tan(math.radians(20))
    expected = torch.zeros(3)
    for row in (1, 2):
        for col in (3, 4):
            x, y = 5 * (2 * (col + 0.5) / 12 - 1) * t, 5 * (1 - 2 * (row + 0.5) / 8) * t * 8 / 12
            for h, intensity in ((2.0, torch.tensor([8.0, 4, 2])), (3.0, torch.ones(3))):
                expected += 0.5 / math.pi * intensity * h / (x * x + y * y + h * h) ** 1.5 / 4
    assert torch.allclose(image[1:3, 3:5].mean((0, 1)), expected, rtol=0.03)
    _assert_emitter_errors(tmp_path, "point", [
        ('<point name="position" value="0 0 1"/><transform name="to_world"><scale value="1"/></transform>',
         "position or to_world"),
        ('<float name="radius" value="-1"/>', "radius -1.0: must be finite and >= 0"),
        ('<rgb name="intensity" value="-1"/>', "intensity must be a constant >= 0"),
    ])


def test_point_and_spot_emitters_of_radius_zero_are_delta_lights(tmp_path):
    body = """<shape type="rectangle" id="floor"/>
    <emitter type="point" id="bulb"><point name="position" value="0, 0, 2"/>
        <rgb name="intensity" value="8, 4, 2"/><float name="radius" value="0"/></emitter>
    <emitter type="spot"><transform name="to_world"><lookat origin="1, 2, 3" target="1, 2, 0"/></transform>
        <float name="cutoff_angle" value="40"/><float name="radius" value="0"/></emitter>
    <emitter type="spot" id="round"><transform name="to_world"><translate z="3"/></transform>
        <float name="beam_width" value="5"/></emitter>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    assert s.shape_ids == ["floor", "round"] and list(s.point_lights) == ["bulb", "spot_1"]
    bulb, spot = s.scene.point_lights
    assert bulb is s.point_lights["bulb"] and bulb.spot is None
    assert torch.equal(bulb.position.float(), torch.tensor([0.0, 0, 2]))
    assert torch.allclose(bulb.intensity, torch.tensor([8.0, 4, 2]))
    # A spot shines along its to_world's z axis, from its translation.
    assert torch.allclose(spot.position.float(), torch.tensor([1.0, 2, 3]))
    assert torch.allclose(spot.spot.direction.float(), torch.tensor([0.0, 0, -1]), atol=1e-6)
    assert (float(spot.spot.cutoff_angle), float(spot.spot.beam_width)) == (40.0, 30.0)
    names = s.parameters()
    assert names["bulb.intensity.value"] is bulb.intensity and names["bulb.position"] is bulb.position
    assert names["spot_1.cutoff_angle"] is spot.spot.cutoff_angle
    assert names["spot_1.direction"] is spot.spot.direction
    # Without a radius, a small sphere with the profile (the default cutoff angle 20 degrees).
    round_spot = s.shapes["round"]
    assert round_spot.spot is not None and float(round_spot.spot.cutoff_angle) == 20.0
    assert float(round_spot.spot.beam_width) == 5.0
    _assert_emitter_errors(tmp_path, "spot", [
        ('<point name="position" value="0 0 1"/>', "a spot is placed by to_world"),
        ('<float name="cutoff_angle" value="0"/>', "cutoff_angle 0.0"),
        ('<float name="cutoff_angle" value="10"/><float name="beam_width" value="10"/>', "beam_width 10.0"),
        ('<float name="radius" value="-1"/>', "radius -1.0"),
        ('<rgb name="intensity" value="-1"/>', "intensity must be a constant >= 0"),
    ])


def test_orthographic_sensor(tmp_path):
    sensor = """<sensor type="orthographic">
        <transform name="to_world"><scale value="2.5"/><lookat origin="0 0 5" target="0 0 0" up="0 1 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
            <rfilter type="gaussian"><float name="stddev" value="0.3"/></rfilter></film>
        <sampler type="stratified"><integer name="sample_count" value="9"/><integer name="seed" value="3"/></sampler>
    </sensor>"""
    s = ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=sensor))
    c = s.scene.camera
    assert c.camera_type == "orthographic" and c.ortho_scale == pytest.approx(2.5)
    assert c.pixel_filter == "gaussian" and c.filter_stddev == pytest.approx(0.3)
    assert (s.spp, s.seed) == (9, 3)
    position, look_at, up = c.frame()
    assert torch.allclose(position, torch.tensor([0.0, 0, 5]))
    assert torch.allclose(c.to_world[:3, 2] / 2.5, torch.tensor([0.0, 0, -1]))
    assert torch.allclose(torch.nn.functional.normalize(look_at - position, dim=0), torch.tensor([0.0, 0, -1]))
    bad = sensor.replace('<scale value="2.5"/>', '<scale x="2" y="1"/>')
    with pytest.raises(ep.MitsubaError, match="scales x and y differently"):
        ep.load_mitsuba(_write(tmp_path, '<shape type="rectangle"/>', sensor=bad, name="b.xml"))


def test_bsdfs(tmp_path):
    texture = tmp_path / "albedo.png"
    ep.imwrite(torch.rand(4, 6, 3, generator=torch.Generator().manual_seed(0)), texture)
    body = """
    <texture type="bitmap" id="tex"><string name="filename" value="albedo.png"/></texture>
    <bsdf type="twosided" id="shared"><bsdf type="diffuse"><ref name="reflectance" id="tex"/></bsdf></bsdf>
    <shape type="rectangle" id="a"><ref id="shared"/></shape>
    <shape type="rectangle" id="b"><ref name="bsdf" id="shared"/></shape>
    <shape type="rectangle" id="gold"><bsdf type="roughconductor">
        <string name="material" value="Au"/><string name="distribution" value="ggx"/>
        <float name="alpha" value="0.2"/><rgb name="specular_reflectance" value="0.5"/></bsdf></shape>
    <shape type="rectangle" id="metal"><bsdf type="roughconductor" id="ek">
        <string name="distribution" value="ggx"/>
        <rgb name="eta" value="0.2, 0.9, 1.1"/><rgb name="k" value="3.9, 2.4, 2.2"/></bsdf></shape>
    <shape type="rectangle" id="plastic"><bsdf type="roughplastic" id="pl">
        <string name="distribution" value="ggx"/><float name="alpha" value="0.3"/>
        <string name="int_ior" value="bk7"/><rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/></bsdf></shape>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    assert s.shapes["a"].material is s.shapes["b"].material is s.bsdfs["shared"]
    shared = s.bsdfs["shared"]
    assert shared.two_sided and torch.equal(shared.diffuse, ep.imread(texture))
    assert s.textures["tex"] is shared.diffuse
    gold = s.shapes["gold"].material
    assert torch.allclose(gold.specular, 0.5 * torch.tensor([1.000, 0.782, 0.344]))
    assert gold.roughness == pytest.approx(0.2) and torch.equal(gold.diffuse, torch.zeros(3))
    eta, k = torch.tensor([0.2, 0.9, 1.1]), torch.tensor([3.9, 2.4, 2.2])
    f0 = ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)
    assert torch.allclose(s.bsdfs["ek"].specular, f0) and s.bsdfs["ek"].roughness == 0.1
    pl = s.bsdfs["pl"]
    assert pl.kind == "plastic" and float(pl.ior) == pytest.approx(1.5046 / 1.000277)
    assert torch.equal(pl.specular, torch.ones(3)) and pl.roughness == pytest.approx(0.3)
    assert torch.allclose(pl.diffuse, torch.tensor([0.1, 0.2, 0.3])) and not pl.two_sided
    names = s.parameters()
    assert names["shared.brdf_0.reflectance.data"] is shared.diffuse
    assert names["ek.specular"] is s.bsdfs["ek"].specular
    assert names["gold.bsdf.specular"] is gold.specular
    assert names["pl.diffuse_reflectance.value"] is pl.diffuse
    assert names["pl.specular_reflectance.value"] is pl.specular and names["pl.eta"] is pl.ior
    assert names["pl.alpha.value"] is pl.roughness
    assert "gold.bsdf.diffuse" in names  # a conductor's (black) diffuse: no Mitsuba name
    # Shapes a and b share one BSDF: its tensors are listed once, under its id.
    assert not any(name.startswith(("a.bsdf", "b.bsdf")) for name in names)
    assert len({id(t) for t in names.values()}) == len(names)


def test_normalmap(tmp_path):
    """A normalmap around a BSDF is that BSDF's material with the bitmap as its normal_map, loaded
    as Mitsuba loads it (raw: 8-bit values as stored), under Mitsuba's parameter names; inside
    twosided too."""
    texels = torch.rand(4, 6, 3, generator=torch.Generator().manual_seed(1))
    ep.imwrite(texels, tmp_path / "normals.exr")
    ep.imwrite(texels, tmp_path / "normals.png")
    body = """
    <shape type="rectangle" id="a"><bsdf type="normalmap" id="bumpy">
        <texture type="bitmap" name="normalmap"><string name="filename" value="normals.exr"/></texture>
        <bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="0.3"/></bsdf>
    </bsdf></shape>
    <shape type="rectangle" id="b"><bsdf type="twosided"><bsdf type="normalmap">
        <texture type="bitmap" name="normalmap"><string name="filename" value="normals.png"/>
            <boolean name="raw" value="true"/></texture>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf>
    </bsdf></bsdf></shape>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    bumpy = s.bsdfs["bumpy"]
    assert torch.equal(bumpy.normal_map, ep.imread(tmp_path / "normals.exr"))
    assert bumpy.roughness == pytest.approx(0.3) and bumpy.kind == "plastic" and not bumpy.two_sided
    b = s.shapes["b"].material
    assert b.two_sided and torch.allclose(b.diffuse, torch.tensor([0.2, 0.4, 0.6]))
    # raw: the 8-bit values as stored (imwrite encoded the linear texels as sRGB)
    assert torch.allclose(b.normal_map, ep.to_srgb(texels), atol=0.5 / 255 + 1e-6)
    names = s.parameters()
    assert names["bumpy.normalmap.data"] is bumpy.normal_map
    assert names["bumpy.nested_bsdf.diffuse_reflectance.value"] is bumpy.diffuse
    assert names["b.bsdf.brdf_0.normalmap.data"] is b.normal_map
    assert names["b.bsdf.brdf_0.nested_bsdf.reflectance.value"] is b.diffuse
    # The map is used: the shading normals differ from the face's.
    out = ep.render_channels(s.scene, ["shading_normal", "geometry_normal", "mesh_id"], spp=1)
    hit = out["mesh_id"][..., 0] >= 0
    assert bool(hit.any())
    assert not torch.allclose(out["shading_normal"][hit], out["geometry_normal"][hit], atol=1e-3)


def test_beckmann_is_rendered_as_ggx_with_a_warning(tmp_path):
    path = _write(tmp_path, '<shape type="rectangle"><bsdf type="roughconductor"/></shape>')
    with pytest.warns(UserWarning, match="Beckmann distribution .* rendered as GGX"):
        s = ep.load_mitsuba(path)
    # Mitsuba's default alpha, and its default material "none": eta 0, k 1, a white reflector
    assert s.scene.meshes[0].material.roughness == 0.1
    assert torch.equal(s.scene.meshes[0].material.specular, torch.ones(3))


def test_mesh_files_and_emitters(tmp_path):
    v, f = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]), torch.tensor([[0, 1, 2], [0, 2, 3]])
    uv = torch.tensor([[0.0, 0.1], [1, 0.1], [1, 0.9], [0, 0.9]])
    ep.save_obj(ep.Mesh(vertices=v, indices=f, uvs=uv), tmp_path / "quad.obj", materials=False)
    (tmp_path / "quad.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    env = torch.rand(4, 8, 3, generator=torch.Generator().manual_seed(2))
    ep.imwrite(env, tmp_path / "sky.exr")
    body = """
    <shape type="obj" id="flat"><string name="filename" value="quad.obj"/>
        <boolean name="face_normals" value="true"/></shape>
    <shape type="obj" id="smooth"><string name="filename" value="quad.obj"/>
        <boolean name="flip_tex_coords" value="false"/>
        <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter></shape>
    <shape type="ply" id="ply"><string name="filename" value="quad.ply"/></shape>
    <emitter type="envmap"><string name="filename" value="sky.exr"/><float name="scale" value="2"/>
        <transform name="to_world"><rotate y="1" angle="90"/></transform></emitter>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    flat, smooth, ply = (s.shapes[k] for k in ("flat", "smooth", "ply"))
    assert flat.normals is None
    assert torch.allclose(flat.uvs[flat.uv_indices.long()], uv[f], atol=1e-6)  # as written
    assert torch.allclose(smooth.uvs[smooth.uv_indices.long()][..., 1], 1 - uv[f][..., 1], atol=1e-6)
    assert torch.allclose(smooth.normals, torch.tensor([0.0, 0, 1]).expand(4, 3))  # computed
    assert torch.equal(smooth.emission, torch.tensor([1.0, 2, 3]))
    assert torch.equal(smooth.material.diffuse, torch.zeros(3))  # emitters: black by default
    assert torch.equal(ply.vertices, v) and ply.indices.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert torch.allclose(ply.normals, torch.tensor([0.0, 0, 1]).expand(4, 3))
    e = s.scene.envmap
    assert torch.equal(e.values, env) and e.scale == 2.0
    assert torch.allclose(e.to_world[:3, :3], torch.tensor([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
                          atol=1e-6)


def test_parameters_and_directions(tmp_path):
    body = """<shape type="rectangle" id="plane"/>
    <shape type="rectangle" id="lamp"><emitter type="area"><rgb name="radiance" value="1 1 1"/></emitter>
        <transform name="to_world"><translate z="2"/><rotate x="1" angle="180"/></transform></shape>
    <emitter type="constant"/>"""
    s = ep.load_mitsuba(_write(tmp_path, body))
    names = s.parameters()
    # Mitsuba 3's names (mi.traverse), each tensor once (sensor.position is a direction only).
    assert set(names) == {"sensor.to_world", "sensor.x_fov", "plane.vertex_positions",
                          "plane.bsdf.reflectance.value", "lamp.vertex_positions",
                          "lamp.emitter.radiance.value", "lamp.bsdf.reflectance.value",
                          "envmap.data"}
    assert len({id(t) for t in names.values()}) == len(names)
    torch.optim.Adam(names.values(), lr=0.1)  # no duplicate-parameter warning or error
    param, d = s.direction("plane.vertex_positions", [1, 2, 3])
    assert param is s.shapes["plane"].vertices and torch.equal(d, torch.tensor([1.0, 2, 3]).expand(4, 3))
    param, d = s.direction("sensor.position", [0, 0, 1])
    assert param is s.scene.camera.to_world and d[2, 3] == 1 and int((d != 0).sum()) == 1
    param, d = s.direction("envmap.data", [0.5])
    assert d.shape == (1, 1, 3) and bool((d == 0.5).all())
    param, d = s.direction("sensor.x_fov", [2])
    assert d.shape == () and float(d) == 2
    with pytest.raises(ValueError, match="expected 3 numbers, got 1"):
        s.direction("plane.vertex_positions", [1])
    with pytest.raises(ValueError, match="'nothing': not in this scene .*sensor.position"):
        s.direction("nothing", [1])
    image = s.render(spp=1)  # the file's settings: 12 x 8 film
    assert image.shape == (8, 12, 3) and float(image.min()) >= 0


def test_the_documented_example_loads(tmp_path):
    doc = (Path(__file__).resolve().parents[2] / "docs" / "scene-files.md").read_text()
    xml = doc.split("```xml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "meshes").mkdir()
    v, f = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), \
        torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    ep.save_obj(ep.Mesh(vertices=v, indices=f), tmp_path / "meshes" / "bunny.obj", materials=False)
    (tmp_path / "scene.xml").write_text(xml)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the example uses no approximated feature
        s = ep.load_mitsuba(tmp_path / "scene.xml", spp=2)
    assert s.shape_ids == ["bunny", "floor", "lamp"] and s.spp == 2 and s.max_bounces == 2
    assert s.bsdfs["paint"].two_sided and s.shapes["bunny"].material is s.bsdfs["paint"]
    bunny = s.shapes["bunny"]
    assert torch.allclose(bunny.vertices[bunny.indices.long()],
                          (2 * v + torch.tensor([0.0, -0.5, 0.0]))[f])
    assert {"bunny.vertex_positions", "paint.brdf_0.reflectance.value",
            "lamp.emitter.radiance.value", "envmap.data"} <= set(s.parameters())
