"""Edges seen in planar mirrors: the boundary term of the outlines the camera sees reflected in
flat smooth faces (edges/primary.cpp, SmoothPlanes).

Closed form: a perfect mirror (a conductor of reflectance 1) under a constant sky shows the
scene mirrored across its plane. Seen only through the mirror, the scene above it renders the
same image as its mirror image seen directly, with no mirror: and so must every derivative
image, whatever the parameter (the objects' positions, the mirror's height, which moves the
mirror image twice as far, its tilt, and the camera). The direct one comes from the primary edges,
checked against closed forms in test_primary_edges.py; the mirrored one from the new term
alone, since the objects are black and the sky constant (no interior term).
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes

BLACK = ep.Material(diffuse=0.0)
# Many edge samples: the virtual edges get samples of their own, apart from the mirror
# images' (direct) ones, so the two are independent estimates.
KW = dict(spp=64, max_bounces=1, seed=1, edge_samples=24 * 24 * 64 * 16)


def _mirror_frame(placement):
    """The mirror's rotation about the z axis by placement[1] (radians), and its point at the
    height placement[0] above the origin."""
    c, s, zero, one = torch.cos(placement[1]), torch.sin(placement[1]), torch.zeros(()), torch.ones(())
    turn = torch.stack([torch.stack([c, -s, zero]), torch.stack([s, c, zero]), torch.stack([zero, zero, one])])
    return turn, torch.stack([zero, placement[0], zero])


def _mirror_floor(placement, material, shading_normals=False):
    """A large square mirror (facing +y at no tilt) placed by _mirror_frame(placement); with
    `shading_normals`, its vertices' normals given (its plane's, turned with it)."""
    v = torch.tensor([[-50., 0., -50.], [50., 0., -50.], [50., 0., 50.], [-50., 0., 50.]])
    turn, point = _mirror_frame(placement)
    normals = turn[:, 1].expand(4, 3) if shading_normals else None
    return ep.Mesh(v @ turn.T + point, torch.tensor([[0, 2, 1], [0, 3, 2]], dtype=torch.int32), normals=normals,
                   material=material)


def _scenes(material=None, camera_type="perspective", glowing=False, far_offset=(0., 0., 0.), shading_normals=False):
    """A mirror floor (placed by a height and a tilt, both 0) seen from above (the camera sees
    nothing else), two black boxes above it under a white sky: one out of the camera's view but
    seen in the mirror, one in view that hides part of the mirror and shows in it. Returns the
    scene, the same without the mirror and with the boxes' mirror images added (the boxes'
    vertices mirrored across its plane), and the parameters: the boxes' offsets, the mirror's
    placement and the camera's offset. The orthographic camera looks down at a slant: it sees
    the boxes and their images side by side; the thin lens keeps the pinhole's place, out of
    focus. `glowing`: the far box emits (on both sides: the mirror image's faces point
    inwards). `far_offset`: the far box's offset's value. `shading_normals`: the mirror's
    vertices carry normals (then it is a curved face to the renderer, test_curved_edges.py)."""
    placement = torch.zeros(2, requires_grad=True)
    offsets = [torch.tensor(far_offset, requires_grad=True), torch.zeros(3, requires_grad=True)]
    camera_t = torch.zeros((), requires_grad=True)
    boxes = [shapes.box((1.0, 1.5, 0.1), (.2, .2, .2)), shapes.box((-.2, .4, -.1), (.15, .1, .12))]
    placed = [(v + o, i) for (v, i), o in zip(boxes, offsets)]

    def camera():
        move = camera_t * torch.tensor([1., 0., .3])
        if camera_type == "orthographic":
            return ep.Camera(position=torch.tensor([-1.5, 3., .7]) + move, look_at=torch.tensor([.5, 0., 0.]),
                             up=torch.tensor([0., 0., -1.]), resolution=(24, 24), camera_type="orthographic",
                             ortho_scale=1.6)
        lens = dict(camera_type="thinlens", aperture_radius=0.08, focus_distance=4.0) \
            if camera_type == "thinlens" else {}
        return ep.Camera(position=torch.tensor([0., 3., 0.]) + move, look_at=torch.tensor([.1, 0., 0.]),
                         up=torch.tensor([0., 0., -1.]), resolution=(24, 24), fov=40.0, **lens)

    def sky():
        return ep.EnvironmentMap(torch.full((1, 1, 3), 1.))

    mirror = _mirror_floor(placement, material or ep.Material(kind="conductor", specular=1.0), shading_normals)
    def mesh(v, i, k):
        if glowing and k == 0:
            return ep.Mesh(v, i, material=BLACK, emission=torch.tensor([2., 3., 1.]), two_sided_emission=True)
        return ep.Mesh(v, i, material=BLACK)

    seen = ep.Scene(camera(), [mirror] + [mesh(v, i, k) for k, (v, i) in enumerate(placed)], envmap=sky())
    turn, point = _mirror_frame(placement)
    normal = turn[:, 1]

    def image(v):
        return v - 2 * ((v - point) @ normal)[:, None] * normal

    direct = ep.Scene(camera(), [mesh(v, i, k) for k, (v, i) in enumerate(placed)] +
                      [mesh(image(v), i, k) for k, (v, i) in enumerate(placed)], envmap=sky())
    return seen, direct, offsets, placement, camera_t


@pytest.mark.parametrize("camera_type,glowing", [("perspective", False), ("orthographic", False),
                                                 ("thinlens", False), ("perspective", True)])
def test_the_mirror_shows_the_mirror_image(camera_type, glowing):
    seen, direct, *_ = _scenes(camera_type=camera_type, glowing=glowing)
    a = ep.render(seen, spp=64, max_bounces=1)
    b = ep.render(direct, spp=64, max_bounces=1)
    # The same but where a sample passes an outline within rounding (a reflected ray is not the
    # straight one): a sample of 64 in a few pixels (at 3 seeds of 8 in the orthographic view).
    differ = (a - b).abs().amax(-1)
    assert differ.max() <= 1 / 64 + 1e-6 and (differ > 1e-6).sum() <= 4, differ
    assert (a < .5).any() and (a > .5).any()  # both boxes' images and the sky


@pytest.mark.parametrize("camera_type", ["perspective", "orthographic", "thinlens", "perspective, glowing"])
@pytest.mark.parametrize("param", ["box x", "box y", "box z", "near box y", "mirror height", "mirror tilt",
                                   "camera"])
def test_derivative_images_equal_the_mirror_images(param, camera_type):
    """Per pixel, to 2% of the image's L1 norm (measured: below 0.05%, the thin lens's up to 1%;
    before this term the mirrored derivative images held only the near box's own outline: for
    the far box, nothing at all)."""
    seen, direct, offsets, placement, camera_t = _scenes(camera_type=camera_type.split(",")[0],
                                                      glowing=camera_type.endswith("glowing"))
    unit = torch.eye(3)
    p, d = {"box x": (offsets[0], unit[0]), "box y": (offsets[0], unit[1]), "box z": (offsets[0], unit[2]),
            "near box y": (offsets[1], unit[1]), "mirror height": (placement, torch.tensor([1., 0.])),
            "mirror tilt": (placement, torch.tensor([0., 1.])),
            "camera": (camera_t, torch.tensor(1.))}[param]
    assert_same_derivative_image(seen, direct, p, d, **KW)


def assert_same_derivative_image(seen, direct, param, direction, scale=1.0, **kw):
    """The derivative image of scene `seen` along `direction` of `param` against that of
    scene `direct` times `scale`, per pixel: within 2% of the latter's L1 norm (above 1)."""
    a = ep.derivative_image(seen, param, direction, **kw)
    b = ep.derivative_image(direct, param, direction, **kw) * scale
    norm = b.abs().sum()
    assert norm > 1.0, norm
    assert (a - b).abs().sum() < 0.02 * norm, ((a - b).abs().sum() / norm, a.sum(), b.sum())


def gradients_of_both(scenes, **kw):
    """The gradient pass (an adjoint image of 24 x 24, every parameter at once) of each of the
    two scenes that scenes() returns first, beside their parameters (two offsets, a placement
    and the camera's offset): the two gradients, each one vector."""
    grads = []
    for scene_index in range(2):
        made = scenes()
        scene, (offsets, placement, camera_t) = made[scene_index], made[2:]
        g = torch.Generator().manual_seed(4)
        adjoint = torch.rand(24, 24, 3, generator=g) - .5
        (ep.render(scene, **kw) * adjoint).sum().backward()
        grads.append(torch.cat([offsets[0].grad, offsets[1].grad, placement.grad, camera_t.grad[None]]))
    return grads


def test_gradients_equal_the_mirror_images():
    """The gradient pass (every parameter at once, an adjoint image) against the same of the
    mirror images: the offsets, the mirror's height and tilt, and the camera."""
    seen, direct = gradients_of_both(_scenes, **KW)
    assert direct.abs().max() > 1.0
    assert torch.allclose(seen, direct, rtol=0.01, atol=0.01 * float(direct.abs().max())), (seen, direct)


@pytest.mark.parametrize("kind", ["conductor", "dielectric", "plastic"])
def test_the_step_is_the_reflected_lobes_weight(kind):
    """Another reflectance scales the step in the mirror by the lobe's weight: Schlick's with 0.5
    at normal incidence, the dielectric's Fresnel reflectance, a smooth plastic's coating (its
    Fresnel reflectance too, over a black base). The camera sees the far box's image at about
    13 degrees from the normal, where those are 0.5 (to 1e-6), 0.0401 and 0.0401."""
    material = {"conductor": ep.Material(kind="conductor", specular=0.5),
                "dielectric": ep.Material(kind="dielectric", ior=1.5),
                "plastic": ep.Material(kind="plastic", diffuse=0.0, specular=1.0, roughness=0.0, ior=1.5)}[kind]
    seen, _, offsets, _, _ = _scenes(material)
    unit_mirror, _, offsets1, _, _ = _scenes()
    a = ep.derivative_image(seen, offsets[0], torch.tensor([1., 0., 0.]), **KW).sum()
    b = ep.derivative_image(unit_mirror, offsets1[0], torch.tensor([1., 0., 0.]), **KW).sum()
    # The far box's image is seen from the camera through the mirror at cos ~ 0.976.
    ci, eta = 0.976, 1.5
    ct = math.sqrt(1 - (1 - ci * ci) / eta ** 2)
    fresnel = ((ci - eta * ct) ** 2 / (ci + eta * ct) ** 2 + (eta * ci - ct) ** 2 / (eta * ci + ct) ** 2) / 2
    expected = 0.5 if kind == "conductor" else fresnel
    assert abs(b) > 1.0
    assert abs(float(a / b) - expected) < 0.03 * expected, (float(a / b), expected)


def test_a_one_sided_mirror_seen_from_behind_shows_nothing():
    """Seen from below, a one-sided mirror is black, and its plane has no mirrored edges: only
    the boxes' own outlines against it remain, the same as with a black floor."""
    def scene(material):
        camera = ep.Camera(position=torch.tensor([0., -3., 0.]), look_at=torch.tensor([.1, 0., 0.]),
                           up=torch.tensor([0., 0., -1.]), resolution=(16, 16), fov=40.0)
        v, i = shapes.box((0., -1., 0.), (.3, .3, .3))
        box = ep.Mesh(v.clone().requires_grad_(), i, material=ep.Material(diffuse=0.5))
        floor = _mirror_floor(torch.zeros(2), material)
        return ep.Scene(camera, [floor, box], envmap=ep.EnvironmentMap(torch.full((1, 1, 3), 1.))), box
    grads = []
    for material in (ep.Material(kind="conductor", specular=1.0), BLACK):
        s, box = scene(material)
        grads.append(ep.derivative_image(s, box.vertices, torch.ones(8, 3), **KW))
    assert grads[1].abs().sum() > 1.0
    assert torch.equal(grads[0], grads[1])



def test_a_box_seen_only_in_the_mirror_is_moved_back_to_its_place():
    """An inverse problem: the far box, which the camera sees only in the mirror, starts 0.15 off
    along x and z; the image's squared error brings it back within 0.03 (before this term its
    gradient was zero and it did not move)."""
    target = ep.render(_scenes()[0], spp=16, max_bounces=1, seed=0).detach()
    shift = torch.tensor([.15, -.15], requires_grad=True)
    optimizer = torch.optim.Adam([shift], lr=0.01)
    for step in range(80):
        optimizer.zero_grad()
        seen, _, offsets, _, _ = _scenes(far_offset=(float(shift[0]), 0., float(shift[1])))
        image = ep.render(seen, spp=8, max_bounces=1, seed=step + 1)
        ((image - target) ** 2).sum().backward()
        shift.grad = offsets[0].grad[[0, 2]]
        optimizer.step()
    assert shift.detach().norm() < 0.03, shift
