"""Draws the picture at the top of README.md (docs/images/readme.png): the demo's scene, and
beside it the derivative of that image as the box moves to the right, silhouettes and shadow
included (red: brighter, blue: darker, white: unchanged).

    python docs/images/readme_picture.py [--size 160] [--spp 64] [-o docs/images/readme.png]
"""

import argparse
import os

import torch

import edgepath as ep
from edgepath import demo
from edgepath.cli import diverging_colours, robust_scale


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=160, help="height and width of each half")
    p.add_argument("--spp", type=int, default=64, help="samples per pixel")
    p.add_argument("-o", "--output", default=os.path.join(os.path.dirname(__file__), "readme.png"))
    args = p.parse_args(argv)

    scene = demo.demo_scene(demo.TRUTH, size=args.size)
    box = scene.meshes[0].vertices
    right = torch.tensor([1.0, 0.0, 0.0]).expand_as(box)
    image = ep.render(scene, spp=args.spp, max_bounces=2, seed=0)
    d = ep.derivative_image(scene, box, right, spp=args.spp, max_bounces=2, seed=0).mean(-1)
    gap = torch.ones(args.size, max(1, args.size // 40), 3)
    ep.imwrite(torch.cat([image.detach(), gap, diverging_colours(d, robust_scale(d, 99))], 1),
               args.output)


if __name__ == "__main__":
    main()
