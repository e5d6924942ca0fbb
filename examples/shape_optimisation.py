"""Shape optimisation: deform a sphere into a target shape seen from three cameras.

Every vertex of a (welded) sphere mesh moves freely; the loss is the image difference in three
views plus a Laplacian smoothness term (each vertex's offset from the mean of its neighbours),
which keeps the surface from crumpling where the images say little. The silhouettes pull the
outline (primary edges); the flat shading under a lamp pulls the face orientations.

    python examples/shape_optimisation.py [--iterations 200] [--size 64] [--output-dir DIR]
"""

import math

import torch

import edgepath as ep
from edgepath import shapes
from _common import lamp, orbit_cameras, output_dir, parser, plot, report, row, run, save_images, weld

SPHERE_V, SPHERE_I = weld(*shapes.sphere(radius=1.0, rings=12, segments=24)[:2])


def target_vertices(sphere: torch.Tensor = SPHERE_V) -> torch.Tensor:
    """The unit sphere's points ``sphere`` moved onto the target: an ellipsoid with a bump."""
    v = sphere * torch.tensor([1.3, 0.75, 0.9])
    bump = 0.45 * torch.exp(-(sphere - torch.tensor([0.3, 1.0, 0.0])).square().sum(1) / 0.25)
    return v + bump.unsqueeze(1) * sphere


# The target surface, densely sampled: to measure how far the estimate's vertices are from it.
DENSE_TARGET = target_vertices(shapes.sphere(rings=96, segments=192)[0])


def neighbours_matrix(indices: torch.Tensor, n: int) -> torch.Tensor:
    """The (n, n) matrix that averages each vertex's neighbours (uniform weights)."""
    i = indices.long()
    edges = torch.cat([i[:, [0, 1]], i[:, [1, 2]], i[:, [2, 0]]])
    edges = torch.unique(torch.cat([edges, edges.flip(1)]), dim=0)
    degree = torch.bincount(edges[:, 0], minlength=n).float()
    matrix = torch.zeros(n, n)
    matrix[edges[:, 0], edges[:, 1]] = 1.0 / degree[edges[:, 0]]
    return matrix


# A lamp above and one beside each camera, so that every view sees lit surfaces (no
# environment light: its sampling would add much noise for little information).
LAMPS = [lamp((0.0, 4.0, 0.0), 1.5, 5.0)] + [
    lamp((4.0 * math.sin(math.radians(a + 25)), 2.5, 4.0 * math.cos(math.radians(a + 25))), 1.5, 4.0)
    for a in (0.0, 120.0, 240.0)]


def make_scene(vertices: torch.Tensor, camera: ep.Camera) -> ep.Scene:
    mesh = ep.Mesh(vertices, SPHERE_I, material=ep.Material(diffuse=torch.tensor([0.7, 0.7, 0.7])))
    return ep.Scene(camera, [mesh] + LAMPS)


def surface_distance(vertices: torch.Tensor) -> float:
    """The mean distance from the vertices to the target surface (its nearest dense sample)."""
    return float(torch.cdist(vertices.detach(), DENSE_TARGET).min(1).values.mean())


def main(argv=None):
    p = parser(__doc__.splitlines()[0], iterations=200, size=64, spp=16)
    p.add_argument("--smoothness", type=float, default=0.2, help="weight of the Laplacian term")
    args = p.parse_args(argv)
    out = output_dir(args, "shape_optimisation")
    cameras = orbit_cameras(args.size)
    views = len(cameras)
    # A seed per view (seed=[...]): the lamps turn with the cameras, so with one seed for all,
    # the views of the (symmetric) starting sphere would have the same noise.
    targets = ep.render(make_scene(target_vertices(), cameras[0]), spp=64, cameras=cameras,
                        seed=[args.seed + 10_000 + k for k in range(views)])
    # One scene for every step and view: its core scene is kept and refitted as the vertices
    # move, and the three views are rendered (and differentiated) in one call.
    scene = make_scene(SPHERE_V, cameras[0])
    average = neighbours_matrix(SPHERE_I, SPHERE_V.shape[0])

    offsets = torch.zeros_like(SPHERE_V, requires_grad=True)
    optimizer = torch.optim.Adam([offsets], lr=0.01)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda i: 0.2 ** (i / args.iterations))
    losses, image_losses, errors = [], [], []
    for step in range(args.iterations):
        optimizer.zero_grad()
        vertices = SPHERE_V + offsets
        scene.meshes[0].vertices = vertices
        # Many cheap samples for the image (its noise would enter the gradient through the
        # loss), fewer for the gradient pass.
        images = ep.render(scene, spp=args.spp, backward_spp=max(1, args.spp // 4), cameras=cameras,
                           seed=[args.seed + views * step + k for k in range(views)])
        image_loss = (images - targets).square().mean()  # the views' mean of each view's mean
        # The Laplacian of the offsets: zero for any smooth deformation of the sphere (that of
        # the vertices themselves would also pull the sphere to shrink).
        laplacian = offsets - average @ offsets
        loss = image_loss + args.smoothness * laplacian.square().sum(1).mean()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())
        image_losses.append(image_loss.item())
        errors.append(surface_distance(vertices))
        report(args, step, losses[-1], extra=f"  distance to the target surface {errors[-1]:.4f}")

    final = (SPHERE_V + offsets).detach()
    pictures = {}
    for name, v in (("start", SPHERE_V), ("result", final)):
        scene.meshes[0].vertices = v
        pictures[name] = ep.render(scene, spp=64, seed=args.seed + 20_000, cameras=cameras)
    save_images(out, {"target": row(targets), "start": row(pictures["start"]),
                      "result": row(pictures["result"])})
    plot(f"{out}/loss.png", {"total loss": losses, "image loss": image_losses,
                             "mean distance to the target surface": errors}, "value",
         "shape optimisation")
    print(f"shape optimisation: loss {losses[0]:.4g} -> {losses[-1]:.4g}, distance to the target "
          f"{errors[0]:.4f} -> {errors[-1]:.4f}; pictures in {out}")
    return {"loss": losses, "image_loss": image_losses, "surface_distance": errors, "vertices": final,
            "build_counts": scene.build_counts()}


if __name__ == "__main__":
    run(main)
