"""Inverse rendering driven by a shadow alone: an orthographic camera between a floor and a box
hovering above it sees only the floor, lit by a square area light above the box. From one
target image, the box's translation (all three components: the height sets the shadow's size
and softness) is recovered by Adam, starting 20% of the visible floor's width away sideways. The image depends on the box only through its shadow, so every gradient
comes from the boundary term of secondary edges (the box's edges seen from the floor)."""

import time

import torch

import edgepath as ep
from edgepath import shapes
from test_primary_edges import box

FLOOR_WIDTH = 2.0  # the width of the floor the camera sees
TRUTH = torch.tensor([0.1, 0.0, -0.05])
START = TRUTH + 0.2 * FLOOR_WIDTH * torch.tensor([0.8, 0.0, 0.6])
BOX_VERTICES, BOX_INDICES, _ = box((0.0, 0.8, 0.0), (0.5, 0.3, 0.6))


def shadow_scene(translation, resolution=24):
    fv, fi = shapes.quad([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]])
    lv, li = shapes.quad([[-0.6, 2.5, -0.6], [0.6, 2.5, -0.6], [0.6, 2.5, 0.6], [-0.6, 2.5, 0.6]])  # facing down
    meshes = [ep.Mesh(vertices=fv, indices=fi, material=ep.Material(diffuse=0.7, specular=0.0)),
              ep.Mesh(vertices=BOX_VERTICES + translation, indices=BOX_INDICES,
                      material=ep.Material(diffuse=0.5, specular=0.0)),
              ep.Mesh(vertices=lv, indices=li, emission=torch.tensor([6.0, 6.0, 6.0]))]
    camera = ep.Camera(position=torch.tensor([0.0, 0.3, 0.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                       up=torch.tensor([0.0, 0.0, -1.0]), camera_type="orthographic",
                       ortho_scale=FLOOR_WIDTH / 2, resolution=(resolution, resolution))
    return ep.Scene(camera=camera, meshes=meshes)


def test_recover_occluder_position_from_its_shadow():
    start_time = time.perf_counter()
    target = ep.render(shadow_scene(TRUTH), spp=256, seed=100)
    assert float(target.min()) < 0.5 * float(target.max())  # a shadow in view
    translation = START.clone().requires_grad_()
    optimizer = torch.optim.Adam([translation], lr=0.02)
    history = []
    for step in range(80):
        optimizer.zero_grad()
        image = ep.render(shadow_scene(translation), spp=4, seed=step)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        history.append(translation.detach().clone())
    estimate = torch.stack(history[-10:]).mean(0)
    seconds = time.perf_counter() - start_time
    with torch.no_grad():  # the loss at the start and at the end, with the same samples
        before, after = (float((ep.render(shadow_scene(t), spp=64, seed=7) - target).square().mean())
                         for t in (START, estimate))
    error = float((estimate - TRUTH).norm())
    start_error = float((START - TRUTH).norm())
    print(f"{seconds:.1f} s, loss {before:.4g} -> {after:.4g}; position error "
          f"{start_error / FLOOR_WIDTH:.1%} -> {error / FLOOR_WIDTH:.2%} of the floor's width")
    assert after < 0.1 * before
    assert error < 0.02 * FLOOR_WIDTH
