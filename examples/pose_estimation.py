"""6-DoF pose estimation: recover an object's rotation and translation from one image.

The object is two boxes of different colours joined in an L (no symmetry). Its pose is an
axis-angle rotation and a translation; the renderer's gradient reaches them through the
vertices, both from the shading inside and from the silhouette (edge sampling).

    python examples/pose_estimation.py [--iterations 150] [--size 96] [--output-dir DIR]
"""


import torch

import edgepath as ep
from _common import output_dir, parser, plot, report, rotation, row, run, save_images

TRUE_ROTATION = torch.tensor([0.4, -0.6, 0.2])
TRUE_TRANSLATION = torch.tensor([0.2, -0.1, 0.0])
START_ROTATION = torch.tensor([0.1, -0.2, 0.0])
START_TRANSLATION = torch.tensor([-0.1, 0.1, 0.3])

LONG_V, LONG_I = ep.shapes.box(center=(0.0, 0.0, 0.0), half=(0.7, 0.2, 0.2))
SHORT_V, SHORT_I = ep.shapes.box(center=(0.5, 0.45, 0.0), half=(0.2, 0.25, 0.2))


def make_scene(axis_angle: torch.Tensor, translation: torch.Tensor, size: int) -> ep.Scene:
    r = rotation(axis_angle)
    long_bar = ep.Mesh(LONG_V @ r.T + translation, LONG_I,
                       material=ep.Material(diffuse=torch.tensor([0.2, 0.4, 0.8])))
    short_bar = ep.Mesh(SHORT_V @ r.T + translation, SHORT_I,
                        material=ep.Material(diffuse=torch.tensor([0.9, 0.6, 0.1])))
    # A lamp up and to the right of the camera, facing the object.
    lv = torch.tensor([[1.0, 2.0, 3.0], [2.0, 2.0, 3.0], [2.0, 3.0, 2.5], [1.0, 3.0, 2.5]])
    lamp = ep.Mesh(lv, torch.tensor([[0, 2, 1], [0, 3, 2]]), emission=torch.full((3,), 12.0))
    camera = ep.Camera(position=torch.tensor([0.0, 0.0, 4.0]), look_at=torch.zeros(3), fov=40.0,
                       resolution=(size, size))
    return ep.Scene(camera, [long_bar, short_bar, lamp], ep.EnvironmentMap(torch.full((1, 1, 3), 0.3)))


def pose_errors(axis_angle, translation):
    """Rotation error (degrees, the angle of R_true^T R) and translation error."""
    relative = rotation(TRUE_ROTATION).T @ rotation(axis_angle.detach())
    cos = ((torch.trace(relative) - 1) / 2).clamp(-1.0, 1.0)
    return float(torch.rad2deg(torch.arccos(cos))), float((translation.detach() - TRUE_TRANSLATION).norm())


def main(argv=None):
    args = parser(__doc__.splitlines()[0], iterations=150, size=96, spp=4).parse_args(argv)
    out = output_dir(args, "pose_estimation")
    target = ep.render(make_scene(TRUE_ROTATION, TRUE_TRANSLATION, args.size), spp=128,
                       seed=args.seed + 10_000)
    axis_angle = START_ROTATION.clone().requires_grad_()
    translation = START_TRANSLATION.clone().requires_grad_()
    optimizer = torch.optim.Adam([axis_angle, translation], lr=0.02)
    losses, rot_err, trans_err = [], [], []
    for step in range(args.iterations):
        optimizer.zero_grad()
        image = ep.render(make_scene(axis_angle, translation, args.size), spp=args.spp,
                          seed=args.seed + step)
        loss = (image - target).square().mean()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        r, t = pose_errors(axis_angle, translation)
        rot_err.append(r)
        trans_err.append(t)
        report(args, step, losses[-1], extra=f"  rotation error {r:.2f} deg, translation error {t:.3f}")

    start = ep.render(make_scene(START_ROTATION, START_TRANSLATION, args.size), spp=128)
    result = ep.render(make_scene(axis_angle.detach(), translation.detach(), args.size), spp=128)
    save_images(out, {"target": target, "start": start, "result": result,
                      "comparison": row([target, start, result])})
    plot(f"{out}/loss.png", {"image loss": losses}, "mean squared error", "pose estimation: loss")
    plot(f"{out}/error.png", {"rotation error (degrees)": rot_err,
                              "translation error (x 100)": [100 * t for t in trans_err]},
         "error", "pose estimation: parameter error")
    print(f"pose estimation: loss {losses[0]:.4g} -> {losses[-1]:.4g}, rotation error "
          f"{rot_err[0]:.1f} -> {rot_err[-1]:.2f} deg, translation error {trans_err[0]:.3f} -> "
          f"{trans_err[-1]:.4f}; pictures in {out}")
    return {"loss": losses, "rotation_error": rot_err, "translation_error": trans_err}


if __name__ == "__main__":
    run(main)
