"""Material and environment-map recovery from images of two spheres.

Two spheres stand in an unknown environment (a latitude-longitude map with a sky gradient and a
bright sun): a known white, matte probe sphere, and a glossy sphere whose diffuse colour,
specular reflectance and roughness are unknown. From three views, gradient descent recovers
the glossy sphere's material and a low-resolution environment map. The probe fixes the overall
brightness (without it, a darker material under a brighter sky would look the same).

    python examples/material_envmap.py [--iterations 200] [--size 64] [--output-dir DIR]
"""

import math

import torch

import edgepath as ep
from edgepath import shapes
from _common import orbit_cameras, output_dir, parser, plot, report, row, run, save_images

TRUE_MATERIAL = {"diffuse": torch.tensor([0.7, 0.25, 0.1]), "specular": torch.tensor([0.4, 0.4, 0.4]),
                 "roughness": torch.tensor([0.15])}
START_MATERIAL = {"diffuse": torch.tensor([0.4, 0.4, 0.4]), "specular": torch.tensor([0.1, 0.1, 0.1]),
                  "roughness": torch.tensor([0.5])}
MAP_SIZE = (8, 16)


def true_envmap() -> torch.Tensor:
    """Blue sky above, brown ground below, a bright warm sun up and to one side (8 x 16)."""
    h, w = MAP_SIZE
    theta = (torch.arange(h) + 0.5) / h * math.pi  # row 0: straight up
    up = torch.cos(theta).clamp(min=0).unsqueeze(1).unsqueeze(2)
    down = (-torch.cos(theta)).clamp(min=0).unsqueeze(1).unsqueeze(2)
    values = (0.25 + 0.6 * up * torch.tensor([0.4, 0.6, 1.0]) + 0.3 * down * torch.tensor([0.5, 0.35, 0.2]))
    values = values.expand(h, w, 3).clone()
    values[2, 4] = torch.tensor([12.0, 10.0, 7.0])
    return values


SPHERE = shapes.sphere(radius=0.7, rings=16, segments=32)


def make_scene(material: dict, envmap: torch.Tensor, camera: ep.Camera) -> ep.Scene:
    v, i, uv, n = SPHERE
    glossy = ep.Mesh(v + torch.tensor([0.8, 0.0, 0.0]), i, uvs=uv, normals=n,
                     material=ep.Material(**material))
    probe = ep.Mesh(v - torch.tensor([0.8, 0.0, 0.0]), i, uvs=uv, normals=n,
                    material=ep.Material(diffuse=torch.tensor([0.8, 0.8, 0.8])))
    return ep.Scene(camera, [glossy, probe], ep.EnvironmentMap(envmap))


def set_unknowns(scene: ep.Scene, material: dict, envmap: torch.Tensor) -> None:
    """The glossy sphere's material and the map, changed on a kept scene (no scene build)."""
    scene.meshes[0].material = ep.Material(**material)
    scene.envmap = ep.EnvironmentMap(envmap)


def main(argv=None):
    args = parser(__doc__.splitlines()[0], iterations=200, size=64, spp=8).parse_args(argv)
    out = output_dir(args, "material_envmap")
    truth_map = true_envmap()
    cameras = orbit_cameras(args.size, count=3, distance=4.0, height=0.8, fov=50.0, offset_degrees=-60.0)
    # One scene for every step and view, the three views in one call: only the material and
    # the map change between steps, so nothing is built after the first step (scene.build_counts():
    # its two BVHs, the plain renders' and the gradient passes', each built once).
    scene = make_scene(TRUE_MATERIAL, truth_map, cameras[0])
    targets = ep.render(scene, spp=128, seed=args.seed + 10_000, cameras=cameras)

    # Unknowns, all positive: optimised through their logarithms.
    log_material = {k: v.log().requires_grad_() for k, v in START_MATERIAL.items()}
    log_map = torch.full(MAP_SIZE + (3,), math.log(0.5), requires_grad=True)  # start: uniform grey
    optimizer = torch.optim.Adam([{"params": list(log_material.values()), "lr": 0.03},
                                  {"params": [log_map], "lr": 0.05}])
    losses, material_errors = [], []
    truth_vector = torch.cat(list(TRUE_MATERIAL.values()))
    for step in range(args.iterations):
        optimizer.zero_grad()
        material = {k: v.exp() for k, v in log_material.items()}
        set_unknowns(scene, material, log_map.exp())
        images = ep.render(scene, spp=args.spp, seed=args.seed + step, cameras=cameras)
        loss = (images - targets).square().mean()  # the views' mean of each view's mean
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        estimate = torch.cat([v.detach() for v in material.values()])
        material_errors.append(float((estimate - truth_vector).norm()))
        report(args, step, losses[-1], extra=f"  material error {material_errors[-1]:.4f}")

    material = {k: v.detach().exp() for k, v in log_material.items()}
    recovered_map = log_map.detach().exp()
    start_map = torch.full(MAP_SIZE + (3,), 0.5)
    set_unknowns(scene, START_MATERIAL, start_map)
    start_views = ep.render(scene, spp=128, cameras=cameras)
    set_unknowns(scene, material, recovered_map)
    result_views = ep.render(scene, spp=128, cameras=cameras)
    # The maps scaled up 8x (nearest) and tone-mapped so that the sun does not hide the sky.
    show = lambda m: (m / (1 + m)).repeat_interleave(8, 0).repeat_interleave(8, 1)  # noqa: E731
    save_images(out, {"target": row(targets), "start": row(start_views), "result": row(result_views),
                      "envmap_true_vs_recovered": row([show(truth_map), show(recovered_map)])})
    plot(f"{out}/loss.png", {"image loss": losses, "material error": material_errors}, "value",
         "material and environment-map recovery")
    print(f"material/envmap: loss {losses[0]:.4g} -> {losses[-1]:.4g}, material error "
          f"{material_errors[0]:.3f} -> {material_errors[-1]:.4f}; diffuse "
          f"{[round(x, 3) for x in material['diffuse'].tolist()]}, specular "
          f"{[round(x, 3) for x in material['specular'].tolist()]}, roughness "
          f"{float(material['roughness']):.3f}; pictures in {out}")
    return {"loss": losses, "material_error": material_errors, "material": material,
            "envmap": recovered_map, "build_counts": scene.build_counts()}


if __name__ == "__main__":
    run(main)
