"""Inverse rendering through silhouettes: geometry recovered from images by edge-sampling
gradients.

(a) An emissive triangle over black, max_bounces=0: the image is the triangle's coverage, whose
    gradient with respect to the vertices is entirely a boundary term (the interior of a constant
    emitter does not change). Adam on an MSE image loss moves a tilted, offset triangle onto the
    target; its projected vertices must land within half a pixel of the target's.
(b) The 6-DoF pose (rotation vector and translation) of a textured, diffuse cube under a smooth
    environment map, max_bounces=1. The gradient combines the silhouette and crease edges with
    the interior term of the texture sliding over the pixels; the rotation must come back within
    a degree and the translation within 1% of the cube's edge length.

Both are seeded (a new seed per iteration): the images and the gradients are reproducible bit
for bit.
``pytest -s`` prints the timing and the final errors.
"""

import math
import time

import pytest
import torch

import edgepath as ep
from test_primary_edges import project as project_points

# ---- shared helpers --------------------------------------------------------------------------


def make_camera(position, fov, resolution):
    return ep.Camera(position=torch.tensor(position), look_at=torch.zeros(3),
                     up=torch.tensor([0.0, 1.0, 0.0]), fov=fov, resolution=resolution)


def project(points, camera):
    """Film coordinates (pixels, y down) of points (N, 3) seen by a perspective ``camera``, in
    float64 (the camera model of test_primary_edges)."""
    position, look_at, up = (t.double() for t in camera.frame())
    cam = dict(position=position, look_at=look_at, up=up, fov=float(camera.fov))
    return project_points(points.double(), cam, "perspective", camera.resolution)


def rodrigues(rotvec):
    """Rotation matrix of a rotation vector (axis times angle in radians), differentiable:
    R = I + sin(a) K + (1 - cos(a)) K^2 with K the cross-product matrix of the unit axis. (The
    tiny epsilon only keeps the axis defined at zero; every rotation used here is far from it.)"""
    angle = torch.sqrt((rotvec * rotvec).sum() + 1e-20)
    k = rotvec / angle
    zero = torch.zeros((), dtype=rotvec.dtype)
    K = torch.stack([torch.stack([zero, -k[2], k[1]]),
                     torch.stack([k[2], zero, -k[0]]),
                     torch.stack([-k[1], k[0], zero])])
    return torch.eye(3, dtype=rotvec.dtype) + torch.sin(angle) * K + (1 - torch.cos(angle)) * (K @ K)


def rotation_vector(R):
    """Inverse of ``rodrigues`` for a rotation by an angle in (0, pi)."""
    angle = torch.acos(((torch.trace(R) - 1) / 2).clamp(-1, 1))
    axis = torch.stack([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return axis * angle / (2 * torch.sin(angle))


def rotation_angle_deg(R):
    return math.degrees(float(torch.acos(((torch.trace(R) - 1) / 2).clamp(-1, 1))))


# ---- (a) a triangle's vertices ---------------------------------------------------------------

TRIANGLE_TARGET = [[-1.7, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.5, -1.0, 0.0]]
TRIANGLE_START = [[-2.0, 1.5, 0.3], [0.9, 1.2, -0.3], [-0.4, -1.4, 0.2]]


def triangle_scene(vertices):
    camera = make_camera([0.0, 0.0, -5.0], 45.0, (256, 256))
    mesh = ep.Mesh(vertices=vertices, indices=torch.tensor([[0, 1, 2]], dtype=torch.int32),
                   emission=torch.ones(3), two_sided_emission=True)
    return ep.Scene(camera=camera, meshes=[mesh])


@pytest.mark.slow  # about 15 s on 2 cores
def test_triangle_recovers_target_vertices():
    """Adam on the MSE to a 256-spp target, 4 spp per step (a new seed each step), learning rate
    decaying from 0.02 (world units; about 1.2 pixels here) by 3% per step. The depth of each
    vertex along its camera ray is barely constrained by the image, so the check is on the
    projected vertices (within 0.5 pixel of the target's) and on the image: its mean absolute
    difference to the target, both rendered with 256 spp and independent seeds, below 1% of the
    target image's mean value (the stricter normalisation: the mean is ~0.16, the maximum 1)."""
    start_time = time.perf_counter()
    target_vertices = torch.tensor(TRIANGLE_TARGET)
    target = ep.render(triangle_scene(target_vertices), spp=256, max_bounces=0, seed=0)
    camera = triangle_scene(target_vertices).camera
    target_px = project(target_vertices, camera)

    vertices = torch.tensor(TRIANGLE_START, requires_grad=True)
    start_error = (project(vertices.detach(), camera) - target_px).norm(dim=1)
    assert start_error.min() > 10  # every vertex starts well away from its target

    optimizer = torch.optim.Adam([vertices], lr=0.02)
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=0.97)
    losses = []
    for step in range(120):
        optimizer.zero_grad()
        image = ep.render(triangle_scene(vertices), spp=4, max_bounces=0, seed=step + 1)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())

    final = vertices.detach()
    pixel_error = (project(final, camera) - target_px).norm(dim=1)
    image = ep.render(triangle_scene(final), spp=256, max_bounces=0, seed=10**6)
    mad = float((image - target).abs().mean())
    relative_mad = mad / float(target.mean())
    seconds = time.perf_counter() - start_time
    print(f"\ntriangle: {seconds:.1f} s, loss {losses[0]:.3g} -> {losses[-1]:.3g}; "
          f"projected vertex error (px) {start_error.tolist()} -> {pixel_error.tolist()}; "
          f"image MAD {mad:.3g} = {100 * relative_mad:.3f}% of the target's mean; "
          f"vertices {final.tolist()}")
    assert (pixel_error < 0.5).all(), f"projected vertex errors {pixel_error.tolist()} px"
    assert relative_mad < 0.01, f"image MAD {100 * relative_mad:.3f}% of the target's mean"


# ---- (b) the pose of a textured cube ---------------------------------------------------------

CUBE_EDGE = 1.0
POSE_TRUE = {"rotvec": [0.5, 0.9, 0.3], "translation": [0.1, -0.05, 0.2]}
PERTURBATION = {"axis": [1.0, -1.0, 2.0], "degrees": 12.0, "translation": [0.06, -0.05, 0.06]}


def cube():
    """Object-space unit cube: 8 corners, 12 triangles (counter-clockwise seen from outside) and
    per-face uvs into a 3 x 2 atlas, one cell per face, so that every face shows a different
    part of the texture."""
    h = CUBE_EDGE / 2
    corners = torch.tensor([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)],
                           dtype=torch.float64)  # index 4 i + 2 j + k for signs (x, y, z)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5],   # -x, +x
             [0, 4, 5, 1], [2, 3, 7, 6],   # -y, +y
             [0, 2, 6, 4], [1, 5, 7, 3]]   # -z, +z
    indices, uvs, uv_indices = [], [], []
    for f, (a, b, c, d) in enumerate(faces):
        col, row, base = f % 3, f // 3, len(uvs)
        for s, t in ((0, 0), (1, 0), (1, 1), (0, 1)):  # the cell, inset from its borders
            uvs.append([(col + 0.05 + 0.9 * s) / 3, (row + 0.05 + 0.9 * t) / 2])
        indices += [[a, b, c], [a, c, d]]
        uv_indices += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return (corners, torch.tensor(indices, dtype=torch.int32), torch.tensor(uvs),
            torch.tensor(uv_indices, dtype=torch.int32))


def cube_texture():
    """Diffuse albedo: red along u, green along v (a gradient across the whole atlas, so no two
    faces or orientations look alike) and a checker in blue for fine detail."""
    height, width = 96, 144
    v, u = torch.meshgrid((torch.arange(height) + 0.5) / height,
                          (torch.arange(width) + 0.5) / width, indexing="ij")
    checker = (torch.floor(u * 24) + torch.floor(v * 16)) % 2
    return torch.stack([0.15 + 0.7 * u, 0.15 + 0.7 * v, 0.2 + 0.5 * checker], -1).float()


def sky():
    """A smooth environment map: brighter overhead, warmer on one side."""
    height, width = 16, 32
    theta = (torch.arange(height) + 0.5) / height * math.pi
    phi = (torch.arange(width) + 0.5) / width * 2 * math.pi
    vertical = (0.6 + 0.4 * torch.cos(theta))[:, None].expand(height, width)  # row 0 is +y
    horizontal = 0.15 * torch.cos(phi)[None, :]
    return torch.stack([vertical + horizontal, vertical, vertical - horizontal], -1).float()


CUBE = cube()
TEXTURE = cube_texture()
SKY = sky()


def cube_scene(rotvec, translation):
    corners, indices, uvs, uv_indices = CUBE
    vertices = corners @ rodrigues(rotvec).T + translation  # flat shading: no normals needed
    mesh = ep.Mesh(vertices=vertices.float(), indices=indices, uvs=uvs, uv_indices=uv_indices,
                   material=ep.Material(diffuse=TEXTURE))
    camera = make_camera([0.0, 0.0, -3.5], 40.0, (96, 96))
    return ep.Scene(camera=camera, meshes=[mesh], envmap=ep.EnvironmentMap(SKY))


def test_textured_object_pose_6dof():
    """A 12-degree rotation about a skew axis and a 0.1 (10% of the edge) translation away from
    the true pose; Adam on the MSE to a 256-spp target at 96 x 96, 4 spp per step, learning rate
    0.02 decaying by 2% per step. The recovered rotation must be within 1 degree of the truth
    (angle of R_est^T R_true) and the translation within 1% of the cube's edge length."""
    start_time = time.perf_counter()
    rotvec_true = torch.tensor(POSE_TRUE["rotvec"], dtype=torch.float64)
    translation_true = torch.tensor(POSE_TRUE["translation"], dtype=torch.float64)
    R_true = rodrigues(rotvec_true)
    target = ep.render(cube_scene(rotvec_true, translation_true), spp=256, max_bounces=1, seed=0)

    axis = torch.nn.functional.normalize(torch.tensor(PERTURBATION["axis"], dtype=torch.float64), dim=0)
    R_start = rodrigues(axis * math.radians(PERTURBATION["degrees"])) @ R_true
    rotvec = rotation_vector(R_start).requires_grad_()
    translation = (translation_true + torch.tensor(PERTURBATION["translation"],
                                                   dtype=torch.float64)).requires_grad_()
    start_rotation = rotation_angle_deg(R_start.T @ R_true)
    start_translation = float((translation.detach() - translation_true).norm()) / CUBE_EDGE
    assert abs(start_rotation - PERTURBATION["degrees"]) < 1e-6  # the helpers invert each other

    optimizer = torch.optim.Adam([rotvec, translation], lr=0.02)
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=0.98)
    losses = []
    for step in range(150):
        optimizer.zero_grad()
        image = ep.render(cube_scene(rotvec, translation), spp=4, max_bounces=1, seed=step + 1)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())

    with torch.no_grad():
        rotation_error = rotation_angle_deg(rodrigues(rotvec).T @ R_true)
        translation_error = float((translation - translation_true).norm()) / CUBE_EDGE
    seconds = time.perf_counter() - start_time
    print(f"\ncube pose: {seconds:.1f} s, loss {losses[0]:.3g} -> {losses[-1]:.3g}; "
          f"rotation error {start_rotation:.2f} -> {rotation_error:.4f} deg; translation error "
          f"{100 * start_translation:.2f}% -> {100 * translation_error:.4f}% of the edge length")
    assert rotation_error < 1.0, f"rotation error {rotation_error:.3f} degrees"
    assert translation_error < 0.01, f"translation error {100 * translation_error:.3f}% of the edge"
