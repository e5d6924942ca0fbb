"""Shadow-driven occluder recovery: find a plate that the camera never sees from its shadow.

The camera looks down at a floor; a lamp to the side shines past a square plate held above the
floor, outside the camera's view. Only the plate's shadow is in the image, so the whole
gradient with respect to the plate's position and rotation comes from the shadow's edges
(secondary edge sampling): with ``--no-secondary-edges`` the plate does not move at all.

    python examples/shadow_occluder.py [--iterations 120] [--size 64] [--output-dir DIR]
"""


import torch

import edgepath as ep
from edgepath import shapes
from _common import lamp, output_dir, parser, plot, report, row, run, save_images

# The plate: centre (x, z) at height PLATE_HEIGHT, rotation about the vertical axis (radians).
TRUE_PLATE = torch.tensor([-1.2, 0.1, 0.5])
START_PLATE = torch.tensor([-1.0, -0.25, 0.1])
PLATE_HEIGHT = 1.6
PLATE_HALF = 0.35


def make_scene(plate: torch.Tensor, size: int) -> ep.Scene:
    x, z, angle = plate.unbind()
    c, s = torch.cos(angle), torch.sin(angle)
    local = torch.tensor([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * PLATE_HALF
    px = x + c * local[:, 0] - s * local[:, 1]
    pz = z + s * local[:, 0] + c * local[:, 1]
    corners = torch.stack([px, torch.full_like(px, PLATE_HEIGHT), pz], dim=1)
    plate_mesh = ep.Mesh(corners, torch.tensor([[0, 1, 2], [0, 2, 3]]),
                         material=ep.Material(diffuse=torch.tensor([0.5, 0.5, 0.5]), two_sided=True))
    fv, fi, fuv, fn = shapes.grid(size=(6.0, 6.0))
    floor = ep.Mesh(fv, fi, uvs=fuv, normals=fn, material=ep.Material(diffuse=torch.tensor([0.8, 0.8, 0.8])))
    light = lamp((-3.0, 3.5, 0.0), 0.4, 60.0, facing=(0.5, 0.0, 0.0))
    # Straight down at the floor; the plate (x < -0.5) is outside the view.
    camera = ep.Camera(position=torch.tensor([0.5, 3.0, 0.0]), look_at=torch.tensor([0.5, 0.0, 0.0]),
                       up=torch.tensor([0.0, 0.0, -1.0]), fov=40.0, resolution=(size, size))
    return ep.Scene(camera, [plate_mesh, floor, light])


def main(argv=None):
    p = parser(__doc__.splitlines()[0], iterations=120, size=64, spp=4)
    p.add_argument("--no-secondary-edges", action="store_true",
                   help="switch off the shadow-edge term of the gradient (the plate then stays put)")
    args = p.parse_args(argv)
    out = output_dir(args, "shadow_occluder")
    target = ep.render(make_scene(TRUE_PLATE, args.size), spp=128, seed=args.seed + 10_000)

    plate = START_PLATE.clone().requires_grad_()
    optimizer = torch.optim.Adam([plate], lr=0.02)
    losses, errors = [], []
    for step in range(args.iterations):
        optimizer.zero_grad()
        image = ep.render(make_scene(plate, args.size), spp=args.spp, seed=args.seed + step,
                          secondary_edges=not args.no_secondary_edges)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        errors.append(float((plate.detach() - TRUE_PLATE).norm()))
        report(args, step, losses[-1], extra=f"  plate error {errors[-1]:.4f}")

    start = ep.render(make_scene(START_PLATE, args.size), spp=128)
    result = ep.render(make_scene(plate.detach(), args.size), spp=128)
    save_images(out, {"target": target, "start": start, "result": result,
                      "comparison": row([target, start, result])})
    plot(f"{out}/loss.png", {"image loss": losses, "plate parameter error": errors}, "value",
         "shadow-driven occluder recovery")
    print(f"shadow occluder: loss {losses[0]:.4g} -> {losses[-1]:.4g}, plate (x, z, angle) "
          f"{[round(v, 3) for v in plate.detach().tolist()]} (truth {TRUE_PLATE.tolist()}), "
          f"error {errors[0]:.3f} -> {errors[-1]:.4f}; pictures in {out}")
    return {"loss": losses, "error": errors, "plate": plate.detach()}


if __name__ == "__main__":
    run(main)
