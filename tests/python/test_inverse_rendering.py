"""Inverse rendering through the interior gradient: recover a glossy sphere's diffuse colour and
roughness and the intensity of the area light from one target image, by Adam."""

import math
import time

import torch

import edgepath as ep
from edgepath import shapes

TRUTH = {"diffuse": [0.7, 0.3, 0.2], "roughness": 0.25, "intensity": 12.0}
START = {"diffuse": [0.4, 0.4, 0.4], "roughness": 0.5, "intensity": 6.0}


def make_scene(diffuse, roughness, intensity) -> ep.Scene:
    v, i, uv, n = shapes.sphere(radius=1.0, rings=24, segments=48)
    sphere = ep.Mesh(v, i, uvs=uv, normals=n,
                     material=ep.Material(diffuse=diffuse, specular=torch.tensor([0.3, 0.3, 0.3]),
                                          roughness=roughness))
    # A 1.5 x 1.5 lamp up and to the left, in front of the sphere, facing it.
    centre = torch.tensor([-2.0, 2.0, 2.5])
    normal = torch.nn.functional.normalize(-centre, dim=0)
    a = torch.nn.functional.normalize(torch.linalg.cross(normal, torch.tensor([0.0, 1.0, 0.0])), dim=0)
    b = torch.linalg.cross(normal, a)  # a x b = normal: the corners run counter-clockwise
    corners = torch.stack([centre + 0.75 * (sa * a + sb * b)
                           for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    lamp = ep.Mesh(corners, torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32),
                   emission=intensity * torch.ones(3))
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, 4.0]), look_at=torch.zeros(3), fov=40.0,
                       resolution=(48, 48))
    sky = ep.EnvironmentMap(torch.full((1, 1, 3), 0.4))  # known ambient light
    return ep.Scene(camera=camera, meshes=[sphere, lamp], envmap=sky)


def test_recover_colour_roughness_and_light_intensity():
    start_time = time.perf_counter()
    target = ep.render(make_scene(torch.tensor(TRUTH["diffuse"]), TRUTH["roughness"],
                                  torch.tensor(TRUTH["intensity"])), spp=512, seed=100)
    assert target[..., 0].max() > 0.5  # the lamp lights the sphere

    # Positive parameters optimised in log space.
    log_diffuse = torch.tensor(START["diffuse"]).log().requires_grad_()
    log_roughness = torch.tensor(math.log(START["roughness"])).requires_grad_()
    log_intensity = torch.tensor(math.log(START["intensity"])).requires_grad_()
    params = [log_diffuse, log_roughness, log_intensity]
    optimizer = torch.optim.Adam(params, lr=0.05)
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=0.995)
    history = []
    losses = []
    for step in range(500):
        optimizer.zero_grad()
        scene = make_scene(log_diffuse.exp(), log_roughness.exp().reshape(1), log_intensity.exp())
        image = ep.render(scene, spp=8, seed=step)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(float(loss))
        history.append(torch.cat([log_diffuse.exp(), log_roughness.exp().reshape(1),
                                  log_intensity.exp().reshape(1)]).detach())
    seconds = time.perf_counter() - start_time

    # The average of the last iterates (the steps are noisy).
    estimate = torch.stack(history[-100:]).mean(0)
    truth = torch.tensor(TRUTH["diffuse"] + [TRUTH["roughness"], TRUTH["intensity"]])
    relative = (estimate - truth).abs() / truth
    print(f"{seconds:.1f} s, loss {losses[0]:.4g} -> {sum(losses[-20:]) / 20:.4g}; "
          f"estimate {estimate.tolist()}, truth {truth.tolist()}, relative error {relative.tolist()}")
    assert (relative < 0.05).all(), f"relative errors {relative.tolist()}"
