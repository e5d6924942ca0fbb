"""Renders the Mitsuba 3 reference images of this folder (run once, with a Python that has the
``mitsuba`` package; the tests never need it):

    python make_references.py [--spp N]

Each ``NAME.xml`` here gives ``NAME.exr``, rendered with the ``scalar_rgb`` variant, ``$spp``
samples per pixel and seed 0. The images are linear RGB, float32."""

import argparse
from pathlib import Path

import mitsuba as mi

HERE = Path(__file__).resolve().parent
SCENES = ["thinlens", "sun"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=8192)
    parser.add_argument("names", nargs="*", default=SCENES)
    args = parser.parse_args()
    mi.set_variant("scalar_rgb")
    for name in args.names:
        scene = mi.load_file(str(HERE / f"{name}.xml"), spp=args.spp)
        image = mi.render(scene, seed=0)
        mi.Bitmap(image).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32,
                                 srgb_gamma=False).write(str(HERE / f"{name}.exr"))
        print(f"{name}.exr: {args.spp} spp")


if __name__ == "__main__":
    main()
