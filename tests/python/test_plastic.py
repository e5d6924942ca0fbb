"""Plastic (Material kind "plastic": a diffuse base under a dielectric coating, Mitsuba 3's
``roughplastic`` and ``plastic``): forward against Mitsuba 3 references, derivative images in
every parameter against finite differences, an inverse problem recovering a roughness, and the
errors of a bad plastic."""

from pathlib import Path

import pytest
import torch

import conformance as C
import edgepath as ep
from edgepath import shapes

SCENE_DIR = Path(__file__).resolve().parent / "mitsuba_refs"


@pytest.mark.parametrize("name", ["rough_plastic", "smooth_plastic"])
def test_plastic_matches_mitsuba(name):
    """A plastic sphere and box before coloured walls (mitsuba_refs/NAME.xml; rough: GGX alpha
    0.2, and 0.5 with a tinted specular reflectance and nonlinear; smooth: Mitsuba's plastic)
    against Mitsuba 3's image: the mean of each channel within 2%, and Mitsuba's metric on 4 x 4
    blocks within its indirect-light conformance thresholds (0.04 mean, 0.4 max). Measured at
    256 spp: means within 0.21% / 0.28%, blocks 0.009 / 0.058 (rough) and 0.014 / 0.077
    (smooth). The sum of a Lambert and a Schlick GGX lobe that the loader made of a
    roughplastic before was 13-17% brighter in the rough scene's means."""
    loaded = ep.load_mitsuba(SCENE_DIR / f"{name}.xml")
    ref = ep.imread(SCENE_DIR / f"{name}.exr")[..., :3].float()
    image = loaded.render(spp=256)
    C.assert_matches_reference_image(image, ref, name)


def plastic_scene(diffuse=None, specular=None, roughness=0.2, ior=1.5, size=(6, 6), nonlinear=False):
    """A plastic floor seen at a low angle, reflecting a bright panel of coloured stripes,
    under a grey environment."""
    diffuse = torch.tensor([0.6, 0.3, 0.2]) if diffuse is None else diffuse
    specular = torch.tensor([1.0, 0.9, 0.8]) if specular is None else specular
    material = ep.Material(kind="plastic", diffuse=diffuse, specular=specular, roughness=roughness, ior=ior,
                           nonlinear=nonlinear)
    fv, fi = shapes.quad([[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]])
    lv, li = shapes.quad([[-1.5, 0.2, -2.5], [1.5, 0.2, -2.5], [1.5, 2.0, -2.5], [-1.5, 2.0, -2.5]])
    luv = torch.tensor([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])
    stripes = torch.zeros(4, 6, 3)
    stripes[:, ::2] = torch.tensor([4.0, 3.0, 2.0])
    stripes[:, 1::2] = torch.tensor([0.5, 1.0, 2.0])
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=material),
              ep.Mesh(vertices=lv, indices=li, uvs=luv, emission=stripes)]
    camera = ep.Camera(position=torch.tensor([0.0, 0.8, 2.5]), look_at=torch.tensor([0.0, 0.0, -0.5]), fov=30,
                       resolution=size)
    return ep.Scene(camera=camera, meshes=meshes, envmap=ep.EnvironmentMap(values=torch.full((1, 1, 3), 0.3)))


# (parameter, value, finite-difference step, other settings, spp), each over SEEDS. The
# finite differences' lobe choices flip under the step, so one seed's image sum is noisy: over
# 32 seeds its ratio to the derivative's had a standard deviation of 0.02-0.03 (ior 0.041 at
# a step of 0.04), and the bound of 5% failed at 1 in 8 or so; over 8 seeds at once, about
# a third of that. Means over 32 seeds (one seed each, 6 x 6 pixels): rough roughness 0.991,
# ior 0.978 (steps 0.05 and 0.1; 0.966 at 0.2), diffuse 1.010, specular 0.995; smooth ior
# 1.002, each +- 0.004-0.005. Over SEEDS the relative L1 distance is 0.02-0.05 (0.06-0.13 at
# one seed).
SEEDS = range(2, 10)
COLOUR = [1.0, 1.0, 1.0]
DERIVATIVE_CASES = [
    ("roughness", 0.2, 0.02, {}, 1024),
    ("ior", 1.5, 0.04, {}, 1024),
    ("diffuse", [0.6, 0.3, 0.2], 0.05, {}, 1024),
    ("specular", [1.0, 0.9, 0.8], 0.05, {}, 1024),
    ("diffuse", [0.6, 0.3, 0.2], 0.05, {"nonlinear": True}, 1024),
    ("ior", 1.5, 0.04, {"roughness": 0.0}, 4096),
    ("diffuse", [0.6, 0.3, 0.2], 0.05, {"roughness": 0.0}, 4096),
    ("specular", [1.0, 0.9, 0.8], 0.05, {"roughness": 0.0}, 4096),
]


@pytest.mark.parametrize("name, value, eps, extra, spp", DERIVATIVE_CASES,
                         ids=[c[0] + ("-smooth" if c[3].get("roughness") == 0.0 else "")
                              + ("-nonlinear" if c[3].get("nonlinear") else "") for c in DERIVATIVE_CASES])
def test_plastic_derivatives_match_finite_differences(name, value, eps, extra, spp):
    """The derivative image in each parameter of the plastic (through the coating's lobe, its
    Fresnel terms, the tabulated transmittance and internal reflectance and their derivatives
    in alpha and eta) against the central finite difference of renders with the same random
    numbers; colours along (1, 1, 1)."""
    value = torch.tensor(value)
    direction = torch.ones_like(value)
    param = value.clone().requires_grad_(True)
    d_image = fd_image = 0
    for seed in SEEDS:
        d_image = d_image + ep.derivative_image(plastic_scene(**{name: param}, **extra), param, direction, spp=spp,
                                                seed=seed, max_bounces=2) / len(SEEDS)
        with torch.no_grad():
            plus, minus = (ep.render(plastic_scene(**{name: value + s * eps * direction}, **extra), spp=spp,
                                     seed=seed, max_bounces=2) for s in (0.5, -0.5))
        fd_image = fd_image + (plus - minus) / eps / len(SEEDS)
    C.assert_matches_finite_difference(d_image, fd_image, f"{name} {extra}", 0.05, l1=0.12)


@pytest.mark.parametrize("name, value, eps", [("ior", 1.5, 0.1), ("roughness", 0.2, 0.02)])
def test_coating_derivatives_of_the_diffuse_lobe_match_finite_differences(name, value, eps):
    """The base seen through the rough coating alone (no specular), lit by the panel only (one
    bounce, light sampling): every sample is a smooth function of the coating's index and
    roughness, so the derivative image and the finite difference of renders with the same
    random numbers agree closely in sum. They go through the coating's internal reflectance R
    and transmittance T and their tabulated derivatives: with those differenced over steps of
    1e-4, which follow the quadratures' wiggles rather than their trend, the index's came out
    1.036 times the finite difference (1.037 at a step of 0.02) and the roughness's 0.971."""
    value = torch.tensor(value)
    param = value.clone().requires_grad_(True)
    options = dict(spp=256, seed=3, max_bounces=1, sampling="light")
    scene = plastic_scene(**{name: param}, specular=torch.zeros(3))
    d_sum = float(ep.derivative_image(scene, param, torch.ones_like(param), **options).sum())
    with torch.no_grad():
        plus, minus = (float(ep.render(plastic_scene(**{name: value + s * eps}, specular=torch.zeros(3)),
                                       **options).sum()) for s in (0.5, -0.5))
    ratio = d_sum / ((plus - minus) / eps)
    print(f"{name}: derivative / finite difference {ratio:.4f}")
    assert abs(ratio - 1) < 0.01


def test_inverse_rendering_recovers_a_plastic_roughness():
    """From alpha 0.1, gradient descent on the image difference finds the roughness 0.35 of
    the plastic floor that rendered the target (the reflected stripes blur with it). Measured:
    0.367 after 40 steps."""
    target = ep.render(plastic_scene(roughness=torch.tensor(0.35), size=(12, 12)), spp=256, max_bounces=2, seed=7)
    found = C.fit_roughness(
        lambda r, seed: ep.render(plastic_scene(roughness=r, size=(12, 12)), spp=16, max_bounces=2, seed=seed),
        target, start=0.1, steps=40, floor=0.02)
    assert found == pytest.approx(0.35, abs=0.03)


def test_plastic_is_darker_than_the_sum_of_its_lobes():
    """The coating passes only part of the light to the base and back (T(cos) < 1, over eta^2):
    the same diffuse colour renders darker under a coating with no specular reflectance than
    as a bare Lambertian surface, and the nonlinear base is darker still for a colour below 1."""
    bare = ep.render(plastic_scene(specular=torch.zeros(3)), spp=64, max_bounces=2)
    base = {"diffuse": torch.tensor([0.6, 0.3, 0.2]), "specular": torch.zeros(3)}

    def lambert(diffuse):
        scene = plastic_scene()
        scene.meshes[0].material = ep.Material(diffuse=diffuse)
        return ep.render(scene, spp=64, max_bounces=2)
    plain = lambert(base["diffuse"])
    nonlinear = ep.render(plastic_scene(**base, nonlinear=True), spp=64, max_bounces=2)
    floor = plain[3:] > 0.01  # the floor's pixels
    assert bool((bare[3:][floor] < plain[3:][floor]).all())
    assert bool((nonlinear[3:][floor] < bare[3:][floor]).all())


@pytest.mark.parametrize("field, kwargs, message", [
    ("roughness", {"roughness": torch.full((2, 2), 0.2)}, "a plastic's roughness must be one value"),
    ("ior", {"ior": torch.full((2, 2), 1.5)}, "a plastic's ior must be one value"),
])
def test_plastic_parameters_must_be_constants(field, kwargs, message):
    scene = plastic_scene()
    scene.meshes[0].material = ep.Material(kind="plastic", **kwargs)
    with pytest.raises(ValueError, match=rf"meshes\[0\]\.material\.{field}: {message}"):
        ep.render(scene, spp=1)


def test_nonlinear_plastic_albedo_above_one_is_refused():
    """kd / (1 - kd R) would pass through infinity for kd >= 1 / R: a nonlinear plastic's
    albedo (its diffuse, and vertex colours over it) is at most 1."""
    scene = plastic_scene(diffuse=torch.tensor([1.2, 0.5, 0.5]), nonlinear=True)
    with pytest.raises(ValueError, match=r"meshes\[0\]\.material\.diffuse: a nonlinear plastic's diffuse must be "
                                         r"at most 1, got 1\.2"):
        ep.render(scene, spp=1)
    scene = plastic_scene(nonlinear=True)
    scene.meshes[0].colors = torch.full((4, 3), 1.5)
    with pytest.raises(ValueError, match=r"meshes\[0\]\.colors: on a nonlinear plastic, colours must be at most 1"):
        ep.render(scene, spp=1)
    ep.render(plastic_scene(diffuse=torch.tensor([1.2, 0.5, 0.5])), spp=1)  # linear: 1 - R whatever kd


def test_plastic_index_of_one_is_refused():
    scene = plastic_scene(ior=1.0)
    with pytest.raises(ValueError,
                       match=r"meshes\[0\]\.material\.ior: a plastic's coating needs an index other than 1"):
        ep.render(scene, spp=1)


def shadow_scene(offset=None, roughness=0.2, size=(6, 6)):
    """A plastic floor under a square area light, with a dark square between them (moved by
    ``offset``) casting a shadow on the floor; seen from above at an angle."""
    material = ep.Material(kind="plastic", diffuse=torch.tensor([0.7, 0.5, 0.3]), roughness=roughness, ior=1.5)
    fv, fi = shapes.quad([[-1.5, 0, -1.5], [-1.5, 0, 1.5], [1.5, 0, 1.5], [1.5, 0, -1.5]])
    lv, li = shapes.quad([[-0.4, 2.0, -0.4], [0.4, 2.0, -0.4], [0.4, 2.0, 0.4], [-0.4, 2.0, 0.4]])
    ov, oi = shapes.quad([[-0.3, 0.8, -0.3], [-0.3, 0.8, 0.3], [0.3, 0.8, 0.3], [0.3, 0.8, -0.3]])
    if offset is not None:
        ov = ov + offset
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=material),
              ep.Mesh(vertices=lv, indices=li, emission=torch.tensor([10.0, 10.0, 10.0])),
              ep.Mesh(vertices=ov, indices=oi,
                      material=ep.Material(diffuse=torch.tensor([0.2, 0.2, 0.2]), two_sided=True))]
    camera = ep.Camera(position=torch.tensor([0.0, 2.6, 1.6]), look_at=torch.zeros(3), fov=35, resolution=size)
    return ep.Scene(camera=camera, meshes=meshes)


@pytest.mark.parametrize("roughness", [0.2, 0.0], ids=["rough", "smooth"])
def test_shadow_on_plastic_matches_finite_differences(roughness):
    """The occluder moving sideways moves its shadow on the plastic floor: the derivative image
    needs the boundary terms of the edges seen from the plastic's vertices (the secondary-edge
    sampler runs there with the plastic's lobe). Measured at 1024 spp (seeds 2, 3): relative L1
    0.19 / 0.19 (rough), 0.21 / 0.20 (smooth); without the secondary edges 0.86-0.94. (The
    image sum of this derivative is near zero: the shadow gains on one side what it loses on
    the other, so only the relative L1 is asserted.)"""
    spp, eps, seed = 1024, 0.02, 2
    param = torch.zeros(3, requires_grad=True)
    direction = torch.tensor([1.0, 0.0, 0.0])
    scene = shadow_scene(param, roughness)
    d_image = ep.derivative_image(scene, param, direction, spp=spp, seed=seed)
    interior = ep.derivative_image(scene, param, direction, spp=spp, seed=seed, secondary_edges=False)
    with torch.no_grad():
        plus, minus = (ep.render(shadow_scene(s * eps * direction, roughness), spp=spp, seed=seed)
                       for s in (0.5, -0.5))
    fd_image = (plus - minus) / eps
    error, interior_error = C.relative_l1(d_image, fd_image), C.relative_l1(interior, fd_image)
    print(f"relative L1 {error:.4f}, without secondary edges {interior_error:.4f}")
    assert float(fd_image.abs().mean()) > 0.05
    assert error < 0.3
    assert interior_error > 0.7
