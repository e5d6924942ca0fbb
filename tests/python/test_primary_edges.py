"""Primary visibility: the boundary term of edges seen by the camera.

Closed form: an emissive triangle over black seen through a box filter renders, summed over the
image, its radiance times its projected area clipped to the film (in pixels). The gradient of
the image sum with respect to the vertices and the camera is therefore the derivative of that
area, computed here by torch autograd through an explicit projection and polygon clipping in
float64. The renderer's gradient comes from edge sampling alone (the interior term of a
constant emitter is zero), so this checks the estimator, the projection's adjoint and the
clipping of edges to the image.
"""

import math

import pytest
import torch

import edgepath as ep
from edgepath import shapes

W, H = 64, 48
RADIANCE = (1.0, 2.0, 0.5)
EDGE_SAMPLES = 200000


def camera_frame(position, look_at, up):
    f = torch.nn.functional.normalize(look_at - position, dim=0)
    r = torch.nn.functional.normalize(torch.linalg.cross(f, up), dim=0)
    return f, r, torch.linalg.cross(r, f)


def project(v, cam, kind):
    """Film coordinates (pixels of the full film, y down) of points v (N, 3)."""
    f, r, u = camera_frame(cam["position"], cam["look_at"], cam["up"])
    q = v - cam["position"]
    x, y, z = q @ r, q @ u, q @ f
    if kind == "perspective":
        tx = torch.tan(torch.deg2rad(cam["fov"]) / 2)
        x, y = x / z, y / z
    else:
        tx = cam["ortho_scale"]
    return torch.stack([(x / tx + 1) * W / 2, (1 - y * W / (tx * H)) * H / 2], -1)


def _clip(poly, axis, value, keep_below):
    out = []
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        a_in = bool(a[axis] <= value) if keep_below else bool(a[axis] >= value)
        b_in = bool(b[axis] <= value) if keep_below else bool(b[axis] >= value)
        if a_in:
            out.append(a)
        if a_in != b_in:
            out.append(a + (value - a[axis]) / (b[axis] - a[axis]) * (b - a))
    return out


def clipped_area(points):
    """Area of the triangle `points` (3, 2) inside [0, W] x [0, H] (Sutherland-Hodgman)."""
    poly = [points[i] for i in range(3)]
    for axis, value, below in ((0, 0.0, False), (0, float(W), True), (1, 0.0, False), (1, float(H), True)):
        poly = _clip(poly, axis, value, below)
        if not poly:
            return points.sum() * 0
    twice = sum(poly[i][0] * poly[(i + 1) % len(poly)][1] - poly[(i + 1) % len(poly)][0] * poly[i][1]
                for i in range(len(poly)))
    return twice.abs() / 2


TRIANGLES = {
    "inside": [[-1.7, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.5, -1.0, 0.0]],
    "tilted": [[-2.0, 1.5, 0.3], [0.9, 1.2, -0.3], [-0.4, -1.4, 0.2]],
    "partly outside": [[-2.5, 1.5, 0.3], [0.9, 1.2, -0.3], [-0.4, -1.4, 0.2]],
    "over a corner": [[1.2, 0.4, 0.5], [3.5, 0.9, -0.2], [2.0, 2.8, 0.1]],
}

CAMERAS = {
    "perspective": dict(position=[0.3, -0.2, -5.0], look_at=[0.0, 0.1, 0.0], up=[0.1, 1.0, 0.0], fov=45.0,
                        ortho_scale=1.0),
    "orthographic": dict(position=[0.3, -0.2, -5.0], look_at=[0.1, 0.1, 0.0], up=[0.1, 1.0, 0.0], fov=45.0,
                         ortho_scale=2.2),
}


def _camera_tensors(kind, dtype):
    return {k: torch.tensor(v, dtype=dtype, requires_grad=True) for k, v in CAMERAS[kind].items()}


@pytest.mark.parametrize("kind", list(CAMERAS))
@pytest.mark.parametrize("name", list(TRIANGLES))
def test_image_sum_gradient_is_projected_area_derivative(name, kind):
    # Closed form, float64.
    v64 = torch.tensor(TRIANGLES[name], dtype=torch.float64, requires_grad=True)
    cam64 = _camera_tensors(kind, torch.float64)
    area = clipped_area(project(v64, cam64, kind))
    assert 0 < float(area.detach()) < W * H  # every case has some of the triangle in view
    area.backward()
    scale = sum(RADIANCE)
    unused = "ortho_scale" if kind == "perspective" else "fov"
    keys = [k for k in ("position", "look_at", "up", "fov", "ortho_scale") if k != unused]
    expected = {"vertices": v64.grad * scale, **{k: cam64[k].grad * scale for k in keys}}

    # The renderer.
    v = torch.tensor(TRIANGLES[name], requires_grad=True)
    cam = _camera_tensors(kind, torch.float32)
    mesh = ep.Mesh(vertices=v, indices=torch.tensor([[0, 1, 2]]), emission=torch.tensor(RADIANCE),
                   two_sided_emission=True)
    camera = ep.Camera(position=cam["position"], look_at=cam["look_at"], up=cam["up"], fov=cam["fov"],
                       ortho_scale=cam["ortho_scale"], camera_type=kind, resolution=(H, W))
    image = ep.render(ep.Scene(camera=camera, meshes=[mesh]), spp=64, max_bounces=0, seed=1,
                      edge_samples=EDGE_SAMPLES)
    # The image itself: radiance times clipped area (pixel-sampling noise only).
    assert float(image.sum()) / scale == pytest.approx(float(area.detach()), rel=5e-3)
    image.sum().backward()
    got = {"vertices": v.grad, **{k: cam[k].grad for k in keys}}
    assert cam[unused].grad is None or float(cam[unused].grad.abs()) == 0.0
    for key, want in expected.items():
        g = got[key].double()
        tol = 3e-3 * float(want.abs().max()) + 1e-4 * scale * float(area.detach())
        assert torch.allclose(g, want, atol=tol, rtol=0), f"{name}, {kind}, {key}: {g} vs {want}"


def test_edge_sample_count_and_switch():
    """Without primary edges the triangle gets no vertex gradient at all; the number of edge
    samples changes only the noise."""
    v = torch.tensor(TRIANGLES["inside"], requires_grad=True)
    mesh = ep.Mesh(vertices=v, indices=torch.tensor([[0, 1, 2]]), emission=torch.tensor(RADIANCE))
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, -5.0]), look_at=torch.zeros(3),
                       up=torch.tensor([0.0, 1.0, 0.0]), fov=45.0, resolution=(H, W))
    scene = ep.Scene(camera=camera, meshes=[mesh])
    ep.render(scene, spp=2, max_bounces=0, primary_edges=False).sum().backward()
    assert float(v.grad.abs().sum()) == 0.0
    grads = []
    for n in (2000, 200000):
        v.grad = None
        ep.render(scene, spp=2, max_bounces=0, edge_samples=n).sum().backward()
        grads.append(v.grad.clone())
    assert torch.allclose(grads[0], grads[1], rtol=0, atol=0.05 * float(grads[1].abs().max()))
    with pytest.raises(ValueError, match="edge_samples"):
        ep.render(scene, edge_samples=0)
    with pytest.raises(ValueError, match="primary_edges"):
        ep.render(scene, primary_edges="yes")
