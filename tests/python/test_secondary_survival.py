"""The secondary edge term's roulette by class of vertices (``secondary_survival``): a pilot
pass sets a probability per mesh and depth, and the term sampled with it is divided by it.

Checked here: 1 (the default) is the pass without roulette, bit for bit; below 1 the result
changes (the roulette acts) but its mean over seeds matches the unrouletted mean within
standard errors (unbiased); values outside (0, 1] are refused with the field's name.
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes


def shadow_scene(offset):
    """A floor, a square occluder above it (translated by `offset`) and a square light; the
    camera looks down at the occluder and its penumbra, so vertices on both meshes see edges."""
    fv, fi = shapes.quad([[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]])
    ov, oi = shapes.quad([[-0.4, 1, -0.4], [-0.4, 1, 0.4], [0.4, 1, 0.4], [0.4, 1, -0.4]])
    lv, li = shapes.quad([[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]])
    grey = ep.Material(diffuse=torch.tensor([0.7, 0.7, 0.7]), specular=torch.zeros(3))
    glossy = ep.Material(diffuse=torch.tensor([0.3, 0.3, 0.3]), specular=torch.tensor([0.5, 0.5, 0.5]),
                         roughness=0.2)
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=grey),
              ep.Mesh(vertices=ov + offset, indices=oi, material=glossy),
              ep.Mesh(vertices=lv, indices=li, emission=torch.tensor([10.0, 10.0, 10.0]))]
    camera = ep.Camera(position=torch.tensor([0.3, 2.5, 1.2]), look_at=torch.tensor([0.3, 0.0, 0.0]),
                       up=torch.tensor([0.0, 1.0, 0.0]), fov=50.0, resolution=(12, 12))
    return ep.Scene(camera=camera, meshes=meshes)


DIRECTION = torch.tensor([1.0, 0.0, 0.3])


def derivative(survival, seed, spp=16, bounces=2):
    offset = torch.zeros(3, requires_grad=True)
    scene = shadow_scene(offset)
    return ep.derivative_image(scene, offset, DIRECTION, spp=spp, max_bounces=bounces, seed=seed,
                               secondary_survival=survival)


def test_survival_one_is_the_pass_without_roulette_bit_for_bit():
    default = derivative(None, seed=3)
    one = derivative(1.0, seed=3)
    assert torch.equal(default, one)
    assert default.abs().sum() > 0
    # Reverse mode too.
    grads = []
    for survival in (None, 1.0):
        offset = torch.zeros(3, requires_grad=True)
        image = ep.render(shadow_scene(offset), spp=8, max_bounces=2, seed=1, backward_seed=5,
                          secondary_survival=survival)
        image.sum().backward()
        grads.append(offset.grad.clone())
    assert torch.equal(grads[0], grads[1])


def test_roulette_is_unbiased():
    seeds = range(1, 25)
    sums = {1.0: [], 0.05: []}
    changed = False
    for seed in seeds:
        full = derivative(1.0, seed)
        rouletted = derivative(0.05, seed)
        changed = changed or not torch.equal(full, rouletted)
        sums[1.0].append(float(full.sum()))
        sums[0.05].append(float(rouletted.sum()))
    assert changed  # the pilot set a probability below 1 somewhere: the roulette acted
    n = len(seeds)
    mean = {k: sum(v) / n for k, v in sums.items()}
    se = {k: math.sqrt(sum((x - mean[k]) ** 2 for x in v) / (n - 1) / n) for k, v in sums.items()}
    print(f"means {mean}, standard errors {se}")
    assert abs(mean[1.0]) > 4 * se[1.0]  # a derivative well above its noise
    assert abs(mean[0.05] - mean[1.0]) < 4 * math.hypot(se[1.0], se[0.05])


@pytest.mark.parametrize("value", [0.0, -0.5, 1.5, float("nan")])
def test_bad_survival_is_refused(value):
    offset = torch.zeros(3, requires_grad=True)
    with pytest.raises(ValueError, match="secondary_survival"):
        ep.derivative_image(shadow_scene(offset), offset, DIRECTION, spp=1, secondary_survival=value)
