"""Direct light from area lights and an environment map in the same scene.

A floor, a box, a small bright lamp and a dim uniform sky. Next-event estimation takes one
sample on the area lights and one on the environment at every vertex, so lighting stays linear
in the lights (render(sky + lamp) = render(sky) + render(lamp) in expectation) and the noise of
both together is that of each alone added up: picking one of the two at random, as the renderer
did before, made the lamp-lit image at 4 spp about 100 times noisier than the lamp alone.
"""

import torch

import edgepath as ep
from edgepath import shapes

RES = (24, 32)


def box(center, size):
    lo = [c - size / 2 for c in center]
    hi = [c + size / 2 for c in center]
    v = torch.tensor([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    # corners: index = x + 2 y + 4 z (0: low, 1: high); faces wound outwards
    f = [[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
         [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]
    return v, torch.tensor(f, dtype=torch.int32)


def lamp_scene(sky=True, lamp=True, emission=None, env_scale=None):
    fv, fi, _, _ = shapes.grid((6.0, 6.0))
    bv, bi = box((0.3, 0.4, 0.0), 0.8)
    # A 0.1 x 0.1 lamp facing down (-y), 2 above the floor.
    lv, li = shapes.quad([[-1.05, 2, -0.05], [-0.95, 2, -0.05], [-0.95, 2, 0.05], [-1.05, 2, 0.05]])
    if emission is None:
        emission = torch.full((3,), 2000.0 if lamp else 0.0)
    meshes = [ep.Mesh(fv, fi, material=ep.Material(diffuse=0.6)),
              ep.Mesh(bv, bi, material=ep.Material(diffuse=0.5)),
              ep.Mesh(lv, li, emission=emission)]
    cam = ep.Camera(position=torch.tensor([0.0, 3.0, 5.0]), look_at=torch.tensor([0.0, 0.3, 0.0]), fov=45.0,
                    resolution=RES)
    envmap = None
    if sky:
        envmap = ep.EnvironmentMap(torch.full((1, 1, 3), 0.05), scale=1.0 if env_scale is None else env_scale)
    return ep.Scene(cam, meshes, envmap)


def test_lamp_faces_the_floor():
    # The lamp lights the floor below it (its face normal points down).
    lit = ep.render(lamp_scene(sky=False), spp=4, seed=0)
    assert lit.mean() > 0.05


def test_sky_and_lamp_add_up():
    # Lighting is linear: the mean image with both lights equals the sum of the mean images
    # with each alone, within the statistical error of independent seeds.
    seeds = range(6)
    both = torch.stack([ep.render(lamp_scene(), spp=16, seed=100 + s).double() for s in seeds])
    sky = torch.stack([ep.render(lamp_scene(lamp=False), spp=16, seed=200 + s).double() for s in seeds])
    lamp = torch.stack([ep.render(lamp_scene(sky=False), spp=16, seed=300 + s).double() for s in seeds])
    n = len(seeds)
    # Per-pixel check, then the image total.
    diff = both.mean(0) - sky.mean(0) - lamp.mean(0)
    se = ((both.var(0) + sky.var(0) + lamp.var(0)) / n).sqrt()
    z = diff / se.clamp_min(1e-6)
    assert (z.abs() > 5).float().mean() < 0.01, f"{int((z.abs() > 5).sum())} pixels off by > 5 standard errors"
    tb, ts, tl = both.sum((1, 2, 3)), sky.sum((1, 2, 3)), lamp.sum((1, 2, 3))
    d = tb.mean() - ts.mean() - tl.mean()
    se_total = ((tb.var() + ts.var() + tl.var()) / n).sqrt()
    assert abs(d) < 4 * se_total, f"total: {d:.4g} +- {se_total:.3g} (sum {tb.mean():.4g})"
    assert sky.mean() > 0.02 and lamp.mean() > 0.1  # both lights contribute


def pixel_variance(scene, spp, seeds):
    images = torch.stack([ep.render(scene, spp=spp, seed=s).double() for s in seeds])
    return images.var(0).mean().item()


def test_sky_does_not_make_the_lamp_noisier():
    # Per-pixel variance over 16 seeds at 4 spp. With one sample on each kind of light the
    # variances add up (measured ratio: 0.99); picking the sky or the lamp at random with
    # probability 1/2, as the renderer did before, gives 61 here.
    seeds = list(range(16))
    v_both = pixel_variance(lamp_scene(), 4, seeds)
    v_sky = pixel_variance(lamp_scene(lamp=False), 4, seeds)
    v_lamp = pixel_variance(lamp_scene(sky=False), 4, seeds)
    ratio = v_both / (v_sky + v_lamp)
    assert 0.6 < ratio < 1.5, f"variance with both lights / sum of each alone = {ratio:.3g}"


def test_gradients_of_lamp_emission_and_sky_scale():
    # The image is linear in the lamp's emission and in the sky's scale, and neither moves a
    # sample (the light choice no longer depends on them), so a central difference with the
    # same seed is exact up to rounding: the gradient pass, replaying the same paths
    # (backward_seed=seed), must match it closely. The differences are finite_difference_image's,
    # whose images have the paths a gradient pass retraces (an image rendered with no gradient
    # to follow leaves the uniform sky to the BSDF's samples: other paths).
    emission = torch.full((3,), 2000.0, requires_grad=True)
    scale = torch.tensor([1.0], requires_grad=True)
    weights = torch.linspace(0.5, 1.5, RES[0] * RES[1] * 3).reshape(RES[0], RES[1], 3)
    img = ep.render(lamp_scene(emission=emission, env_scale=scale), spp=4, seed=7, backward_seed=7)
    (img * weights).sum().backward()

    def fd(param, h, scene):  # along all ones: the sum of the partial derivatives
        d = ep.finite_difference_image(scene, param, torch.ones_like(param), eps=2 * h, spp=4, seed=7)
        return (d.double() * weights).sum().item()

    scene = lamp_scene(emission=torch.full((3,), 2000.0), env_scale=torch.tensor([1.0]))
    fd_e = fd(scene.meshes[2].emission, 10.0, scene)
    g_e = emission.grad.sum().item()
    assert abs(g_e - fd_e) < 2e-3 * abs(fd_e), (g_e, fd_e)
    fd_s = fd(scene.envmap.scale, 0.05, scene)
    g_s = scale.grad.item()
    assert abs(g_s - fd_s) < 2e-3 * abs(fd_s), (g_s, fd_s)
    assert g_e > 0 and g_s > 0


def test_an_image_alone_leaves_a_uniform_sky_to_the_bsdf():
    # docs/conventions.md, "How lights are sampled": a flat-shaded sphere (convex) of albedo 0.6
    # under a white uniform sky. In an image no gradient follows, the sky is left to the BSDF's
    # samples, each of which escapes with the weight 0.6: inside the outline every pixel is 0.6
    # to rounding. So is an image whose gradient is wanted, its gradient pass having a seed of
    # its own (the default): the same image, bit for bit. With backward_seed=seed the image
    # samples the sky as its gradient pass does (which then retraces its paths): noisy, the same
    # on average.
    v, i = shapes.sphere(radius=1.0, rings=12, segments=24)[:2]
    cam = ep.Camera(position=torch.tensor([0.0, 0.0, 4.0]), look_at=torch.zeros(3), fov=40.0, resolution=(32, 32))
    albedo = torch.tensor([0.6, 0.6, 0.6])
    sky = ep.EnvironmentMap(torch.ones((1, 1, 3)))

    def image(diffuse, **kwargs):
        return ep.render(ep.Scene(cam, [ep.Mesh(v, i, material=ep.Material(diffuse=diffuse))], sky),
                         spp=4, max_bounces=2, seed=1, **kwargs)

    inside = (slice(12, 20), slice(12, 20))
    alone = image(albedo)
    assert (alone[inside] - 0.6).abs().max() < 1e-5
    followed = image(albedo.clone().requires_grad_()).detach()
    assert torch.equal(followed, alone)
    retraced = image(albedo.clone().requires_grad_(), backward_seed=1)[inside].detach()
    assert (retraced - 0.6).abs().max() > 1e-2
    assert abs(retraced.mean().item() - 0.6) < 0.02
