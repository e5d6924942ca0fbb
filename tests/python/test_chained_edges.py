"""Edges seen after two flat smooth faces: through a pane (in at one face, out at the other), in
one mirror seen in another, in a face of a glass object from inside after entering at another
(edges/primary.cpp, "Chains of two planes").

Closed forms:
- An orthographic camera's parallel rays leave a pane of parallel faces in the direction they
  entered, each moved along the pane by the same vector. So a black box behind a pane under a
  constant sky looks like the box moved back by that vector, dimmed by the Fresnel
  transmittance on the way in and again on the way out ((1 - F)^2, the same angle at both
  faces), beside the sky's reflection F everywhere. Every derivative image of the box seen
  through the pane is the moved box's, times (1 - F)^2.
- Two perfect mirrors at a right angle (a floor and a wall) show the scene mirrored across
  each and, seen in one in the other, across both: the same image as the four copies seen
  without mirrors, and so the same derivative images. The copy across both planes is seen only
  through chains of two planes.

A pinhole's rays through a pane, a glass cube's reflections inside it, and a smooth-shaded scan
seen through a glass cube (many edges in every chain's beam) are checked against finite
differences.
"""

import math
from pathlib import Path

import pytest
import torch

import edgepath as ep
from edgepath import shapes
from test_mirror_edges import assert_same_derivative_image, gradients_of_both
from test_refracted_edges import _fresnel, _sky, glass_cube, matches_finite_differences

ETA = 1.5
BLACK = ep.Material(diffuse=0.0)
POSITION, LOOK_AT = torch.tensor([-1.2, 2.5, 0.9]), torch.tensor([.2, -1.2, .1])
# The pane: glass between y = -0.45 and y = -0.15, far wider than the view; the box below it.
PANE_CENTER, PANE_HALF, PANE_BOTTOM = (0., -.3, 0.), (20., .15, 20.), -.45
BOX_CENTER, BOX_HALF = (.2, -1.2, .1), (.3, .2, .25)


def _pane_camera(camera_type, shift, resolution):
    """Looking down at the box through the pane from POSITION moved by `shift` (a 0-d tensor)
    along (1, 0, 0.3), the direction kept."""
    kw = {"orthographic": dict(camera_type="orthographic", ortho_scale=0.8),
          "perspective": dict(fov=30.0)}[camera_type]
    move = shift * torch.tensor([1., 0., .3])
    return ep.Camera(position=POSITION + move, look_at=LOOK_AT + move, up=torch.tensor([0., 1., 0.]),
                     resolution=resolution, **kw)


def _pane(camera_type="orthographic", resolution=(24, 24)):
    """A black box under a pane of glass (index `eta`), seen from above at a slant under a white
    sky. Returns the scene and its parameters: the box's offset, the rise of the pane's bottom
    face (thinning it), the index and the camera's shift (tensors that require grad)."""
    offset = torch.zeros(3, requires_grad=True)
    rise = torch.zeros((), requires_grad=True)
    eta = torch.tensor(ETA, requires_grad=True)
    shift = torch.zeros((), requires_grad=True)
    bv, bi = shapes.box(BOX_CENTER, BOX_HALF)
    pv, pi = shapes.box(PANE_CENTER, PANE_HALF)
    bottom = (pv[:, 1] < PANE_CENTER[1]).float()[:, None] * torch.tensor([0., 1., 0.])
    pane = ep.Mesh(pv + bottom * rise, pi, material=ep.Material(kind="dielectric", ior=eta))
    scene = ep.Scene(_pane_camera(camera_type, shift, resolution), [pane, ep.Mesh(bv + offset, bi, material=BLACK)],
                     envmap=_sky())
    return scene, (offset, rise, eta, shift)


def _moved(params):
    """The box in air as the orthographic camera sees it through the pane of `params` (the
    parameters _pane returns): moved back by the shift of the rays, r t / (r . -n) - w t / (w .
    -n) for the pane's thickness t, w the camera's direction and r the refracted one."""
    offset, rise, eta, shift = params
    bv, bi = shapes.box(BOX_CENTER, BOX_HALF)
    w = torch.nn.functional.normalize(LOOK_AT - POSITION, dim=0)
    n = torch.tensor([0., 1., 0.])
    c1 = -(w @ n)
    r = w / eta + n * (c1 / eta - torch.sqrt(1 - (1 - c1 ** 2) / eta ** 2))
    thickness = 2 * PANE_HALF[1] - rise
    s = r * (thickness / -(r @ n)) - w * (thickness / -(w @ n))
    return ep.Scene(_pane_camera("orthographic", shift, (24, 24)), [ep.Mesh(bv + offset - s, bi, material=BLACK)],
                    envmap=_sky())


COS = float(-torch.nn.functional.normalize(LOOK_AT - POSITION, dim=0)[1])
# Many edge samples: a chained edge is sampled along its parameter (its film length varies
# along it), which costs some variance against the moved box's straight edges.
KW = dict(spp=64, max_bounces=2, seed=1, edge_samples=24 * 24 * 64 * 16)


def test_through_a_pane_the_box_is_seen_moved_and_dimmed():
    scene, params = _pane()
    a = ep.render(scene, spp=1024, max_bounces=2, seed=2).mean(-1)
    b = ep.render(_moved(params), spp=1024, max_bounces=2, seed=2).mean(-1)
    F = _fresnel(COS, ETA)
    # The sky reflected (F) and seen through the pane ((1 - F)^2: the rest is reflected inside
    # and lost at two bounces); per pixel a mean of samples of 0 and 1.
    expected = F + b * (1 - F) ** 2
    assert (b < .5).any() and (b > .5).any()
    assert (a - expected).abs().mean() < 0.006, (a - expected).abs().mean()


@pytest.mark.parametrize("param", ["box x", "box y", "box z", "thickness", "camera"])
def test_derivative_images_equal_the_moved_boxs_dimmed(param):
    """Per pixel, to 2% of the image's L1 norm (measured: 0.02-0.03% for the box, 0.4% for the
    thickness and the camera; before this term the box behind the pane had no derivative image
    at all)."""
    scene, params = _pane()
    air = _moved(params)
    unit = torch.eye(3)
    p, d = {"box x": (params[0], unit[0]), "box y": (params[0], unit[1]), "box z": (params[0], unit[2]),
            "thickness": (params[1], torch.tensor(1.)), "camera": (params[3], torch.tensor(1.))}[param]
    assert_same_derivative_image(scene, air, p, d, (1 - _fresnel(COS, ETA)) ** 2, **KW)


def test_the_index_moves_the_outline_through_a_pane():
    """The index sets the rays' shift, and so moves the box's outline as it moves the box in
    air: the primary edges' share of the derivative image (its interior term, the dimming,
    taken out: the same random numbers with and without the edges) equals the moved box's,
    dimmed, to 2% of the L1 norm."""
    scene, params = _pane()
    eta = params[2]
    a = ep.derivative_image(scene, eta, torch.tensor(1.), **KW) - \
        ep.derivative_image(scene, eta, torch.tensor(1.), primary_edges=False, **KW)
    b = ep.derivative_image(_moved(params), eta, torch.tensor(1.), **KW) * (1 - _fresnel(COS, ETA)) ** 2
    norm = b.abs().sum()
    assert norm > 1.0, norm
    assert (a - b).abs().sum() < 0.02 * norm, ((a - b).abs().sum() / norm, a.sum(), b.sum())


def _corner(camera_type):
    """A mirror floor (y = 0) and a mirror wall (x = 1, facing the camera) meeting at a right
    angle, two black boxes in the corner under a white sky, seen from above. Returns the scene,
    the same without the mirrors and with each box's three mirror images added (across the
    floor, the wall, and both), and the parameters: the boxes' offsets, the floor's height and
    the wall's shift along x, and the camera's offset."""
    placement = torch.zeros(2, requires_grad=True)
    offsets = [torch.zeros(3, requires_grad=True), torch.zeros(3, requires_grad=True)]
    camera_t = torch.zeros((), requires_grad=True)
    boxes = [shapes.box((.55, .35, .1), (.15, .15, .2)), shapes.box((-.1, .25, -.35), (.12, .1, .12))]
    placed = [(v + o, i) for (v, i), o in zip(boxes, offsets)]

    def camera():
        move = camera_t * torch.tensor([1., 0., .3])
        kw = {"perspective": dict(fov=50.0), "orthographic": dict(camera_type="orthographic", ortho_scale=2.2),
              "thinlens": dict(fov=50.0, camera_type="thinlens", aperture_radius=0.06, focus_distance=2.8)}
        return ep.Camera(position=torch.tensor([-1., 2.2, 1.6]) + move, look_at=torch.tensor([.6, .2, 0.]),
                         up=torch.tensor([0., 1., 0.]), resolution=(24, 24), **kw[camera_type])

    h, w = placement[0], placement[1]
    lift, push = torch.stack([torch.zeros(()), h, torch.zeros(())]), torch.stack([w, torch.zeros(()), torch.zeros(())])
    faces = torch.tensor([[0, 2, 1], [0, 3, 2]], dtype=torch.int32)
    mirror = ep.Material(kind="conductor", specular=1.0)
    # The floor's far side and the wall's foot follow each other: the corner stays closed.
    floor = torch.tensor([[-50., 0., -50.], [1., 0., -50.], [1., 0., 50.], [-50., 0., 50.]]) + lift + \
        torch.tensor([[0.], [1.], [1.], [0.]]) * push
    wall = torch.tensor([[1., 0., -50.], [1., 50., -50.], [1., 50., 50.], [1., 0., 50.]]) + push + \
        torch.tensor([[1.], [0.], [0.], [1.]]) * lift
    meshes = [ep.Mesh(floor, faces, material=mirror), ep.Mesh(wall, faces, material=mirror)]
    seen = ep.Scene(camera(), meshes + [ep.Mesh(v, i, material=BLACK) for v, i in placed], envmap=_sky())

    def images(v):
        across_floor = torch.stack([v[:, 0], 2 * h - v[:, 1], v[:, 2]], 1)
        across_wall = torch.stack([2 * (1 + w) - v[:, 0], v[:, 1], v[:, 2]], 1)
        across_both = torch.stack([2 * (1 + w) - v[:, 0], 2 * h - v[:, 1], v[:, 2]], 1)
        return [v, across_floor, across_wall, across_both]

    direct = ep.Scene(camera(), [ep.Mesh(x, i, material=BLACK) for v, i in placed for x in images(v)],
                      envmap=_sky())
    return seen, direct, offsets, placement, camera_t


def test_a_mirror_corner_shows_the_four_copies():
    seen, direct, *_ = _corner("perspective")
    a = ep.render(seen, spp=64, max_bounces=2)
    b = ep.render(direct, spp=64, max_bounces=2)
    differ = (a - b).abs().amax(-1)
    assert differ.max() <= 1 / 64 + 1e-6 and (differ > 1e-6).sum() <= 4, differ
    assert (a < .5).any() and (a > .5).any()


# The thin lens at four times the edge samples (its lens points add their own noise): the far
# box along x, the near box, a mirror and the camera.
CORNER_CASES = [(p, c) for c in ("perspective", "orthographic")
                for p in ("box x", "box y", "box z", "near box y", "floor", "wall", "camera")] + \
    [(p, "thinlens") for p in ("box x", "near box y", "floor", "camera")]


@pytest.mark.parametrize("param,camera_type", CORNER_CASES)
def test_derivative_images_equal_the_four_copies(param, camera_type):
    """Per pixel, to 2% of the image's L1 norm (measured: below 0.03% for the boxes, 0.2-0.8%
    for the mirrors and the camera; the thin lens, at four times the edge samples, 0.1-0.3% and
    1.3-1.9%: its lens points add their own noise). With one of the two chains left out, the
    errors were 11-24%."""
    seen, direct, offsets, placement, camera_t = _corner(camera_type)
    unit = torch.eye(3)
    p, d = {"box x": (offsets[0], unit[0]), "box y": (offsets[0], unit[1]), "box z": (offsets[0], unit[2]),
            "near box y": (offsets[1], unit[1]), "floor": (placement, torch.tensor([1., 0.])),
            "wall": (placement, torch.tensor([0., 1.])), "camera": (camera_t, torch.tensor(1.))}[param]
    kw = dict(KW, edge_samples=4 * KW["edge_samples"]) if camera_type == "thinlens" else KW
    assert_same_derivative_image(seen, direct, p, d, **kw)


def test_gradients_equal_the_four_copies():
    """The gradient pass (every parameter at once, an adjoint image) against the same of the
    four copies."""
    seen, direct = gradients_of_both(lambda: _corner("perspective"), **KW)
    assert direct.abs().max() > 1.0
    assert torch.allclose(seen, direct, rtol=0.01, atol=0.01 * float(direct.abs().max())), (seen, direct)


@pytest.mark.parametrize("param", ["box x", "thickness"])
def test_a_pinhole_through_a_pane_matches_finite_differences(param):
    """Each ray through the pane is moved by its own vector. Image sums, 16 x 16; derivative 4
    seeds x 256 spp, finite differences (step 0.025) 4 seeds x 4096 spp. Measured (8 seeds, and
    16 x 8192 spp): the box along x 8.10 +- 0.01 against 8.01 +- 0.28, the thickness 13.15 +-
    0.47 against 13.14 +- 0.13 (before this term: 0 for both)."""
    scene, params = _pane("perspective", (16, 16))
    box, pane = scene.meshes[1].vertices, scene.meshes[0].vertices
    bottom = (pane[:, 1] < PANE_CENTER[1]).float()[:, None] * torch.tensor([0., 1., 0.])
    param, direction = {"box x": (box, torch.tensor([1., 0., 0.]).expand(box.shape)),
                        "thickness": (pane, bottom)}[param]
    matches_finite_differences(scene, param, direction, step=0.025, spp=256, fd_spp=4096, seeds=4, fd_seeds=4,
                               floor=4.0)


def test_a_glass_cube_at_three_bounces_matches_finite_differences():
    """A glass cube (flat faces, turned) before a random sky, moved along x, at three bounces:
    its edges seen from inside reflected in a face after entering through another (the chains
    of a refraction and a reflection), beside those seen through one face. Image sums, 24 x 24;
    derivative 8 seeds x 256 spp, finite differences (step 0.005) 8 seeds x 2048 spp. Measured
    at 32 x 32: 217.6 +- 3.8 against 219.0 +- 3.4 (before this term: 167.8 +- 0.9); a faceted
    glass sphere (4 x 8) 257.5 +- 3.9 against 258.5 +- 4.7 (before: 223.6)."""
    scene = glass_cube()
    matches_finite_differences(scene, scene.meshes[0].vertices, torch.tensor([1., 0., 0.]).expand(8, 3), step=0.005,
                               spp=256, fd_spp=2048, seeds=8, fd_seeds=8, floor=10.0, bounces=3)


def _icosphere(subdivisions):
    """A unit icosahedron's faces split in four `subdivisions` times, the new vertices pushed out
    to the sphere: flat faces of nearly equal size, no poles."""
    t = (1 + 5 ** .5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [torch.nn.functional.normalize(torch.tensor(p, dtype=torch.float64), dim=0) for p in v]
    for _ in range(subdivisions):
        middle, faces = {}, []

        def between(a, b):
            if (min(a, b), max(a, b)) not in middle:
                v.append(torch.nn.functional.normalize(v[a] + v[b], dim=0))
                middle[(min(a, b), max(a, b))] = len(v) - 1
            return middle[(min(a, b), max(a, b))]

        for a, b, c in f:
            ab, bc, ca = between(a, b), between(b, c), between(c, a)
            faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = faces
    return torch.stack(v).float(), torch.tensor(f, dtype=torch.int32)


@pytest.mark.slow
def test_a_faceted_glass_ball_at_three_bounces_matches_finite_differences():
    """A glass ball of 320 flat faces before a random sky, moved along x, at three bounces: its
    many planes make many chains, most of which see nothing (a beam through one small face
    meets a few faces behind it). Image sums, 16 x 16; derivative 12 seeds x 64 spp at 16 edge
    samples per pixel per sample, finite differences (step 0.005) 6 seeds x 4096 spp: about 12
    s. Measured (16 seeds, 8 x 4096 spp): 40.7 +- 4.6 against 38.2 +- 1.4; before chains 66.7 +-
    3.7 (the reflections inside left out), which fails here. At 32 x 32: 184 +- 22 against 163
    +- 4 (before chains: 256)."""
    v, i = _icosphere(2)
    ball = ep.Mesh(v * 0.5, i, material=ep.Material(kind="dielectric", ior=1.5))
    camera = ep.Camera(position=torch.tensor([0., .3, 2.5]), look_at=torch.zeros(3), resolution=(16, 16), fov=30.0)
    sky = ep.EnvironmentMap(torch.rand(8, 16, 3, generator=torch.Generator().manual_seed(0)))
    scene = ep.Scene(camera, [ball], envmap=sky)
    matches_finite_differences(scene, ball.vertices, torch.tensor([1., 0., 0.]).expand(v.shape), step=0.005, spp=64,
                               fd_spp=4096, seeds=12, fd_seeds=6, floor=20.0, bounces=3,
                               edge_samples=16 * 16 * 64 * 16)


SHARED = Path(__file__).resolve().parents[3] / "shared"


@pytest.mark.slow
@pytest.mark.parametrize("camera_type", ["perspective", "thinlens"])
def test_a_smooth_scan_behind_a_glass_cube_matches_finite_differences(camera_type):
    """The scanned bunny (69,451 triangles, smooth normals, black) behind the glass cube, seen
    through two of its faces, moved along x; two bounces, 32 x 32, the image summed with a ramp
    across it. Each chain of two faces sees most of the bunny's 104,065 edges; set up every one,
    the chains' budget (2^18 set-ups) kept only the best four of them, and the derivative was
    39% short: -12.30 +- 0.23 against -20.18 +- 0.11 (16 x 64 spp; finite differences 8 x 4096
    spp, step 0.005), which fails here. The smooth edges that do not fold seen from a chain's
    beam are kept by roulette (as curved faces keep them), so the budget reaches the chains
    that see the bunny: -19.61 +- 1.04 (16 x 64 spp), -19.99 +- 0.79 (8 x 128 spp), at the same
    cost. A thin lens (radius 0.05, focused at 2.5) had no beams: its chains tied in rank, each
    set up every edge, and the budget took three that saw nothing of the bunny: 6.70 +- 0.93
    against -20.90 +- 0.17. Its beams now follow the corner rays from eight points of the
    aperture's rim too: -20.88 +- 1.28. Derivative 8 seeds x 128 spp, finite differences 4 seeds
    x 4096 spp: about 20 s each."""
    path = SHARED / "data" / "bunny.ply"
    if not path.exists():
        pytest.skip(f"test data not found: {path}")
    bunny = ep.load_ply(path)
    v, i = bunny.vertices, bunny.indices.long()
    v = (v - v.mean(0)) / (v.max(0).values - v.min(0).values).max() * 0.8 + torch.tensor([0., -.1, -.9])
    face_normals = torch.cross(v[i[:, 1]] - v[i[:, 0]], v[i[:, 2]] - v[i[:, 0]], dim=1)
    normals = torch.zeros_like(v).index_add_(0, i.reshape(-1), face_normals.repeat_interleave(3, 0))
    normals = torch.nn.functional.normalize(normals + 1e-12, dim=1)
    cube = glass_cube()
    lens = dict(camera_type="thinlens", aperture_radius=0.05, focus_distance=2.5) if camera_type == "thinlens" else {}
    camera = ep.Camera(position=torch.tensor([0., .3, 2.5]), look_at=torch.zeros(3), resolution=(32, 32), fov=30.0,
                       **lens)
    scan = ep.Mesh(v, bunny.indices, normals=normals, material=BLACK)
    scene = ep.Scene(camera, [cube.meshes[0], scan], envmap=cube.envmap)
    ramp = torch.linspace(-1, 1, 32)[None, :, None]
    along_x = torch.zeros_like(v)
    along_x[:, 0] = 1.0
    d = torch.tensor([float((ep.derivative_image(scene, scan.vertices, along_x, spp=128, max_bounces=2, seed=s)
                             * ramp).sum()) for s in range(8)], dtype=torch.float64)
    f = torch.tensor([float((ep.finite_difference_image(scene, scan.vertices, along_x, eps=0.01, spp=4096,
                                                        max_bounces=2, seed=100 + s) * ramp).sum())
                      for s in range(4)], dtype=torch.float64)
    error = math.sqrt(float(d.var()) / len(d) + float(f.var()) / len(f))
    assert abs(float(f.mean())) > 10.0
    assert abs(float(d.mean() - f.mean())) < 4 * error + 0.05 * abs(float(f.mean())), (d, f, error)
