"""Secondary visibility: the boundary term of edges seen from shading points.

A floor, a square occluder and a square area light above it; a camera with a tiny field of view
looks at one floor point in the occluder's penumbra, so the one-pixel image is the radiance
reflected there. Moving the occluder, the floor (the shading point), the light or the camera
moves the shadow's edge across the light as seen from that point: a boundary term in direction
space at the shading point (edges of the occluder, and the light's own outline). Each is checked
separately against central finite differences of the same pixel.
"""

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
