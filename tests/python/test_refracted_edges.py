"""Edges seen through flat glass: the boundary term of the outlines the camera sees refracted by
a flat face of smooth glass (edges/primary.cpp, "Refraction"), here a box seen under water.

Closed form: an orthographic camera's parallel rays all refract into one direction at a flat
water surface, so what lies under it is seen as if sheared (every point moved along the
surface, in proportion to its depth, onto the straight ray that shows it), and dimmed by the
Fresnel transmittance on the way in and again on the way out through the water's flat bottom:
(1 - F)^2 at the one angle of incidence, beside the sky's reflection F everywhere. Under a
constant sky, the outline of a black box under water has every derivative image of the
sheared box in air, times (1 - F)^2. A pinhole camera's rays bend by different
angles: checked against finite differences.
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes
from test_mirror_edges import assert_same_derivative_image

ETA = 1.33
BLACK = ep.Material(diffuse=0.0)
POSITION, LOOK_AT = torch.tensor([-1.2, 2.5, 0.9]), torch.tensor([.2, -1.2, .1])


def _camera(camera_type, shift, resolution=(24, 24)):
    """Looking at the box from POSITION moved by `shift` (a 0-d tensor) along (1, 0, 0.3), the
    direction kept."""
    kw = {"orthographic": dict(camera_type="orthographic", ortho_scale=0.8), "perspective": dict(fov=30.0),
          "thinlens": dict(fov=30.0, camera_type="thinlens", aperture_radius=0.1, focus_distance=4.0)}[camera_type]
    move = shift * torch.tensor([1., 0., .3])
    return ep.Camera(position=POSITION + move, look_at=LOOK_AT + move, up=torch.tensor([0., 1., 0.]),
                     resolution=resolution, **kw)


def _sky():
    return ep.EnvironmentMap(torch.full((1, 1, 3), 1.))


def _fresnel(ci, eta):
    ct = math.sqrt(1 - (1 - ci * ci) / eta ** 2)
    return ((ci - eta * ct) ** 2 / (ci + eta * ct) ** 2 + (eta * ci - ct) ** 2 / (eta * ci + ct) ** 2) / 2


def _water(camera_type="orthographic", resolution=(24, 24), offset=(0., 0., 0.), level=0.0, eta=ETA):
    """A black box under a flat water surface (a large box of glass of index `eta`, its top at
    y = `level`), seen from above at a slant under a white sky. Returns the scene and its
    parameters: the box's offset, the level, the index and the camera's shift (tensors that
    require grad)."""
    offset = torch.tensor(offset, requires_grad=True)
    shift = torch.zeros((), requires_grad=True)
    level = torch.tensor(level, requires_grad=True)
    eta = torch.tensor(eta, requires_grad=True)
    bv, bi = shapes.box((.2, -1.2, .1), (.3, .2, .25))
    wv, wi = shapes.box((0., -3., 0.), (20., 3., 20.))
    lift = torch.stack([torch.zeros(()), level, torch.zeros(())])
    water = ep.Mesh(wv + lift, wi, material=ep.Material(kind="dielectric", ior=eta))
    scene = ep.Scene(_camera(camera_type, shift, resolution), [water, ep.Mesh(bv + offset, bi, material=BLACK)],
                     envmap=_sky())
    return scene, (offset, level, eta, shift)


def _sheared(params):
    """The box in air as the orthographic camera sees it under the water of `params` (the
    parameters _water returns, of that scene): each point moved along the surface by its depth
    times (w / (w . n) - r / (r . n)), w the camera's direction, r the refracted one."""
    offset, level, eta, shift = params
    bv, bi = shapes.box((.2, -1.2, .1), (.3, .2, .25))
    v = bv + offset
    w = torch.nn.functional.normalize(LOOK_AT - POSITION, dim=0)
    n = torch.tensor([0., 1., 0.])
    c1 = -(w @ n)
    r = w / eta + n * (c1 / eta - torch.sqrt(1 - (1 - c1 ** 2) / eta ** 2))
    shear = w / (w @ n) - r / (r @ n)
    return ep.Scene(_camera("orthographic", shift), [ep.Mesh(v + (v[:, 1:2] - level) * shear, bi, material=BLACK)],
                    envmap=_sky())


# Many edge samples: a refracted edge is sampled along its parameter (its film length varies
# along it), which costs some variance against the sheared box's straight edges.
KW = dict(spp=64, max_bounces=2, seed=1, edge_samples=24 * 24 * 64 * 16)
COS = float(-torch.nn.functional.normalize(LOOK_AT - POSITION, dim=0)[1])


def test_under_water_the_box_is_seen_sheared_and_dimmed():
    scene, params = _water()
    air = _sheared(params)
    a = ep.render(scene, spp=1024, max_bounces=2, seed=2).mean(-1)
    b = ep.render(air, spp=1024, max_bounces=2, seed=2).mean(-1)
    F = _fresnel(COS, ETA)
    # The sky reflected (F) and seen through the water ((1 - F)^2: the rest is reflected inside
    # and lost at two bounces); per pixel a mean of samples of 0 and 1 (standard deviation
    # 0.0044 in the sky).
    expected = F + b * (1 - F) ** 2
    assert (b < .5).any() and (b > .5).any()
    assert (a - expected).abs().mean() < 0.006, (a - expected).abs().mean()


@pytest.mark.parametrize("param", ["box x", "box y", "box z", "level", "camera"])
def test_derivative_images_equal_the_sheared_boxs_dimmed(param):
    """Per pixel, to 2% of the image's L1 norm (measured 0.2-0.9%; before this term the box
    under water had no derivative image at all, and the level's was zero)."""
    scene, params = _water()
    air = _sheared(params)
    unit = torch.eye(3)
    p, d = {"box x": (params[0], unit[0]), "box y": (params[0], unit[1]), "box z": (params[0], unit[2]),
            "level": (params[1], torch.tensor(1.)), "camera": (params[3], torch.tensor(1.))}[param]
    assert_same_derivative_image(scene, air, p, d, (1 - _fresnel(COS, ETA)) ** 2, **KW)


def test_the_index_moves_the_outline():
    """The index bends the rays, and so moves the box's outline as it shears the box in air: the
    primary edges' share of the derivative image (its interior term, the dimming, taken out: the
    same random numbers with and without the edges) equals the sheared box's, dimmed, to 2%
    of the L1 norm (measured 0.9%). Finite differences check the whole below."""
    scene, params = _water()
    air = _sheared(params)
    eta = params[2]
    a = ep.derivative_image(scene, eta, torch.tensor(1.), **KW) - \
        ep.derivative_image(scene, eta, torch.tensor(1.), primary_edges=False, **KW)
    b = ep.derivative_image(air, eta, torch.tensor(1.), **KW) * (1 - _fresnel(COS, ETA)) ** 2
    norm = b.abs().sum()
    assert norm > 1.0, norm
    assert (a - b).abs().sum() < 0.02 * norm, ((a - b).abs().sum() / norm, a.sum(), b.sum())


def matches_finite_differences(scene, param, direction, step, spp, fd_spp, seeds, fd_seeds, floor, bounces=2,
                               **kw):
    """The derivative image's sum (`seeds` renders at `spp`, with options `kw`) against the
    central finite difference of the image's sum (ep.finite_difference_image, steps of
    +-`step`, `fd_seeds` renders at `fd_spp`) at `bounces` bounces: within 4 standard errors
    plus 5%, the latter above `floor` in magnitude."""
    d = torch.tensor([float(ep.derivative_image(scene, param, direction, spp=spp, max_bounces=bounces, seed=s,
                                                **kw).sum())
                      for s in range(seeds)], dtype=torch.float64)
    f = torch.tensor([float(ep.finite_difference_image(scene, param, direction, eps=2 * step, spp=fd_spp,
                                                       max_bounces=bounces, seed=100 + s).sum())
                      for s in range(fd_seeds)], dtype=torch.float64)
    error = math.sqrt(float(d.var()) / len(d) + float(f.var()) / len(f))
    assert abs(float(f.mean())) > floor
    assert abs(float(d.mean() - f.mean())) < 4 * error + 0.05 * abs(float(f.mean())), (d, f, error)


@pytest.mark.parametrize("camera_type,param", [("perspective", "box x"), ("perspective", "level"),
                                               ("perspective", "index"), ("thinlens", "box x")])
def test_perspective_cameras_match_finite_differences(camera_type, param):
    """Each ray bends by its own angle (and a thin lens's by its lens point's too). Image sums,
    derivative 4 seeds x 256 spp, finite differences (step 0.05) 6 seeds x 4096 spp, 16 x 16.
    Measured: the box along x 22.1 against 21.4 +- 0.3 at 24 x 24 (before: 0), the index -172.2
    against -173.8 +- 0.6 (before: -141.6: its interior term only)."""
    scene, params = _water(camera_type, (16, 16))
    box, water = scene.meshes[1].vertices, scene.meshes[0].vertices
    param, direction = {"box x": (box, torch.tensor([1., 0., 0.]).expand(box.shape)),
                        "level": (water, torch.tensor([0., 1., 0.]).expand(water.shape)),
                        "index": (params[2], torch.tensor(1.))}[param]
    matches_finite_differences(scene, param, direction, step=0.05, spp=256, fd_spp=4096, seeds=4, fd_seeds=6,
                               floor=1.0)


def test_a_glass_cube_matches_finite_differences():
    """A glass cube (flat faces, turned) before a random sky, moved along x, at two bounces (in
    through a face, out through another: the edges of its far faces seen through its near ones,
    refracted once; the paths reflected inside, whose edges are left out, end there). Image
    sums, 24 x 24; derivative 8 seeds x 256 spp, finite differences (step 0.005) 8 seeds x 2048
    spp. Measured at 32 x 32: 227.3 +- 0.9 against 231.7 +- 4.1 (before this term: 325.5); a
    faceted glass sphere (4 x 8) 248.3 +- 1.8 against 254.3 +- 5.9 (before: 340.6)."""
    scene = glass_cube()
    matches_finite_differences(scene, scene.meshes[0].vertices, torch.tensor([1., 0., 0.]).expand(8, 3), step=0.005,
                               spp=256, fd_spp=2048, seeds=8, fd_seeds=8, floor=10.0)


def glass_cube():
    """A glass cube (flat faces, turned) before a random sky, 24 x 24."""
    turn = torch.tensor([[0.8, 0., 0.6], [0., 1., 0.], [-0.6, 0., 0.8]]) @ \
        torch.tensor([[1., 0., 0.], [0., 0.9, -0.436], [0., 0.436, 0.9]])
    v, i = shapes.box((0., 0., 0.), (.4, .4, .4))
    cube = ep.Mesh(v @ turn.T, i, material=ep.Material(kind="dielectric", ior=1.5))
    camera = ep.Camera(position=torch.tensor([0., .3, 2.5]), look_at=torch.zeros(3), resolution=(24, 24), fov=30.0)
    sky = ep.EnvironmentMap(torch.rand(8, 16, 3, generator=torch.Generator().manual_seed(0)))
    return ep.Scene(camera, [cube], envmap=sky)
