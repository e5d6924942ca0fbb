"""bench/mitsuba_compare.py without Mitsuba: the scene files it writes load into edgepath with
welded meshes (the fairness of the comparison rests on it), and without the mitsuba package it
says so in one line and exits 0."""

import importlib.util
import pathlib
import subprocess
import sys

import torch

import edgepath as ep

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "bench" / "mitsuba_compare.py"


def load_script():
    spec = importlib.util.spec_from_file_location("mitsuba_compare", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write(tmp_path, xml):
    path = tmp_path / "scene.xml"
    path.write_text(xml)
    return ep.load_mitsuba(path)


def closed_and_welded(mesh):
    """Every edge of the mesh is shared by exactly two triangles, in opposite directions."""
    f = mesh.indices.long()
    directed = torch.cat([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    keys = set(map(tuple, directed.tolist()))
    return len(keys) == len(directed) and all((b, a) in keys for a, b in keys)


def test_scenes_load_welded(tmp_path):
    mc = load_script()
    xml, triangles = mc.make_cornell(str(tmp_path), 16, 1, 2)
    loaded = write(tmp_path, xml)
    assert sum(int(m.indices.shape[0]) for m in loaded.scene.meshes) == triangles > 30000
    sphere = loaded.scene.meshes[6]
    assert closed_and_welded(sphere) and closed_and_welded(loaded.scene.meshes[5])  # sphere, box
    assert loaded.scene.meshes[5].vertices.shape == (8, 3)

    xml = mc.make_shadow(str(tmp_path), 16, 1, 2)
    loaded = write(tmp_path, xml)
    cube = loaded.shapes["shape0"]
    assert cube.vertices.shape == (8, 3) and closed_and_welded(cube)
    image = ep.render(loaded.scene, spp=2, max_bounces=1)
    assert image.mean() > 0  # the floor is lit, the light faces it

    # The glossy variant: the floor is a GGX roughplastic (no Beckmann-as-GGX warning), the
    # light's highlight in it brighter than the diffuse floor's brightest pixel.
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        glossy = write(tmp_path, mc.make_glossy(str(tmp_path), 16, 1, 3))
    floor = glossy.scene.meshes[1].material
    assert floor.kind == "plastic" and float(floor.roughness) > 0
    assert ep.render(glossy.scene, spp=16, max_bounces=2).max() > image.max()

    xml, triangles = mc.make_scan(str(tmp_path), 16, 1, 2)
    loaded = write(tmp_path, xml)
    assert loaded.shapes["shape0"].indices.shape[0] > 99000  # the same sphere() as above, bumped

    # The faceted sphere: welded and closed, and wholly in view (Mitsuba's projective sampling
    # would need film samples past the border otherwise): the image's border pixels see only
    # the floor, its mask of the sphere's pixels is not empty.
    loaded = write(tmp_path, mc.make_faceted_shadow(str(tmp_path), 32, 1, 2))
    ball = loaded.shapes["shape0"]
    assert ball.indices.shape[0] > 49000 and closed_and_welded(ball)
    mesh_id = ep.render_channels(loaded.scene, ["mesh_id"], spp=1)["mesh_id"][..., 0]
    assert (mesh_id == 0).any()
    border = torch.cat([mesh_id[0], mesh_id[-1], mesh_id[:, 0], mesh_id[:, -1]])
    assert (border == 1).all()


def test_rays_per_sample(tmp_path):
    # The counts the forward table prints beside the times: one camera ray per sample; at most
    # max_bounces continuations; the scan scene (an area light and a uniform sky) traces shadow
    # rays towards the area light alone, at most one per vertex: the sky is left to the BSDF's
    # samples (docs/conventions.md), unless the light sampling strategy is used alone, which
    # samples both.
    from edgepath.render import flatten_scene, render_flat, render_options
    mc = load_script()
    xml, _ = mc.make_scan(str(tmp_path), 16, 1, 3)
    loaded = write(tmp_path, xml)
    camera, shadow, bounce = mc.rays_per_sample(loaded.scene, 16, 2, 2)
    assert camera == 1.0
    assert 0.3 < bounce <= 2.0
    assert 0.3 < shadow <= 1.0 + bounce
    _, light_only = render_flat(flatten_scene(loaded.scene),
                                render_options(spp=2, max_bounces=2, sampling="light"))
    assert light_only["shadow_rays"] / (16 * 16 * 2) > shadow + 0.3


def test_skipped_without_mitsuba(tmp_path):
    # The script run with the mitsuba package hidden.
    code = ("import runpy, sys; sys.modules['mitsuba'] = None; sys.argv = ['mitsuba_compare.py']; "
            f"runpy.run_path({str(SCRIPT)!r}, run_name='__main__')")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Mitsuba comparison skipped: the mitsuba package is not installed")
