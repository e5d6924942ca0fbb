"""Pose of a scanned mesh from four views: recover the translation and scale of the Stanford bunny.

The target is the bunny moved by 10% of its size and scaled by 5%, rendered from four cameras
around it; the optimisation starts from the bunny as loaded. Its gradient comes mostly from the
outlines, along which a scan's small triangles zig-zag: the case where silhouette gradients
used to be biased (docs/gradients.md, "Both sides in the limit").

    python examples/bunny_pose.py [--mesh bunny.ply] [--iterations 120] [--size 64] [--spp 4]

Without --mesh, the bunny beside the repository (shared/data/bunny.ply) is used.
"""

import math
import pathlib

import torch

import edgepath as ep
from _common import orbit_cameras, output_dir, parser, plot, report, row, run, save_images

DEFAULT_MESH = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "bunny.ply"
TRUE_SHIFT = torch.tensor([0.8, -0.36, 0.48])  # a unit vector: times 10% of the size
TRUE_SCALE = 1.05


def load_bunny(path):
    """The mesh centred on the origin, and its size (the diagonal of its bounding box)."""
    mesh = ep.load_ply(path)
    v = mesh.vertices
    lo, hi = v.min(0).values, v.max(0).values
    return (v - (lo + hi) / 2), mesh.indices, float((hi - lo).norm())


def make_scene(vertices, indices, camera):
    bunny = ep.Mesh(vertices, indices, material=ep.Material(diffuse=torch.tensor([0.7, 0.55, 0.4])))
    return ep.Scene(camera, [bunny], ep.EnvironmentMap(torch.full((1, 1, 3), 0.9)))


def posed(vertices, shift, log_scale):
    return vertices * torch.exp(log_scale) + shift


def main(argv=None):
    p = parser(__doc__.splitlines()[0], iterations=120, size=64, spp=4)
    p.add_argument("--mesh", default=None, help="a PLY or OBJ mesh (default: the Stanford bunny)")
    args = p.parse_args(argv)
    out = output_dir(args, "bunny_pose")
    path = pathlib.Path(args.mesh) if args.mesh else DEFAULT_MESH
    if not path.exists():
        raise SystemExit(f"bunny_pose: mesh not found: {path} (pass one with --mesh)")
    vertices, indices, size = load_bunny(path)
    cameras = orbit_cameras(args.size, count=4, distance=2.2 * size, height=0.8 * size, fov=40.0,
                            offset_degrees=20.0)
    true_shift = 0.1 * size * TRUE_SHIFT
    true_log_scale = torch.tensor(math.log(TRUE_SCALE))
    # One scene for all views and steps: its core scene is kept and refitted as the vertices
    # move, and the four views are rendered (and differentiated) in one call.
    scene = make_scene(posed(vertices, true_shift, true_log_scale), indices, cameras[0])
    targets = ep.render(scene, spp=64, seed=args.seed + 10_000, cameras=cameras)

    shift = torch.zeros(3, requires_grad=True)
    log_scale = torch.zeros((), requires_grad=True)
    # Steps of 1% of the size and 1% of the scale, annealed to a twentieth of that.
    optimizer = torch.optim.Adam([{"params": [shift], "lr": 0.01 * size}, {"params": [log_scale], "lr": 0.01}])
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda k: 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * k / args.iterations)))
    losses, shift_err, scale_err = [], [], []
    for step in range(args.iterations):
        optimizer.zero_grad()
        scene.meshes[0].vertices = posed(vertices, shift, log_scale)
        images = ep.render(scene, spp=args.spp, seed=args.seed + step, cameras=cameras)
        loss = (images - targets).square().mean()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())
        shift_err.append(float((shift.detach() - true_shift).norm()) / size)
        scale_err.append(abs(math.exp(log_scale.item()) / TRUE_SCALE - 1))
        report(args, step, losses[-1],
               extra=f"  shift error {100 * shift_err[-1]:.2f}% of the size, scale error {100 * scale_err[-1]:.2f}%")

    with torch.no_grad():
        scene.meshes[0].vertices = vertices
        start = ep.render(scene, spp=32, cameras=cameras)
        scene.meshes[0].vertices = posed(vertices, shift, log_scale)
        result = ep.render(scene, spp=32, cameras=cameras)
    save_images(out, {"comparison": torch.cat([row(list(targets)), row(list(start)), row(list(result))], dim=0)})
    plot(f"{out}/error.png", {"shift error (fraction of the size)": shift_err, "scale error": scale_err},
         "error", "bunny pose: parameter error")
    print(f"bunny pose: loss {losses[0]:.4g} -> {losses[-1]:.4g}, shift error {100 * shift_err[0]:.1f}% -> "
          f"{100 * shift_err[-1]:.2f}% of the size, scale error {100 * scale_err[0]:.1f}% -> "
          f"{100 * scale_err[-1]:.2f}%; pictures in {out}")
    return {"loss": losses, "shift_error": shift_err, "scale_error": scale_err}


if __name__ == "__main__":
    run(main)
