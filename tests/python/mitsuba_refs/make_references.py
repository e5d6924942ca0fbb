"""Renders the Mitsuba 3 references of this folder's scenes (run once, with the mitsuba pip
package; the tests only read the EXR files it writes):

    python make_references.py [spp]

Each ``NAME.xml`` gives ``NAME.exr``: Mitsuba's ``scalar_rgb`` variant, seed 0, ``spp``
samples per pixel (default 8192, what the committed files used), with the ``$name``
parameters listed below, stored as half floats to keep the files small."""

import sys
from pathlib import Path

import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = Path(__file__).resolve().parent
# name: $name parameters of the file (the tutorial's Cornell box at 32 x 32 pixels).
SCENES = {"cornell_glass_mirror": {}, "direct_hidden_emitters": {}, "tutorial_cbox": {"res": 32},
          "normalmap_rectangle": {}}


def main() -> None:
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 8192
    for name, params in SCENES.items():
        scene = mi.load_file(str(HERE / f"{name}.xml"), spp=spp, **params)
        image = mi.render(scene, spp=spp, seed=0)
        bitmap = mi.Bitmap(image).convert(component_format=mi.Struct.Type.Float16)
        bitmap.write(str(HERE / f"{name}.exr"))
        print(f"{name}.exr: {spp} spp")


if __name__ == "__main__":
    main()
