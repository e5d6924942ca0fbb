"""Secondary visibility: the boundary term of edges seen from shading points.

A floor, a square occluder and a square area light above it; a camera with a tiny field of view
looks at one floor point in the occluder's penumbra, so the one-pixel image is the radiance
reflected there. Moving the occluder, the floor (the shading point), the light or the camera
moves the shadow's edge across the light as seen from that point: a boundary term in direction
space at the shading point (edges of the occluder, and the light's own outline). Each is checked
separately against central finite differences of the same pixel.
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes

LOOK_AT_X = 0.6  # in the penumbra: the occluder hides part of the light from here
PARTS = ("floor", "occluder", "light", "camera")


def penumbra_scene(offsets):
    fv, fi = shapes.quad([[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]])
    ov, oi = shapes.quad([[-0.4, 1, -0.4], [-0.4, 1, 0.4], [0.4, 1, 0.4], [0.4, 1, -0.4]])
    lv, li = shapes.quad([[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]])
    grey = ep.Material(diffuse=torch.tensor([0.7, 0.7, 0.7]), specular=torch.zeros(3))
    meshes = [ep.Mesh(vertices=fv + offsets["floor"], indices=fi, material=grey),
              ep.Mesh(vertices=ov + offsets["occluder"], indices=oi, material=grey),
              ep.Mesh(vertices=lv + offsets["light"], indices=li, emission=torch.tensor([10.0, 10.0, 10.0]))]
    camera = ep.Camera(position=torch.tensor([LOOK_AT_X + 0.01, 0.5, 1.5]) + offsets["camera"],
                       look_at=torch.tensor([LOOK_AT_X, 0.0, 0.0]) + offsets["camera"],
                       up=torch.tensor([0.0, 1.0, 0.0]), fov=0.05, resolution=(1, 1))
    return ep.Scene(camera=camera, meshes=meshes)


# part: (direction of its motion, samples, relative tolerance). The tolerances are about three
# standard deviations of the derivative at those sample counts (measured over seeds: occluder
# 0.5%, light 1%, camera and floor 2-4% at 200k samples).
CASES = {
    "occluder": ([1.0, 0.0, 0.3], 200_000, 0.03),
    "light": ([1.0, 0.0, 0.3], 200_000, 0.03),
    "camera": ([1.0, 0.0, 0.3], 1_000_000, 0.05),
    "floor": ([0.2, 1.0, 0.0], 1_000_000, 0.05),  # up: the shading point moves along the view ray
}


@pytest.mark.parametrize("part", list(CASES))
def test_penumbra_derivative_matches_finite_difference(part):
    direction, spp, tolerance = CASES[part]
    direction = torch.tensor(direction)
    offset = torch.zeros(3, requires_grad=True)
    offsets = {k: torch.zeros(3) for k in PARTS}
    offsets[part] = offset
    scene = penumbra_scene(offsets)
    d = float(ep.derivative_image(scene, offset, direction, spp=spp, seed=1)[0, 0, 0])
    interior = float(ep.derivative_image(scene, offset, direction, spp=spp, seed=1,
                                         secondary_edges=False)[0, 0, 0])
    eps = 0.02
    with torch.no_grad():
        images = [ep.render(penumbra_scene({**offsets, part: s * eps * direction}), spp=spp, seed=2)
                  for s in (0.5, -0.5)]
    fd = float((images[0] - images[1])[0, 0, 0]) / eps
    print(f"{part}: derivative {d:.5f}, finite difference {fd:.5f}, without secondary edges {interior:.5f}")
    assert abs(fd) > 0.05
    assert d == pytest.approx(fd, rel=tolerance)
    assert abs(interior - fd) > 3 * tolerance * abs(fd)  # the check sees the boundary term


@pytest.mark.parametrize("edge_sampling", ["importance", "uniform"])
def test_awkward_geometry_gives_finite_gradients(edge_sampling):
    """Edges shared by three faces (a fin), a box standing on the floor (edges through the
    shading points along its base), a wall seen edge-on by the camera and grazing light: every
    gradient finite, with both boundary terms on, in reverse and forward mode."""
    fv, fi = shapes.quad([[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]])
    # three triangles sharing the edge (0,0,0)-(0,1,0)
    fin_v = torch.tensor([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.8, 0.5, 0.0], [-0.6, 0.5, 0.5], [-0.3, 0.5, -0.7]])
    fin_i = torch.tensor([[0, 1, 2], [1, 0, 3], [0, 1, 4]], dtype=torch.int32)
    # a box on the floor; a wall in the plane x = 1.5 that the camera sees edge-on
    bv = torch.tensor([[x, y, z] for x in (-1.2, -0.6) for y in (0.0, 0.6) for z in (-0.3, 0.3)])
    bi = torch.tensor([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                       [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=torch.int32)
    wv, wi = shapes.quad([[1.5, 0, -1], [1.5, 1, -1], [1.5, 1, 1], [1.5, 0, 1]])
    lv, li = shapes.quad([[-3, 0.05, -0.5], [-3, 0.05, 0.5], [-3, 1.0, 0.5], [-3, 1.0, -0.5]])  # grazing light
    grey = ep.Material(diffuse=torch.tensor([0.6, 0.6, 0.6]), specular=torch.tensor([0.2, 0.2, 0.2]),
                       roughness=0.2, two_sided=True)
    params = [t.clone().requires_grad_(True) for t in (fv, fin_v, bv, wv, lv)]
    meshes = [ep.Mesh(vertices=params[0], indices=fi, material=grey),
              ep.Mesh(vertices=params[1], indices=fin_i, material=grey),
              ep.Mesh(vertices=params[2], indices=bi, material=grey),
              ep.Mesh(vertices=params[3], indices=wi, material=grey),
              ep.Mesh(vertices=params[4], indices=li, emission=torch.tensor([20.0, 20.0, 20.0]),
                      two_sided_emission=True)]
    position = torch.tensor([1.5, 0.5, 4.0], requires_grad=True)
    camera = ep.Camera(position=position, look_at=torch.tensor([1.5, 0.5, 0.0]), up=torch.tensor([0.0, 1.0, 0.0]),
                       fov=60.0, resolution=(16, 16))
    scene = ep.Scene(camera=camera, meshes=meshes, envmap=ep.EnvironmentMap(values=torch.full((4, 8, 3), 0.3)))
    image = ep.render(scene, spp=8, max_bounces=2, seed=3, edge_sampling=edge_sampling)
    assert torch.isfinite(image).all()
    image.sum().backward()
    for t in params + [position]:
        assert t.grad is not None and torch.isfinite(t.grad).all()
    assert float(params[1].grad.abs().sum()) > 0  # the fin's edges were sampled
    d = ep.derivative_image(scene, params[2], torch.ones_like(params[2]), spp=8, max_bounces=2, seed=3,
                            edge_sampling=edge_sampling)
    assert torch.isfinite(d).all() and float(d.abs().sum()) > 0


def test_penumbra_far_from_the_origin():
    """The penumbra scene moved 12 units along x: the derivative must not change. Rays leave a
    surface from a point lifted off it by an offset that grows with the coordinates; the two
    rays either side of an edge must be aimed from that lifted point, or (here, where the lift
    is larger than their separation) both pass the occluder's edge on the same side and the
    shadow's derivative vanishes."""
    direction, spp, tolerance = CASES["occluder"]
    direction = torch.tensor(direction)
    far = torch.tensor([12.0, 0.0, 0.0])
    offset = torch.zeros(3, requires_grad=True)
    offsets = {k: far for k in PARTS}
    offsets["occluder"] = far + offset
    scene = penumbra_scene(offsets)
    d = float(ep.derivative_image(scene, offset, direction, spp=spp, seed=1)[0, 0, 0])
    eps = 0.02
    with torch.no_grad():
        images = [ep.render(penumbra_scene({**offsets, "occluder": far + s * eps * direction}), spp=spp, seed=2)
                  for s in (0.5, -0.5)]
    fd = float((images[0] - images[1])[0, 0, 0]) / eps
    print(f"far from the origin: derivative {d:.5f}, finite difference {fd:.5f}")
    assert abs(fd) > 0.05
    assert d == pytest.approx(fd, rel=tolerance)


@pytest.mark.parametrize("sampling", ["light", "bsdf", "mis"])
def test_light_reaches_a_scene_far_from_the_origin(sampling):
    """The same penumbra 30 units along x renders the same image: a shadow ray leaves from the
    lifted origin and must be aimed and measured from there, or (when the lift is larger than
    the shadow epsilon's shortening) it reaches the light's own surface and counts as blocked."""
    zero = {k: torch.zeros(3) for k in PARTS}
    far = {k: torch.tensor([30.0, 0.0, 0.0]) for k in PARTS}
    near_image = ep.render(penumbra_scene(zero), spp=4096, seed=3, sampling=sampling)
    far_image = ep.render(penumbra_scene(far), spp=4096, seed=3, sampling=sampling)
    assert float(near_image[0, 0, 0]) > 0.05
    assert float(far_image[0, 0, 0]) == pytest.approx(float(near_image[0, 0, 0]), rel=0.05)


# ---- closed form: the shadow of a polygon under a uniform sky --------------------------------
#
# A Lambertian floor (albedo RHO) under uniform radiance L from every direction above it, and a
# black polygon occluder hovering over it. The floor's radiance at p is RHO * L * (1 - F(p)),
# where F(p) = |sum_i beta_i n . Gamma_i| / (2 pi) is the form factor from p to the polygon
# (Lambert's formula: beta_i the angle that edge i subtends at p, Gamma_i the unit normal of
# the plane through p and edge i, n the floor's normal). An orthographic camera between the
# floor and the occluder sees only the floor, so the interior term of the occluder's motion is
# zero and its derivative is the boundary term of the occluder's edges alone.

RHO, SKY = 0.5, 1.5
OCCLUDER = [[-0.35, 0.7, -0.45], [0.5, 0.7, -0.2], [0.25, 0.7, 0.45], [-0.45, 0.7, 0.25]]
SHADOW_RES, SHADOW_HALF_WIDTH = 8, 1.0


def form_factor(points, polygon):
    """F at floor points (N, 3) of the polygon (K, 3), float64, differentiable."""
    a = polygon[None, :, :] - points[:, None, :]
    b = torch.roll(a, -1, dims=1)
    c = torch.linalg.cross(a, b, dim=-1)
    beta = torch.atan2(c.norm(dim=-1), (a * b).sum(-1))
    gamma_y = c[..., 1] / c.norm(dim=-1)
    return (beta * gamma_y).sum(-1).abs() / (2 * math.pi)


def pixel_points(res, half_width, per_side=12):
    """Points (res, res, per_side^2, 3) on the floor covering each pixel of the orthographic
    camera below (midpoint rule)."""
    step = 2 * half_width / res
    sub = (torch.arange(per_side, dtype=torch.float64) + 0.5) / per_side
    start = -half_width + step * torch.arange(res, dtype=torch.float64)
    x = (start[None, :, None, None] + step * sub[None, None, None, :]).expand(res, res, per_side, per_side)
    z = (start[:, None, None, None] + step * sub[None, None, :, None]).expand(res, res, per_side, per_side)
    return torch.stack([x, torch.zeros_like(x), z], -1).reshape(res, res, per_side * per_side, 3)


def sky_shadow_scene(occluder_vertices):
    fv, fi = shapes.quad([[-6, 0, -6], [-6, 0, 6], [6, 0, 6], [6, 0, -6]])
    floor = ep.Mesh(vertices=fv, indices=fi, material=ep.Material(diffuse=torch.full((3,), RHO), specular=0.0))
    occluder = ep.Mesh(vertices=occluder_vertices, indices=torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32),
                       material=ep.Material(diffuse=0.0, specular=0.0))
    envmap = ep.EnvironmentMap(values=torch.full((8, 16, 3), SKY))
    # Image right = +x, image up = -z; row i, column j covers z, x in
    # [-w + i step, -w + (i + 1) step] x [-w + j step, ...].
    camera = ep.Camera(position=torch.tensor([0.0, 0.4, 0.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                       up=torch.tensor([0.0, 0.0, -1.0]), camera_type="orthographic",
                       ortho_scale=SHADOW_HALF_WIDTH, resolution=(SHADOW_RES, SHADOW_RES))
    return ep.Scene(camera=camera, meshes=[floor, occluder], envmap=envmap)


# Measured over seeds 2, 5, 9 at 16384 spp: relative mean abs error 0.017-0.020 (importance),
# 0.017-0.023 (uniform); image sums within 0.04 of the closed form's (its sum of |values|: 7.0).
@pytest.mark.parametrize("edge_sampling", ["importance", "uniform"])
def test_shadow_of_a_polygon_matches_closed_form(edge_sampling):
    direction = torch.tensor([1.0, 0.2, -0.6])
    polygon = torch.tensor(OCCLUDER, dtype=torch.float64)
    points = pixel_points(SHADOW_RES, SHADOW_HALF_WIDTH).reshape(-1, 3)

    def pixels(t):  # the image (one channel), as a function of the translation t along direction
        f = form_factor(points, polygon + t * direction.double())
        return (RHO * SKY * (1 - f)).reshape(SHADOW_RES, SHADOW_RES, -1).mean(-1)

    t0 = torch.zeros((), dtype=torch.float64)
    expected_image = pixels(t0)
    expected = torch.func.jacfwd(pixels)(t0)

    vertices = torch.tensor(OCCLUDER)
    scene = sky_shadow_scene(vertices)
    image = ep.render(scene, spp=1024, seed=1)
    # the image itself (the closed form's premise): within the pixel noise
    assert float((image[..., 0] - expected_image).abs().mean()) < 0.01 * float(expected_image.mean())
    along = direction.expand_as(vertices)
    spp = 16384
    d = ep.derivative_image(scene, vertices, along, spp=spp, seed=2, edge_sampling=edge_sampling)
    interior = ep.derivative_image(scene, vertices, along, spp=64, seed=2, secondary_edges=False)
    scale = float(expected.abs().mean())
    error = float((d - expected[..., None]).abs().mean()) / scale
    error_off = float((interior - expected[..., None]).abs().mean()) / scale
    print(f"{edge_sampling}: mean |expected| {scale:.4f}, relative mean abs error {error:.4f} at {spp} spp; "
          f"sums {float(d[..., 0].sum()):.4f} vs {float(expected.sum()):.4f}; without secondary edges {error_off:.3f}")
    assert error < 0.03
    assert abs(float(d[..., 0].sum() - expected.sum())) < 0.01 * float(expected.abs().sum())
    assert error_off > 0.5


# ---- derivative images against finite differences: shadow, reflection, indirect light -------
#
# Each scene is seen by a 16x16 camera that sees no moving edge directly (the derivative
# without secondary edges is zero), and the derivative image for a sideways translation of one
# mesh is compared with central finite differences of the renderer, both averaged over square
# blocks of pixels (the per-pixel noise of either is a few percent). Without secondary edges the
# same check fails.

def square(cx, y, cz, half, facing_down=False):
    """A horizontal square quad (vertices, indices), facing +y (or -y)."""
    corners = [[cx - half, y, cz - half], [cx - half, y, cz + half], [cx + half, y, cz + half], [cx + half, y, cz - half]]
    return shapes.quad(corners[::-1] if facing_down else corners)


def looking_down(res=16):
    """Orthographic, between the floor and anything above y = 0.3: sees the floor only."""
    return ep.Camera(position=torch.tensor([0.0, 0.3, 0.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                     up=torch.tensor([0.0, 0.0, -1.0]), camera_type="orthographic", ortho_scale=1.0,
                     resolution=(res, res))


def sun_shadow_scene(moving):
    """An occluder shadowing the floor from a sun: a bright 2x2-texel patch of an otherwise dim
    environment map, 55-80 degrees above the horizon."""
    fv, fi = square(0, 0, 0, 3)
    _, oi = square(0, 0, 0, 1)
    env = torch.full((16, 32, 3), 0.05)
    env[2:4, 15:17] = 100.0
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=ep.Material(diffuse=0.6, specular=0.0)),
              ep.Mesh(vertices=moving, indices=oi, material=ep.Material(diffuse=0.3, specular=0.0))]
    return ep.Scene(camera=looking_down(), meshes=meshes, envmap=ep.EnvironmentMap(values=env))


def glossy_reflection_scene(moving):
    """An emissive panel behind and above the camera's view, seen only in a glossy floor."""
    fv, fi = shapes.quad([[-3, 0, -6], [-3, 0, 3], [3, 0, 3], [3, 0, -6]])
    camera = ep.Camera(position=torch.tensor([0.0, 1.0, 3.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                       up=torch.tensor([0.0, 1.0, 0.0]), fov=20.0, resolution=(16, 16))
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=ep.Material(diffuse=0.02, specular=0.9, roughness=0.1)),
              ep.Mesh(vertices=moving, indices=torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32),
                      emission=torch.tensor([4.0, 4.0, 4.0]))]
    return ep.Scene(camera=camera, meshes=meshes)


def indirect_shadow_scene(moving):
    """A light facing up at a white ceiling, which lights the floor: the floor gets indirect
    light only, and a black square hanging between them shadows it (and the ceiling)."""
    fv, fi = square(0, 0, 0, 3)
    cv, ci = square(0, 2, 0, 3, facing_down=True)
    lv, li = square(-2, 0.5, 0, 0.5)
    white = ep.Material(diffuse=0.8, specular=0.0)
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=white),
              ep.Mesh(vertices=cv, indices=ci, material=white),
              ep.Mesh(vertices=lv, indices=li, emission=torch.tensor([30.0, 30.0, 30.0])),
              ep.Mesh(vertices=moving, indices=square(0, 0, 0, 1)[1], material=ep.Material(diffuse=0.0, specular=0.0))]
    return ep.Scene(camera=looking_down(), meshes=meshes)


def block_means(image, size):
    h, w = image.shape[:2]
    return image.reshape(h // size, size, w // size, size, -1).mean((1, 3))


# name: (scene, moving mesh's vertices, max_bounces, derivative spp, finite-difference spp, eps,
#        block size, tolerance). Relative mean abs errors measured at these settings over three
#        pairs of seeds: sun 0.019-0.023, glossy 0.013-0.019, indirect 0.018-0.021 (there, at 4096
#        spp the finite differences alone were 6% off those at 32768 spp).
FD_CASES = {
    "sun shadow": (sun_shadow_scene, square(0.1, 0.6, 0.1, 0.3)[0], 1, 8192, 16384, 0.02, 2, 0.05),
    "glossy reflection": (glossy_reflection_scene,
                          torch.tensor([[-0.4, 0.6, -3.0], [0.4, 0.6, -3.0], [0.4, 1.4, -3.0], [-0.4, 1.4, -3.0]]),
                          1, 4096, 16384, 0.01, 2, 0.04),
    "indirect shadow": (indirect_shadow_scene, square(0, 1.2, 0, 0.6)[0], 2, 4096, 16384, 0.1, 4, 0.05),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(FD_CASES))
def test_derivative_image_matches_finite_differences(name):
    make, moving, max_bounces, spp, fd_spp, eps, size, tolerance = FD_CASES[name]
    scene = make(moving)
    direction = torch.tensor([1.0, 0.0, 0.0]).expand_as(moving)
    d = ep.derivative_image(scene, moving, direction, spp=spp, max_bounces=max_bounces, seed=1)
    off = ep.derivative_image(scene, moving, direction, spp=64, max_bounces=max_bounces, seed=1,
                              secondary_edges=False)
    fd = ep.finite_difference_image(scene, moving, direction, eps=eps, spp=fd_spp, max_bounces=max_bounces, seed=2)
    want = block_means(fd, size)
    scale = float(want.abs().mean())
    error = float((block_means(d, size) - want).abs().mean()) / scale
    error_off = float((block_means(off, size) - want).abs().mean()) / scale
    print(f"{name}: mean |finite difference| {scale:.4f} over {size}x{size} blocks, relative mean abs error "
          f"{error:.4f}; without secondary edges {error_off:.3f}")
    assert scale > 0.01
    assert error < tolerance
    assert error_off > 0.5


def glossy_highlight_scene(moving, alpha=0.08):
    """A small area light's highlight in a glossy plastic floor (GGX alpha 0.08), cut by the edges
    of a cube floating between them (the cube's shadow falls across the highlight): the
    benchmark's glossy scene, framed on the highlight. The cube is out of view and black from
    below, so everything that changes is the light seen past its edges."""
    fv, fi = square(0, 0, 0, 4)
    lv, li = square(0, 3.5, 0, 0.15, facing_down=True)
    camera = ep.Camera(position=torch.tensor([1.7, 3.0, 0.0]), look_at=torch.tensor([0.9, 0.0, 0.0]),
                       up=torch.tensor([0.0, 0.0, 1.0]), fov=20.0, resolution=(16, 16))
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=ep.Material(kind="plastic", diffuse=0.3, roughness=alpha)),
              ep.Mesh(vertices=moving, indices=shapes.box()[1], material=ep.Material(diffuse=0.5, specular=0.0)),
              ep.Mesh(vertices=lv, indices=li, emission=torch.tensor([300.0, 300.0, 300.0]))]
    return ep.Scene(camera=camera, meshes=meshes)


# alpha: (4x4-block relative mean abs error, relative error of the image sum) allowed. Measured
# at these settings over seeds 1, 3, 5: alpha 0.08 0.022-0.037 and within 0.5-1.2%; alpha 0.02
# (a lobe narrower than the light's cone, where the light strategy's point follows the lobe)
# 0.026-0.036 and within 0.3-2.1% (the image sum at 4x2048 spp, -635 +- 2, agrees with uniform
# edge sampling's at 4x8192, -626 +- 11, and with finite differences at eps 0.005, -631).
GLOSSY_HIGHLIGHT_CASES = {0.08: (0.06, 0.03), 0.02: (0.07, 0.04)}


@pytest.mark.parametrize("alpha", list(GLOSSY_HIGHLIGHT_CASES))
def test_glossy_highlight_cut_by_an_edge_matches_finite_differences(alpha):
    """Two bounces: the floor's vertices pick the light strategy by their lobe's share of the light
    cone, the cube's (last bounces, no environment) by the light strategy alone; the derivative
    image must stay unbiased."""
    tolerance, sum_tolerance = GLOSSY_HIGHLIGHT_CASES[alpha]
    moving = shapes.box(center=(0, 1.2, 0), half=(0.4, 0.4, 0.4))[0]
    scene = glossy_highlight_scene(moving, alpha)
    direction = torch.tensor([1.0, 0.0, 0.0]).expand_as(moving)
    d = ep.derivative_image(scene, moving, direction, spp=1024, max_bounces=2, seed=1)
    off = ep.derivative_image(scene, moving, direction, spp=16, max_bounces=2, seed=1, secondary_edges=False)
    fd = ep.finite_difference_image(scene, moving, direction, eps=0.02, spp=4096, max_bounces=2, seed=2)
    want = block_means(fd, 4)
    scale = float(want.abs().mean())
    error = float((block_means(d, 4) - want).abs().mean()) / scale
    print(f"glossy highlight, alpha {alpha}: mean |finite difference| {scale:.4f} over 4x4 blocks, relative mean "
          f"abs error {error:.4f}; sums {float(d.sum()):.2f} vs {float(fd.sum()):.2f}")
    assert scale > 0.1
    assert float(off.abs().max()) == 0.0  # all of it is the boundary term
    assert error < tolerance
    assert abs(float(d.sum() / fd.sum()) - 1) < sum_tolerance


# part: (vertex moved alone, or None for the camera position; direction; relative tolerance).
# Measured over backward seeds 5, 6, 7 at 1M samples: within 0.8% (occluder), 0.7% (light),
# 0.9% (camera) and 5.3% (floor: a derivative 10x smaller) of the finite differences.
VERTEX_CASES = {
    "occluder": (2, [1.0, 0.0, 0.3], 0.03),  # a corner at the end of the edge shading the point
    "light": (1, [1.0, 0.0, 0.3], 0.03),
    "floor": (3, [0.0, 1.0, 0.0], 0.1),  # tilts the triangle under the shading point
    "camera": (None, [1.0, 0.0, 0.3], 0.05),
}


@pytest.mark.slow
def test_penumbra_reverse_mode_gradients_per_vertex():
    """Reverse mode (loss.backward()) on the penumbra pixel, every part needing gradients at
    once: one vertex each of the occluder, the receiving floor and the light, and the camera
    position, each against finite differences of moving that vertex (or the camera) alone."""
    spp = 1_000_000

    def gradients(secondary_edges, backward_spp):
        offsets = {k: torch.zeros(3 if k == "camera" else (4, 3), requires_grad=True) for k in PARTS}
        image = ep.render(penumbra_scene(offsets), spp=1, seed=1, backward_spp=backward_spp, backward_seed=5,
                          secondary_edges=secondary_edges)
        image[0, 0, 0].backward()
        return {k: t.grad for k, t in offsets.items()}

    grads, grads_off = gradients(True, spp), gradients(False, spp // 10)
    eps = 0.02
    for part, (vertex, direction, tolerance) in VERTEX_CASES.items():
        direction = torch.tensor(direction)
        pick = (lambda g: g) if vertex is None else (lambda g: g[vertex])
        d, off = float(pick(grads[part]) @ direction), float(pick(grads_off[part]) @ direction)
        values = []
        with torch.no_grad():
            for s in (0.5, -0.5):
                offsets = {k: torch.zeros(3 if k == "camera" else (4, 3)) for k in PARTS}
                pick(offsets[part])[...] = s * eps * direction
                values.append(float(ep.render(penumbra_scene(offsets), spp=spp, seed=2)[0, 0, 0]))
        fd = (values[0] - values[1]) / eps
        print(f"{part}: gradient {d:.5f}, finite difference {fd:.5f}, without secondary edges {off:.5f}")
        assert abs(fd) > 0.01
        assert d == pytest.approx(fd, rel=tolerance)
        assert abs(off - fd) > 3 * tolerance * abs(fd)
