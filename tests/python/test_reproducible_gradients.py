"""Gradients are the same bit for bit whatever ``num_threads``, as images are: each tile's (and
each chunk of camera edge samples') additions are made in the tiles' order, not as the threads
happen to finish them (``OrderedAdds``, scene/gradients.h). Before, the threads' atomic float
additions left the gradients reproducible only up to rounding; these tests failed then."""

import torch

import edgepath as ep


def make_scene():
    g = torch.Generator().manual_seed(0)
    v, i = ep.shapes.sphere(center=(0.0, 0.6, 0.0), radius=0.5, rings=16, segments=32)[:2]
    sphere = ep.Mesh(v.requires_grad_(), i,
                     material=ep.Material(diffuse=torch.tensor([0.6, 0.5, 0.4]).requires_grad_(), specular=0.2,
                                          roughness=0.3))
    fv, fi = ep.shapes.quad([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]])
    floor = ep.Mesh(fv, fi, material=ep.Material(diffuse=torch.tensor([0.5, 0.5, 0.5]).requires_grad_()))
    lv, li = ep.shapes.quad([[-0.5, 2.5, -0.5], [0.5, 2.5, -0.5], [0.5, 2.5, 0.5], [-0.5, 2.5, 0.5]])
    lamp = ep.Mesh(lv, li, emission=torch.tensor([6.0, 6.0, 5.0]).requires_grad_())
    camera = ep.Camera(position=torch.tensor([0.3, 1.4, 2.6]).requires_grad_(), look_at=torch.tensor([0.0, 0.5, 0.0]),
                       fov=45.0, resolution=(40, 48))
    envmap = ep.EnvironmentMap(torch.rand(8, 16, 3, generator=g).requires_grad_())
    return ep.Scene(camera, [sphere, floor, lamp], envmap=envmap)


def parameters(scene):
    return [scene.meshes[0].vertices, scene.meshes[0].material.diffuse, scene.meshes[1].material.diffuse,
            scene.meshes[2].emission, scene.camera.position, scene.envmap.values]


def gradients(scene, threads):
    params = parameters(scene)
    for p in params:
        p.grad = None
    image = ep.render(scene, spp=2, max_bounces=2, seed=3, num_threads=threads)
    weights = torch.rand(image.shape, generator=torch.Generator().manual_seed(1))
    (image * weights).sum().backward()
    return [p.grad.clone() for p in params]


def test_gradients_are_the_same_bit_for_bit_whatever_the_thread_count():
    scene = make_scene()
    one = gradients(scene, 1)
    assert all(g.abs().sum() > 0 for g in one)  # every kind of parameter receives something
    for threads in (2, 2, None):  # None: every core
        for g, h in zip(gradients(scene, threads), one):
            assert torch.equal(g, h)


def test_derivative_images_are_the_same_bit_for_bit_whatever_the_thread_count():
    """The camera's edge samples (one per pixel and sample: four chunks of them here) splat their
    jumps over pixels of several tiles."""
    scene = make_scene()
    vertices = scene.meshes[0].vertices
    direction = torch.zeros_like(vertices)
    direction[:, 0] = 1.0
    one = ep.derivative_image(scene, vertices, direction, spp=8, max_bounces=1, seed=5, num_threads=1)
    assert one.abs().sum() > 0
    for threads in (2, 2, 2):
        assert torch.equal(ep.derivative_image(scene, vertices, direction, spp=8, max_bounces=1, seed=5,
                                               num_threads=threads), one)
