"""Small helpers shared by the example scripts: command-line options, writing images and
plots, welding a mesh's duplicated vertices."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Dict, List, Optional, Sequence

import torch

import edgepath as ep


def parser(description: str, iterations: int, size: int, spp: int) -> argparse.ArgumentParser:
    """The options every example takes (with its own defaults)."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--iterations", type=int, default=iterations,
                   help=f"optimisation steps (default {iterations})")
    p.add_argument("--size", type=int, default=size, help=f"image height and width (default {size})")
    p.add_argument("--spp", type=int, default=spp, help=f"samples per pixel per step (default {spp})")
    p.add_argument("--output-dir", default=None, metavar="DIR",
                   help="where the pictures go (default: out/<example name>)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--quiet", action="store_true", help="print only the summary")
    p.add_argument("--metrics", metavar="FILE.json", default=None,
                   help="also write the run's figures (losses, errors per step) as JSON")
    return p


def run(main) -> None:
    """A script's entry point: ``main(command line)``; with ``--metrics FILE`` the figures it
    returns are written to FILE as JSON (tensors as nested lists), unless it returns None."""
    figures = main(sys.argv[1:])
    if figures is None:
        return
    option = argparse.ArgumentParser(add_help=False)
    option.add_argument("--metrics", default=None)
    path = option.parse_known_args()[0].metrics
    if path:
        with open(path, "w") as f:
            json.dump(figures, f, default=lambda t: t.tolist())


def output_dir(args, name: str) -> str:
    directory = args.output_dir or os.path.join("out", name)
    os.makedirs(directory, exist_ok=True)
    return directory


def save_images(directory: str, images: Dict[str, torch.Tensor]) -> None:
    """Writes each image as DIRECTORY/NAME.png (8-bit sRGB)."""
    for name, image in images.items():
        ep.imwrite(image, os.path.join(directory, f"{name}.png"))


def row(images: Sequence[torch.Tensor]) -> torch.Tensor:
    """Images of the same height side by side, with a one-pixel white gap."""
    gap = torch.ones(images[0].shape[0], 1, 3)
    parts: List[torch.Tensor] = []
    for image in images:
        parts += [image.detach(), gap]
    return torch.cat(parts[:-1], dim=1)


def plot(path: str, curves: Dict[str, Sequence[float]], ylabel: str, title: str,
         log: bool = True, xlabel: str = "iteration") -> None:
    """Curves against iteration as a PNG (matplotlib, Agg backend)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(figsize=(6, 4))
    for label, values in curves.items():
        axes.plot(range(len(values)), values, label=label)
    if log:
        axes.set_yscale("log")
    axes.set_xlabel(xlabel)
    axes.set_ylabel(ylabel)
    axes.set_title(title)
    axes.grid(True, which="both", alpha=0.3)
    if len(curves) > 1:
        axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def weld(vertices: torch.Tensor, indices: torch.Tensor, decimals: int = 5):
    """Merges vertices at the same position (the seam and poles of ``shapes.sphere``), so that
    moving a vertex cannot open a crack. Returns (vertices, indices)."""
    keys = torch.round(vertices.double() * 10**decimals)
    unique, inverse = torch.unique(keys, dim=0, return_inverse=True)
    welded = torch.zeros(unique.shape[0], 3, dtype=vertices.dtype).index_copy_(
        0, inverse, vertices)
    return welded, inverse[indices.long()].to(torch.int32)


def report(args, step: int, loss: float, every: Optional[int] = None, extra: str = "") -> None:
    every = every or max(1, args.iterations // 10)
    if not args.quiet and (step % every == 0 or step == args.iterations - 1):
        print(f"  step {step:4d}  loss {loss:.4g}{extra}")


def rotation(axis_angle: torch.Tensor) -> torch.Tensor:
    """The rotation matrix of an axis-angle vector (differentiable: the matrix exponential of
    its cross-product matrix)."""
    x, y, z = axis_angle.unbind()
    zero = torch.zeros_like(x)
    skew = torch.stack([torch.stack([zero, -z, y]), torch.stack([z, zero, -x]),
                        torch.stack([-y, x, zero])])
    return torch.linalg.matrix_exp(skew)


def lamp(centre: Sequence[float], size: float, radiance: float,
         facing: Sequence[float] = (0.0, 0.0, 0.0)) -> ep.Mesh:
    """A square area light of side ``size`` at ``centre``, facing the point ``facing``."""
    centre_t = torch.tensor(centre, dtype=torch.float32)
    normal = torch.nn.functional.normalize(torch.tensor(facing, dtype=torch.float32) - centre_t, dim=0)
    helper = torch.tensor([0.0, 0.0, 1.0]) if abs(float(normal[1])) > 0.9 else torch.tensor([0.0, 1.0, 0.0])
    a = torch.nn.functional.normalize(torch.linalg.cross(normal, helper), dim=0)
    b = torch.linalg.cross(normal, a)  # a x b = normal: the corners run counter-clockwise
    corners = torch.stack([centre_t + size / 2 * (sa * a + sb * b)
                           for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return ep.Mesh(corners, torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32),
                   emission=torch.full((3,), float(radiance)))


def orbit_cameras(size: int, count: int = 3, distance: float = 3.5, height: float = 1.5,
                  fov: float = 45.0, offset_degrees: float = 0.0) -> List[ep.Camera]:
    """``count`` cameras evenly spaced around the vertical axis, looking at the origin."""
    import math
    cameras = []
    for k in range(count):
        a = math.radians(offset_degrees + 360.0 * k / count)
        position = torch.tensor([distance * math.sin(a), height, distance * math.cos(a)])
        cameras.append(ep.Camera(position=position, look_at=torch.zeros(3), fov=fov,
                                 resolution=(size, size)))
    return cameras
