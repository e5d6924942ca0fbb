"""Edges seen in curved mirrors and through curved glass: meshes with shading normals whose
material has a smooth lobe (edges/primary.cpp, CurvedFace). Each face turns the camera's rays by
its interpolated normal; the film point that sees an edge point through a face is solved for.

Closed forms:
- A flat mirror whose vertices carry its plane's normal is a curved face to the renderer, but
  turns rays as a plane does: it shows the mirror images of what is above it, and every derivative
  image equals theirs (test_mirror_edges.py), the mirror's tilt turning its normals too.
- A flat water surface whose faces carry their own normals shows a box under it sheared and
  dimmed (test_refracted_edges.py).

A ball with smooth normals, mirror or glass, is checked against finite differences: its
reflections move with the objects they show, with the ball and with its normals.

Through two curved faces (CurvedPair: in at one side of glass and out at the other):
- A pane whose faces carry their own normals shows the box behind it moved back and dimmed, as
  the flat pane of test_chained_edges.py does, for an orthographic camera (closed form), and for a
  pinhole the same derivative image as the flat pane.
- A box behind a smooth glass ball, seen only through both of its sides, against finite
  differences.
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes
from test_mirror_edges import KW as MIRROR_KW
from test_mirror_edges import _scenes, assert_same_derivative_image, gradients_of_both
from test_refracted_edges import COS, ETA, KW as WATER_KW
from test_refracted_edges import _fresnel, _sheared, _water
from test_chained_edges import COS as PANE_COS, ETA as PANE_ETA, KW as PANE_KW, _moved, _pane

BLACK = ep.Material(diffuse=0.0)


@pytest.mark.parametrize("camera_type", ["perspective", "orthographic"])
@pytest.mark.parametrize("param", ["box x", "box y", "near box y", "mirror height", "mirror tilt", "camera"])
def test_a_flat_mirror_with_shading_normals_shows_the_mirror_images(param, camera_type):
    """Per pixel, to 2% of the image's L1 norm (measured 0.01-0.03%; before this term the far box,
    seen only in the mirror, had no derivative image at all)."""
    seen, direct, offsets, placement, camera_t = _scenes(camera_type=camera_type, shading_normals=True)
    assert seen.meshes[0].normals is not None
    unit = torch.eye(3)
    p, d = {"box x": (offsets[0], unit[0]), "box y": (offsets[0], unit[1]), "near box y": (offsets[1], unit[1]),
            "mirror height": (placement, torch.tensor([1., 0.])), "mirror tilt": (placement, torch.tensor([0., 1.])),
            "camera": (camera_t, torch.tensor(1.))}[param]
    assert_same_derivative_image(seen, direct, p, d, **MIRROR_KW)


def test_a_thin_lens_sees_the_mirror_images_in_a_flat_mirror_with_shading_normals():
    """The thin lens's points see each face from directions within the angle its aperture spans
    there (the faces' beams widened by it): the mirror's tilt (both boxes' images and
    its normals turning), at 4x the edge samples, to 2% of the L1 norm (measured 0.07-0.4% for
    every parameter of the test above)."""
    seen, direct, _, placement, _ = _scenes(camera_type="thinlens", shading_normals=True)
    assert_same_derivative_image(seen, direct, placement, torch.tensor([0., 1.]),
                                 **dict(MIRROR_KW, edge_samples=4 * MIRROR_KW["edge_samples"]))


def test_the_gradient_pass_equals_the_mirror_images():
    """Every parameter at once (an adjoint image): the offsets, the mirror's height and tilt (its
    normals turning with it) and the camera."""
    seen, direct = gradients_of_both(lambda: _scenes(shading_normals=True), **MIRROR_KW)
    assert direct.abs().max() > 1.0
    assert torch.allclose(seen, direct, rtol=0.01, atol=0.01 * float(direct.abs().max())), (seen, direct)


def _with_face_normals(mesh):
    """The mesh with each face's own normal as its shading normal (one normal per face, computed
    from its vertices): flat, but a curved face to the renderer."""
    v, i = mesh.vertices, mesh.indices.long()
    n = torch.nn.functional.normalize(torch.cross(v[i[:, 1]] - v[i[:, 0]], v[i[:, 2]] - v[i[:, 0]], dim=1), dim=1)
    mesh.normals = n
    mesh.normal_indices = torch.arange(len(i), dtype=torch.int32)[:, None].expand(-1, 3).contiguous()
    return mesh


@pytest.mark.parametrize("param", ["box x", "level"])
def test_water_with_shading_normals_shows_the_box_sheared(param):
    """Per pixel, to 2% of the image's L1 norm, at 4x the edge samples of the plane's test
    (measured 0.1-0.8%, the camera's 0.8% too: its adjoint through the face is checked with the
    mirror, above). At the plane test's samples 0.3-1.9%, against the plane's 0.3-1.2%: each
    face's samples are spread over the part of the edge seen near it, and those that land in
    another face are lost; the error halves with 4x the samples."""
    scene, params = _water()
    _with_face_normals(scene.meshes[0])
    air = _sheared(params)
    p, d = {"box x": (params[0], torch.tensor([1., 0., 0.])), "level": (params[1], torch.tensor(1.))}[param]
    kw = dict(WATER_KW, edge_samples=4 * WATER_KW["edge_samples"])
    assert_same_derivative_image(scene, air, p, d, (1 - _fresnel(COS, ETA)) ** 2, **kw)


def mirror_ball(rings=16, resolution=(24, 24)):
    """A mirror ball (smooth normals) under a white sky, a black box above it and before it, out
    of the camera's view: seen only in the ball, near its top."""
    sv, si, _, sn = shapes.sphere((0., 0., 0.), 0.6, rings=rings)
    ball = ep.Mesh(sv, si, normals=sn, material=ep.Material(kind="conductor", specular=1.0))
    bv, bi = shapes.box((0.1, 0.95, -0.4), (.4, .15, .4))
    camera = ep.Camera(position=torch.tensor([0., 0., -2.5]), look_at=torch.tensor([0., 0., 0.]),
                       up=torch.tensor([0., 1., 0.]), fov=35.0, resolution=resolution)
    return ep.Scene(camera, [ball, ep.Mesh(bv, bi, material=BLACK)], envmap=ep.EnvironmentMap(torch.ones(1, 1, 3)))


def _compare(scene, param, direction, step, spp, fd_spp, seeds, fd_seeds, floor, weight=None, bounces=1,
             edge_samples=None):
    """The derivative image's (weighted) sum, `seeds` renders at `spp` (and `edge_samples`), against
    the central finite difference's, `fd_seeds` at `fd_spp` (steps of +-`step`): within 4 standard
    errors plus 4%, the latter above `floor` in magnitude. Returns both means."""
    w = 1.0 if weight is None else weight

    def total(image):
        return float((image * w).sum())

    d = torch.tensor([total(ep.derivative_image(scene, param, direction, spp=spp, max_bounces=bounces, seed=s,
                                                edge_samples=edge_samples))
                      for s in range(seeds)], dtype=torch.float64)
    f = torch.tensor([total(ep.finite_difference_image(scene, param, direction, eps=2 * step, spp=fd_spp,
                                                       max_bounces=bounces, seed=100 + s))
                      for s in range(fd_seeds)], dtype=torch.float64)
    error = math.sqrt(float(d.var()) / len(d) + float(f.var()) / len(f))
    assert abs(float(f.mean())) > floor
    assert abs(float(d.mean() - f.mean())) < 4 * error + 0.04 * abs(float(f.mean())), (d, f, error)
    return float(d.mean()), float(f.mean())


# The image's sum weighted by a ramp across the film: a reflection moved sideways changes it.
RAMP = torch.linspace(-1, 1, 24)[None, :, None] + 0.5 * torch.linspace(-1, 1, 24)[:, None, None]


@pytest.mark.parametrize("param", ["box up", "box sideways", "ball sideways", "normals tilted"])
def test_a_mirror_ball_matches_finite_differences(param):
    """24 x 24, one bounce; derivative 4 seeds x 64 spp, finite differences (steps 0.005) 4 seeds x
    2048 spp. Measured (finite differences at 8 seeds): the box up 148.8 +- 0.2 against 152.5 +-
    1.5 (an 8-ring ball: 150.2 against 150.9 +- 1.2), sideways (weighted by a ramp) 31.4 +- 0.1
    against 32.5 +- 0.4, the ball sideways 67.3 +- 0.2 against 68.7 +- 1.1, the normals tilted
    -11.50 against -11.51 +- 0.23; before this term, 0 for the box and the normals."""
    scene = mirror_ball()
    box, ball, normals = scene.meshes[1].vertices, scene.meshes[0].vertices, scene.meshes[0].normals
    p, d, w = {"box up": (box, torch.tensor([0., 1., 0.]), None),
               "box sideways": (box, torch.tensor([1., 0., 0.]), RAMP),
               "ball sideways": (ball, torch.tensor([1., 0., 0.]), RAMP),
               "normals tilted": (normals, torch.tensor([.5, 0., 0.]), RAMP)}[param]
    _compare(scene, p, d.expand(p.shape), step=0.005, spp=64, fd_spp=2048, seeds=4, fd_seeds=4, floor=5.0, weight=w)


def glass_ball_and_box(radius, box_centre, box_half, position, fov):
    """A smooth glass ball (16 rings, index 1.5) of `radius` at the origin and a black box under a
    white sky, seen at 24 x 24 from `position` looking at the ball's centre."""
    sv, si, _, sn = shapes.sphere((0., 0., 0.), radius, rings=16)
    ball = ep.Mesh(sv, si, normals=sn, material=ep.Material(kind="dielectric", ior=1.5))
    bv, bi = shapes.box(box_centre, box_half)
    camera = ep.Camera(position=torch.tensor(position), look_at=torch.tensor([0., 0., 0.]),
                       up=torch.tensor([0., 1., 0.]), fov=fov, resolution=(24, 24))
    return ep.Scene(camera, [ball, ep.Mesh(bv, bi, material=BLACK)], envmap=ep.EnvironmentMap(torch.ones(1, 1, 3)))


def test_a_box_inside_a_glass_ball_matches_finite_differences():
    """A black box inside a glass ball (smooth normals), seen through its near side: each edge
    refracted once by a curved face. 24 x 24, two bounces; derivative 8 seeds x 64 spp, finite
    differences (steps 0.005) 4 seeds x 2048 spp. Measured: -68.6 +- 5.5 against -66.8 +- 5.0."""
    scene = glass_ball_and_box(0.8, (0.1, 0.05, 0.0), (.2, .25, .2), (0.3, 0.4, -2.5), 40.0)
    box = scene.meshes[1].vertices
    _compare(scene, box, torch.tensor([1., 0., 0.]).expand(box.shape), step=0.005, spp=64, fd_spp=2048, seeds=8,
             fd_seeds=4, floor=20.0, bounces=2)


@pytest.mark.parametrize("param", ["box x", "box y", "box z", "thickness", "camera"])
def test_a_pane_with_shading_normals_shows_the_box_moved_and_dimmed(param):
    """Each face of the pane is a curved face to the renderer, so the box behind it is seen
    through pairs of them. Per pixel, to 2% of the image's L1 norm, at 4x the edge samples of the
    flat pane's test (measured: the box 0.04%, the thickness 0.3%, the camera 0.2%; at its
    samples up to 1.4%). Before, the box behind it had no derivative image."""
    scene, params = _pane()
    _with_face_normals(scene.meshes[0])
    unit = torch.eye(3)
    p, d = {"box x": (params[0], unit[0]), "box y": (params[0], unit[1]), "box z": (params[0], unit[2]),
            "thickness": (params[1], torch.tensor(1.)), "camera": (params[3], torch.tensor(1.))}[param]
    kw = dict(PANE_KW, edge_samples=4 * PANE_KW["edge_samples"])
    assert_same_derivative_image(scene, _moved(params), p, d, (1 - _fresnel(PANE_COS, PANE_ETA)) ** 2, **kw)


def test_a_pinhole_through_a_pane_with_shading_normals_sees_what_it_sees_through_the_flat_pane():
    """The pane's faces reach behind the camera (no beam): every face pairs with every face.
    The box's offset, per pixel, against the flat pane's chains of two planes: to 2% of the L1
    norm (measured 0.04%)."""
    curved, params = _pane("perspective")
    _with_face_normals(curved.meshes[0])
    flat, flat_params = _pane("perspective")
    a = ep.derivative_image(curved, params[0], torch.tensor([1., 0., 0.]), **PANE_KW)
    b = ep.derivative_image(flat, flat_params[0], torch.tensor([1., 0., 0.]), **PANE_KW)
    norm = b.abs().sum()
    assert norm > 1.0, norm
    assert (a - b).abs().sum() < 0.02 * norm, ((a - b).abs().sum() / norm, a.sum(), b.sum())


@pytest.mark.slow
def test_a_box_behind_a_smooth_glass_ball_matches_finite_differences():
    """A black box behind a smooth glass ball (16 rings), hidden by it: seen only through both of
    its sides. 24 x 24, two bounces; derivative 12 seeds x 64 spp at 4x the edge samples, finite
    differences (steps 0.005) 4 seeds x 4096 spp. Measured: 662.2 +- 1.3 (16 seeds) against
    672.5 +- 2 (673 +- 4 with steps of 0.002); the pixels short lie along the ball's outline.
    Before, 0: nothing but the edges moves there; then 643 +- 9, with parts of the outline lost
    where it passes from one pair of faces to the next."""
    scene = glass_ball_and_box(0.6, (0.15, 0.1, 1.4), (.25, .3, .2), (0., 0., -2.5), 30.0)
    box = scene.meshes[1].vertices
    _compare(scene, box, torch.tensor([1., 0., 0.]).expand(box.shape), step=0.005, spp=64, fd_spp=4096, seeds=12,
             fd_seeds=4, floor=100.0, bounces=2, edge_samples=24 * 24 * 64 * 4)
