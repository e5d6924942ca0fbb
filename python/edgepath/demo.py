"""The built-in demo scene: a red triangle in front of a grey wall, lit by a square area light
behind the camera. ``edgepath demo`` renders it."""

from __future__ import annotations

from typing import Tuple

import torch

from .scene import Camera, Material, Mesh, Scene


def quad(corners) -> Tuple[torch.Tensor, torch.Tensor]:
    """Vertices and indices of a quad given by 4 corners in order; the face normal follows
    the right-hand rule around them."""
    return torch.tensor(corners, dtype=torch.float32), torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32)


def default_scene(resolution: Tuple[int, int] = (256, 256)) -> Scene:
    camera = Camera(position=torch.tensor([0.0, 0.0, -5.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                    up=torch.tensor([0.0, 1.0, 0.0]), fov=45.0, resolution=resolution)
    triangle = Mesh(vertices=torch.tensor([[-1.7, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.5, -1.0, 0.0]]),
                    indices=torch.tensor([[0, 1, 2]], dtype=torch.int32),
                    material=Material(diffuse=torch.tensor([0.8, 0.2, 0.2]),
                                      specular=torch.tensor([0.04, 0.04, 0.04]), roughness=0.3))
    # A wall at z = 2 facing the camera (normal -z) and a lamp at z = -7 facing the scene (+z).
    wall_v, wall_i = quad([[-4, -4, 2], [-4, 4, 2], [4, 4, 2], [4, -4, 2]])
    wall = Mesh(vertices=wall_v, indices=wall_i, material=Material(diffuse=torch.tensor([0.5, 0.5, 0.5])))
    lamp_v, lamp_i = quad([[-2, -2, -7], [2, -2, -7], [2, 2, -7], [-2, 2, -7]])
    lamp = Mesh(vertices=lamp_v, indices=lamp_i, emission=torch.tensor([20.0, 20.0, 20.0]))
    return Scene(camera=camera, meshes=[triangle, wall, lamp])
