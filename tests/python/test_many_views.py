"""Many views per call: ``ep.render(scene, cameras=[...])`` equals a Python loop over the views
(images bit for bit, gradients to float rounding), from one scene build and one backward call."""

import pytest
import torch

import edgepath as ep

RES = (16, 20)


def make_scene():
    box_v, box_i = ep.shapes.box(center=(0.0, 0.5, 0.0))
    floor_v, floor_i = ep.shapes.quad([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]])
    lamp_v, lamp_i = ep.shapes.quad([[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]])
    box = ep.Mesh(box_v.clone().requires_grad_(), box_i,
                  material=ep.Material(diffuse=torch.tensor([0.6, 0.4, 0.3], requires_grad=True)))
    meshes = [box, ep.Mesh(floor_v, floor_i), ep.Mesh(lamp_v, lamp_i, emission=torch.tensor([6.0, 6.0, 5.0]))]
    return ep.Scene(camera=None, meshes=meshes)


def cameras(n=3):
    out = []
    for k in range(n):
        angle = torch.tensor(0.7 * k)
        position = torch.stack([3.5 * torch.sin(angle), torch.tensor(2.0), -3.5 * torch.cos(angle)])
        out.append(ep.Camera(position=position.requires_grad_(), look_at=torch.tensor([0.0, 0.5, 0.0]),
                             fov=40.0, resolution=RES))
    return out


OPTIONS = dict(spp=2, seed=4, backward_seed=9, num_threads=1)


def weights(shape):
    return torch.linspace(-1.0, 1.5, int(torch.tensor(shape).prod())).reshape(shape)


def test_views_equal_a_loop_over_views():
    scene, views = make_scene(), cameras()
    params = [scene.meshes[0].vertices, scene.meshes[0].material.diffuse] + [c.position for c in views]
    images = ep.render(scene, cameras=views, **OPTIONS)
    assert images.shape == (3, *RES, 3)
    w = weights(images.shape)
    grads = torch.autograd.grad((images * w).sum(), params)
    # The views' images trace the BVH built for images, their gradient pass the exact one.
    assert scene.build_counts() == {"builds": 2, "refits": 0, "reuses": 1}
    # The edge hierarchy is built once, for the first view, and shared by the others.
    assert scene.edge_hierarchy_counts() == {"builds": 1, "refits": 0, "reuses": 2}

    loop_images, loss = [], 0.0
    for k, camera in enumerate(views):
        image = ep.render(ep.Scene(camera, scene.meshes), **OPTIONS)
        loop_images.append(image)
        loss = loss + (image * w[k]).sum()
    loop_grads = torch.autograd.grad(loss, params)
    assert torch.equal(images.detach(), torch.stack(loop_images).detach())
    for name, g, h in zip(["vertices", "diffuse", "camera 0", "camera 1", "camera 2"], grads, loop_grads):
        assert h.abs().max() > 0, name
        torch.testing.assert_close(g, h, rtol=1e-5, atol=1e-6 * float(h.abs().max()), msg=name)


def loop_over_views(scene, views, w, params, seeds, backward_seeds):
    """The loop that a call with a seed per view equals: its images and gradients."""
    images, loss = [], 0.0
    for k, camera in enumerate(views):
        image = ep.render(ep.Scene(camera, scene.meshes), spp=2, num_threads=1, seed=seeds[k],
                          backward_seed=None if backward_seeds is None else backward_seeds[k])
        images.append(image)
        loss = loss + (image * w[k]).sum()
    return torch.stack(images).detach(), torch.autograd.grad(loss, params)


@pytest.mark.parametrize("backward", ["default", "own", "replay"])
def test_a_seed_per_view_equals_a_loop_with_those_seeds(backward):
    """seed=[s0, s1, s2]: view k is the image of seed s_k (its gradient pass: backward_seed[k],
    by default the seed derived from s_k, as for one view), and the views' noise differs."""
    scene, views = make_scene(), cameras()
    params = [scene.meshes[0].vertices, scene.meshes[0].material.diffuse] + [c.position for c in views]
    seeds = [4, 11, 7]
    backward_seeds = {"default": None, "own": [21, 5, 13], "replay": seeds}[backward]
    images = ep.render(scene, cameras=views, spp=2, num_threads=1, seed=seeds, backward_seed=backward_seeds)
    w = weights(images.shape)
    grads = torch.autograd.grad((images * w).sum(), params)
    loop_images, loop_grads = loop_over_views(scene, views, w, params, seeds, backward_seeds)
    assert torch.equal(images.detach(), loop_images)
    for name, g, h in zip(["vertices", "diffuse", "camera 0", "camera 1", "camera 2"], grads, loop_grads):
        assert h.abs().max() > 0, name
        torch.testing.assert_close(g, h, rtol=1e-5, atol=1e-6 * float(h.abs().max()), msg=name)
    # With one seed for every view, view 0 is the same image and the others are not.
    one = ep.render(scene, cameras=views, spp=2, num_threads=1, seed=4,
                    backward_seed=None if backward == "default" else 4 if backward == "replay" else 21)
    assert torch.equal(one[0], images[0])
    assert not torch.equal(one[1], images[1]) and not torch.equal(one[2], images[2])


def test_seeds_per_view_are_checked():
    scene, views = make_scene(), cameras()
    with pytest.raises(ValueError, match=r"seed: expected one seed per camera \(3\), got 2"):
        ep.render(scene, cameras=views, seed=[1, 2])
    with pytest.raises(ValueError, match=r"seed\[1\]"):
        ep.render(scene, cameras=views, seed=[1, -2, 3])
    with pytest.raises(ValueError, match=r"backward_seed: expected one seed per camera"):
        ep.render(scene, cameras=views, seed=1, backward_seed=[1, 2, 3, 4])
    with pytest.raises(ValueError, match=r"seed: a list of seeds \(one per view\) needs cameras"):
        ep.render(ep.Scene(views[0], scene.meshes), seed=[1, 2, 3])
    with pytest.raises(ValueError, match=r"backward_seed: a list of seeds"):
        ep.render(ep.Scene(views[0], scene.meshes), backward_seed=[1])
    # Retracing the image's paths in some views only: refused (the images would be traced for
    # one or the other).
    with pytest.raises(ValueError, match=r"backward_seed: equals seed for some views"):
        ep.render(scene, cameras=views, seed=[1, 2, 3], backward_seed=[1, 5, 6])


def test_each_view_camera_gets_its_own_gradient():
    """Only view 1's camera is differentiated: views 0 and 2 get none, and view 1's equals the
    gradient of view 1 rendered alone."""
    scene, views = make_scene(), cameras()
    views[0].position = views[0].position.detach()
    views[2].position = views[2].position.detach()
    scene.meshes[0].vertices.requires_grad_(False)
    scene.meshes[0].material.diffuse.requires_grad_(False)
    images = ep.render(scene, cameras=views, **OPTIONS)
    (g,) = torch.autograd.grad((images * weights(images.shape)).sum(), [views[1].position])
    alone = ep.render(ep.Scene(views[1], scene.meshes), **OPTIONS)
    (h,) = torch.autograd.grad((alone * weights(images.shape)[1]).sum(), [views[1].position])
    assert torch.equal(g, h)


def test_views_must_share_one_film_size():
    scene, views = make_scene(), cameras()
    views[1].resolution = (8, 8)
    with pytest.raises(ValueError, match=r"cameras\[1\]\.resolution"):
        ep.render(scene, cameras=views)
    views[1].resolution = RES
    views[2].fov = -1.0
    with pytest.raises(ValueError, match=r"cameras\[2\]\.fov"):
        ep.render(scene, cameras=views)
    with pytest.raises(ValueError, match=r"cameras"):
        ep.render(scene, cameras=[])
    views[2].fov = 40.0
    views[0].position = None
    with pytest.raises(ValueError, match=r"cameras\[0\]\.position"):
        ep.render(scene, cameras=views)
