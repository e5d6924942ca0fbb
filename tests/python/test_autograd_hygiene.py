"""Autograd as torch's own ops behave: a scene tensor edited in place between the render and
``backward()`` raises, double backward raises instead of returning a gradient without its
second-order part, and forward-mode derivative images work from several threads at once."""

from concurrent.futures import ThreadPoolExecutor

import pytest
import torch

import edgepath as ep


def small_scene(vertices=None, resolution=(12, 16)):
    """A lit triangle in front of the camera; ``vertices`` (3, 3) default to a fixed one."""
    if vertices is None:
        vertices = torch.tensor([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.2, -1.0, 0.0]])
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, -4.0]), look_at=torch.zeros(3),
                       up=torch.tensor([0.0, 1.0, 0.0]), fov=45.0, resolution=resolution)
    tri = ep.Mesh(vertices=vertices, indices=torch.tensor([[0, 1, 2]], dtype=torch.int32),
                  material=ep.Material(diffuse=torch.tensor([0.7, 0.5, 0.3])))
    return ep.Scene(camera=camera, meshes=[tri], envmap=ep.EnvironmentMap(values=torch.ones(1, 1, 3)))


@pytest.mark.parametrize("what", ["vertices", "indices", "diffuse", "envmap"])
@pytest.mark.parametrize("function", ["render", "render_channels"])
def test_editing_a_scene_tensor_before_backward_raises(what, function):
    scene = small_scene(torch.tensor([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.2, -1.0, 0.0]],
                                     requires_grad=True))
    mesh = scene.meshes[0]
    if function == "render":
        image = ep.render(scene, spp=1)
    else:
        image = ep.render_channels(scene, ["radiance", "alpha"], spp=1)["alpha"]
    with torch.no_grad():  # as an optimiser's step would
        if what == "vertices":
            mesh.vertices.add_(0.1)
        elif what == "indices":
            mesh.indices[0, 0] = 1
        elif what == "diffuse":
            mesh.material.diffuse.mul_(0.5)
        else:
            scene.envmap.values.fill_(2.0)
    field = {"vertices": "meshes[0].vertices", "indices": "meshes[0].indices",
             "diffuse": "meshes[0].material.diffuse", "envmap": "envmap.values"}[what]
    with pytest.raises(RuntimeError, match=r"modified by an inplace operation") as info:
        image.sum().backward()
    assert field in str(info.value)


def test_edits_after_backward_and_copies_are_fine():
    """The usual loop (render, backward, step) keeps working, and a tensor the flattening
    converted (float64 vertices) may change: the gradient is that of the rendered scene."""
    v64 = torch.tensor([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.2, -1.0, 0.0]], dtype=torch.float64,
                       requires_grad=True)
    image = ep.render(small_scene(v64), spp=2, backward_seed=0)
    with torch.no_grad():
        v64.add_(0.05)  # before backward: the render read a float32 copy
    image.sum().backward()
    grad_edited = v64.grad.clone()
    v64.grad = None
    with torch.no_grad():
        v64.sub_(0.05)
    image = ep.render(small_scene(v64), spp=2, backward_seed=0)
    image.sum().backward()
    assert torch.equal(v64.grad, grad_edited) or torch.allclose(v64.grad, grad_edited, rtol=1e-5)
    assert v64.grad.abs().sum() > 0
    with torch.no_grad():
        v64.sub_(0.01 * v64.grad)  # a step after backward
    ep.render(small_scene(v64), spp=1).sum().backward()


def test_double_backward_raises():
    v = torch.tensor([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.2, -1.0, 0.0]], requires_grad=True)
    image = ep.render(small_scene(v), spp=1)
    loss = image.sum() + (v ** 2).sum()  # a loss with a part whose second derivative exists
    (g,) = torch.autograd.grad(loss, v, create_graph=True)
    assert g.requires_grad
    with pytest.raises(RuntimeError, match="differentiate twice"):
        g.sum().backward()


def test_double_backward_of_channels_raises():
    v = torch.tensor([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.2, -1.0, 0.0]], requires_grad=True)
    alpha = ep.render_channels(small_scene(v), ["alpha"], spp=1)["alpha"]
    (g,) = torch.autograd.grad(alpha.sum() + v.pow(3).sum(), v, create_graph=True)
    with pytest.raises(RuntimeError, match="differentiate twice"):
        torch.autograd.grad(g.sum(), v)


def test_derivative_images_from_several_threads():
    scene = small_scene()
    param = scene.meshes[0].vertices
    direction = torch.tensor([[1.0, 0.0, 0.0]] * 3)
    expected = ep.derivative_image(scene, param, direction, spp=2, num_threads=1)
    assert expected.abs().sum() > 0

    def one(_):
        return ep.derivative_image(scene, param, direction, spp=2, num_threads=1)

    with ThreadPoolExecutor(max_workers=8) as pool:
        results = list(pool.map(one, range(32)))
    for image in results:
        torch.testing.assert_close(image, expected, rtol=1e-5, atol=1e-6)
