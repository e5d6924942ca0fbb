"""Multi-view shape optimisation over processes: the views split over ranks (torch.distributed).

The shape of shape_optimisation.py (a sphere deformed into an ellipsoid with a bump), seen by
``--views`` cameras around it. Each of ``--ranks`` processes (gloo backend, on the CPU) renders
its share of the views in one call (``ep.render(scene, cameras=...)``: one scene build, one
backward pass), backpropagates its share of the loss, and an all-reduce sums the vertex
gradients over the ranks before every rank takes the same optimiser step: the ranks hold the
same parameters throughout, and each step is the one a single process rendering every view
would take (to float rounding: the sums run in another order).

    python examples/multiview_distributed.py [--ranks 2] [--views 8] [--iterations 100] [--size 48]

Started by torchrun (which sets RANK, WORLD_SIZE, MASTER_ADDR and MASTER_PORT), each process
joins that group instead of spawning ranks of its own.
"""

import os
import socket
import tempfile

import torch
import torch.distributed as dist

import edgepath as ep
from _common import orbit_cameras, output_dir, parser, plot, report, row, run, save_images
from shape_optimisation import LAMPS, SPHERE_I, SPHERE_V, neighbours_matrix, surface_distance, target_vertices

MATERIAL = ep.Material(diffuse=torch.tensor([0.7, 0.7, 0.7]))


def train(rank: int, world: int, args) -> dict:
    """The optimisation as rank ``rank`` of ``world`` runs it (world 1: no process group)."""
    # The cores are shared between the ranks of one machine.
    threads = max(1, (os.cpu_count() or 1) // world) if world > 1 else None
    cameras = orbit_cameras(args.size, count=args.views, height=1.2)
    mine = cameras[rank::world]
    # A seed per view, from its index among all the views: the views' noise is their own, and
    # whichever rank renders a view renders it alike, so any split gives the same gradient.
    indices = range(rank, args.views, world)
    with torch.no_grad():
        target = ep.Scene(None, [ep.Mesh(target_vertices(), SPHERE_I, material=MATERIAL)] + LAMPS)
        targets = ep.render(target, cameras=mine, spp=64, seed=[args.seed + 10_000 + k for k in indices],
                            num_threads=threads)
    average = neighbours_matrix(SPHERE_I, SPHERE_V.shape[0])

    # One scene for the whole run: its ray-tracing structures are kept between steps and only
    # refitted when the vertices move.
    mesh = ep.Mesh(SPHERE_V, SPHERE_I, material=MATERIAL)
    scene = ep.Scene(None, [mesh] + LAMPS)
    offsets = torch.zeros_like(SPHERE_V, requires_grad=True)
    optimizer = torch.optim.Adam([offsets], lr=0.01)
    losses, errors, first_gradient = [], [], None
    for step in range(args.iterations):
        optimizer.zero_grad()
        mesh.vertices = SPHERE_V + offsets
        images = ep.render(scene, cameras=mine, spp=args.spp, backward_spp=max(1, args.spp // 4),
                           seed=[args.seed + args.views * step + k for k in indices], num_threads=threads)
        # This rank's share of the mean over every view, and of the smoothness term (a
        # Laplacian of the offsets, as in shape_optimisation.py): the ranks' losses sum to the
        # loss of one process rendering every view.
        image_loss = (images - targets).square().mean(dim=(1, 2, 3)).sum() / args.views
        laplacian = offsets - average @ offsets
        loss = image_loss + args.smoothness * laplacian.square().sum(1).mean() / world
        loss.backward()
        total = loss.detach().reshape(1)
        if world > 1:
            dist.all_reduce(offsets.grad)  # the sum over the ranks
            dist.all_reduce(total)
        if first_gradient is None:
            first_gradient = offsets.grad.clone()
        optimizer.step()
        losses.append(float(total))
        errors.append(surface_distance(mesh.vertices))
        if rank == 0:
            report(args, step, losses[-1], extra=f"  distance to the target surface {errors[-1]:.4f}")

    final = (SPHERE_V + offsets).detach()
    if rank == 0:
        out = output_dir(args, "multiview_distributed")
        with torch.no_grad():
            result = ep.render(ep.Scene(None, [ep.Mesh(final, SPHERE_I, material=MATERIAL)] + LAMPS),
                               cameras=mine, spp=64, seed=args.seed + 20_000, num_threads=threads)
        save_images(out, {"target": row(list(targets)), "result": row(list(result))})
        plot(f"{out}/loss.png", {"loss": losses, "mean distance to the target surface": errors},
             "value", f"{args.views} views over {world} rank(s)")
        print(f"multi-view, {world} rank(s): loss {losses[0]:.4g} -> {losses[-1]:.4g}, distance to the "
              f"target {errors[0]:.4f} -> {errors[-1]:.4f}; pictures of rank 0's views in {out}")
    return {"loss": losses, "surface_distance": errors, "first_gradient": first_gradient,
            "vertices": final, "builds": scene.build_counts()}


def rank_main(rank: int, world: int, argv, init_method: str, result_path: str) -> None:
    """One spawned rank: joins the group, trains, and rank 0 leaves its figures in result_path."""
    args = arguments(argv)
    dist.init_process_group("gloo", init_method=init_method, rank=rank, world_size=world)
    try:
        figures = train(rank, world, args)
        if rank == 0:
            torch.save(figures, result_path)
    finally:
        dist.destroy_process_group()


def arguments(argv):
    p = parser(__doc__.splitlines()[0], iterations=100, size=48, spp=8)
    p.add_argument("--ranks", type=int, default=2, help="processes to spawn (default 2)")
    p.add_argument("--views", type=int, default=8, help="cameras around the shape (default 8)")
    p.add_argument("--smoothness", type=float, default=0.2, help="weight of the Laplacian term")
    args = p.parse_args(argv)
    if args.ranks < 1 or args.views < args.ranks:
        p.error("need at least one rank and at least one view per rank")
    return args


def main(argv=None):
    args = arguments(argv)
    if "RANK" in os.environ:  # started by torchrun: the group is given
        dist.init_process_group("gloo")
        try:
            figures = train(dist.get_rank(), dist.get_world_size(), args)
            return figures if dist.get_rank() == 0 else None  # rank 0 writes the figures
        finally:
            dist.destroy_process_group()
    if args.ranks == 1:
        return train(0, 1, args)
    with socket.socket() as s:  # a free local port for the group's rendezvous
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "figures.pt")
        torch.multiprocessing.spawn(rank_main, args=(args.ranks, argv, f"tcp://127.0.0.1:{port}", path),
                                    nprocs=args.ranks)
        return torch.load(path)


if __name__ == "__main__":
    run(main)
