"""Fit a triangle's three vertices to a target image.

An orange triangle in front of a white sky: the inside of the triangle looks the same wherever
its vertices are, so the whole gradient comes from its edges (primary edge sampling). The
vertices move in the triangle's plane (x, y). Writes target, start and result images, a GIF-like
strip of the progress and the loss against iteration.

    python examples/single_triangle.py [--iterations 100] [--size 64] [--output-dir DIR]
"""


import torch

import edgepath as ep
from _common import output_dir, parser, plot, report, row, run, save_images

TRUE_XY = torch.tensor([[-1.0, -0.8], [1.1, -0.6], [0.1, 1.0]])
START_XY = torch.tensor([[-0.6, -0.3], [0.5, -0.9], [-0.3, 0.5]])


def make_scene(xy: torch.Tensor, size: int) -> ep.Scene:
    vertices = torch.cat([xy, torch.zeros(3, 1)], dim=1)
    triangle = ep.Mesh(vertices, torch.tensor([[0, 1, 2]]),
                       material=ep.Material(diffuse=torch.tensor([0.9, 0.5, 0.1]), two_sided=True))
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, 4.0]), look_at=torch.zeros(3), fov=45.0,
                       resolution=(size, size))
    return ep.Scene(camera, [triangle], ep.EnvironmentMap(torch.ones(1, 1, 3)))


def main(argv=None):
    args = parser(__doc__.splitlines()[0], iterations=100, size=64, spp=4).parse_args(argv)
    out = output_dir(args, "single_triangle")
    target = ep.render(make_scene(TRUE_XY, args.size), spp=64, seed=args.seed + 10_000)

    xy = START_XY.clone().requires_grad_()
    optimizer = torch.optim.Adam([xy], lr=0.03)
    losses, errors, snapshots = [], [], []
    for step in range(args.iterations):
        optimizer.zero_grad()
        image = ep.render(make_scene(xy, args.size), spp=args.spp, seed=args.seed + step)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        errors.append(float((xy.detach() - TRUE_XY).norm(dim=1).mean()))
        if step % max(1, args.iterations // 4) == 0:
            snapshots.append(image.detach())
        report(args, step, losses[-1], extra=f"  vertex error {errors[-1]:.3f}")

    result = ep.render(make_scene(xy.detach(), args.size), spp=64, seed=args.seed + 20_000)
    save_images(out, {"target": target, "start": ep.render(make_scene(START_XY, args.size), spp=64),
                      "result": result, "progress": row(snapshots + [result])})
    plot(f"{out}/loss.png", {"image loss": losses, "mean vertex error": errors}, "value",
         "single triangle: loss and vertex error")
    print(f"single triangle: loss {losses[0]:.4g} -> {losses[-1]:.4g}, "
          f"mean vertex error {errors[0]:.3f} -> {errors[-1]:.3f}; pictures in {out}")
    return {"loss": losses, "error": errors, "vertices": xy.detach()}


if __name__ == "__main__":
    run(main)
