"""Renders the Mitsuba 3 references of this folder's scenes (run once, with the mitsuba pip
package; the tests only read the EXR files it writes):

    python make_references.py [spp [NAME ...]]

Each ``NAME.xml`` (all of them, or the NAMEs given) gives ``NAME.exr``: Mitsuba's
``scalar_rgb`` variant, seed 0, ``spp`` samples per pixel (default 8192, what the committed files used), with the ``$name``
parameters listed below, stored as half floats to keep the files small. edgepath's own
properties that Mitsuba does not know (a point or spot emitter's ``radius``) are removed from
the XML before Mitsuba reads it."""

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = Path(__file__).resolve().parent
# name: $name parameters of the file (the tutorial's Cornell box at 32 x 32 pixels).
SCENES = {"cornell_glass_mirror": {}, "direct_hidden_emitters": {}, "tutorial_cbox": {"res": 32},
          "normalmap_rectangle": {}, "point_spot": {}, "rough_glass": {}, "rough_plastic": {},
          "smooth_plastic": {}}


def load(path: Path, **params):
    """The scene of the file, without edgepath's radius of point and spot emitters."""
    root = ET.parse(path).getroot()
    removed = False
    for emitter in root.iter("emitter"):
        if emitter.get("type") in ("point", "spot"):
            for child in list(emitter):
                if child.tag == "float" and child.get("name") == "radius":
                    emitter.remove(child)
                    removed = True
    if not removed:
        return mi.load_file(str(path), **params)
    return mi.load_string(ET.tostring(root, encoding="unicode"), **params)


def main() -> None:
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 8192
    for name, params in SCENES.items():
        if len(sys.argv) > 2 and name not in sys.argv[2:]:
            continue
        scene = load(HERE / f"{name}.xml", spp=spp, **params)
        image = mi.render(scene, spp=spp, seed=0)
        bitmap = mi.Bitmap(image).convert(component_format=mi.Struct.Type.Float16)
        bitmap.write(str(HERE / f"{name}.exr"))
        print(f"{name}.exr: {spp} spp")


if __name__ == "__main__":
    main()
