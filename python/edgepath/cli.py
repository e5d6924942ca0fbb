"""Command line: ``edgepath render MESH.obj -o out.png``, ``edgepath demo`` (inverse rendering)."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import List, Optional

import torch

from .io import imwrite, load_obj
from .render import SAMPLING, render
from .scene import Camera, EnvironmentMap, Scene


def _add_render_options(parser: argparse.ArgumentParser, spp: int, max_bounces: int) -> None:
    parser.add_argument("--spp", type=int, default=spp, help=f"samples per pixel (default {spp})")
    parser.add_argument("--max-bounces", type=int, default=max_bounces,
                        help="scattering events per path: 0 = emitters only, 1 = direct light, "
                             f"2 = one indirect bounce, ... (default {max_bounces})")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    parser.add_argument("--sampling", choices=list(SAMPLING), default="mis",
                        help="direct-light sampling strategy (default mis)")
    parser.add_argument("--resolution", type=int, nargs=2, metavar=("HEIGHT", "WIDTH"),
                        default=(256, 256), help="image size (default 256 256)")


def _framing_camera(meshes, resolution, fov: float) -> Camera:
    """A camera on the +z side of the meshes' bounding box, looking at its centre."""
    points = torch.cat([m.vertices.detach().reshape(-1, 3).to(torch.float32) for m in meshes])
    lo, hi = points.min(dim=0).values, points.max(dim=0).values
    centre, radius = (lo + hi) / 2, max(float((hi - lo).norm()) / 2, 1e-3)
    distance = 1.1 * radius / math.sin(math.radians(fov) / 2)
    position = centre + torch.tensor([0.0, 0.0, distance])
    return Camera(position=position, look_at=centre, up=torch.tensor([0.0, 1.0, 0.0]),
                  fov=fov, resolution=tuple(resolution))


def _render_and_write(scene: Scene, args, outputs: List[str]) -> None:
    start = time.perf_counter()
    image = render(scene, spp=args.spp, max_bounces=args.max_bounces, seed=args.seed,
                   num_threads=args.threads, sampling=args.sampling)
    seconds = time.perf_counter() - start
    for path in outputs:
        directory = os.path.dirname(path)
        if directory:
            os.makedirs(directory, exist_ok=True)
        imwrite(image, path)
    height, width = image.shape[:2]
    print(f"rendered {width}x{height} at {args.spp} spp in {seconds:.2f} s: {', '.join(outputs)}")


def _cmd_render(args) -> None:
    meshes = load_obj(args.scene)
    if not meshes:
        raise ValueError(f"{args.scene}: no faces")
    camera = _framing_camera(meshes, args.resolution, args.fov)
    envmap = None
    if args.env >= 0 and (args.env > 0 or all(m.emission is None for m in meshes)):
        # A constant white environment (1x1 map) lights scenes without emitters.
        envmap = EnvironmentMap(values=torch.full((1, 1, 3), 1.0), scale=args.env or 1.0)
    _render_and_write(Scene(camera=camera, meshes=meshes, envmap=envmap), args, args.output or ["out.png"])


def _cmd_demo(args) -> None:
    from .demo import run_demo
    run_demo(iterations=args.iterations, size=args.size, spp=args.spp, output_dir=args.output_dir,
             seed=args.seed, num_threads=args.threads, progress=not args.quiet,
             secondary_edges=not args.no_secondary_edges)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="edgepath",
                                     description="edgepath: a differentiable path tracer.")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    r = commands.add_parser("render", help="render an OBJ file",
                            description="Render an OBJ file (with its MTL materials) seen from the "
                                        "+z side of its bounding box. Without emitters in the file "
                                        "it is lit by a constant white environment.")
    r.add_argument("scene", help="the .obj file")
    r.add_argument("-o", "--output", action="append", metavar="FILE",
                   help="output image, .png or .exr; repeat for several (default out.png)")
    r.add_argument("--fov", type=float, default=45.0, help="horizontal field of view, degrees")
    r.add_argument("--env", type=float, default=0.0,
                   help="constant environment radiance: 0 = only if the file has no emitters "
                        "(radiance 1), < 0 = never (default 0)")
    _add_render_options(r, spp=16, max_bounces=2)
    r.set_defaults(run=_cmd_render)

    d = commands.add_parser("demo", help="inverse rendering: recover pose, colour and light from one image",
                            description="The built-in inverse-rendering demo: a box floats above a "
                                        "floor under a small area light. From one target image, Adam "
                                        "recovers the box's position, rotation and colour and the "
                                        "lamp's position and intensity, the shadow doing part of the "
                                        "work. Writes DIR/target.png, start.png, result.png, "
                                        "optimisation.gif and convergence.png.")
    d.add_argument("-o", "--output-dir", default="demo_out", metavar="DIR",
                   help="output directory (default demo_out)")
    d.add_argument("--iterations", type=int, default=150, help="optimisation steps (default 150)")
    d.add_argument("--size", type=int, default=128, help="image height and width (default 128)")
    d.add_argument("--spp", type=int, default=4, help="samples per pixel per step (default 4)")
    d.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    d.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    d.add_argument("--no-secondary-edges", action="store_true",
                   help="leave the shadow and lamp outlines out of the gradient (for comparison: "
                        "the lamp then gets no gradient)")
    d.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    d.set_defaults(run=_cmd_demo)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.run(args)
    except (ValueError, OSError) as error:
        print(f"edgepath {args.command}: error: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
