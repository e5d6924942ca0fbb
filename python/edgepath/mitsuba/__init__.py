"""Mitsuba 3 scene files: ``load_mitsuba`` reads a documented subset of Mitsuba's XML format
into an ``edgepath.Scene`` (see docs/scene-files.md for the subset, element by element).

Anything outside the subset raises ``MitsubaError`` (a ValueError) naming the file, the line
and the element, e.g. ``scene.xml:12: <emitter type="point">: unsupported emitter type 'point'
(supported: area, constant, envmap)``. Analytic shapes (rectangle, cube, sphere, disk) are
tessellated; materials are mapped onto edgepath's diffuse + GGX model, approximately where
Mitsuba's model differs (documented per BSDF).

One module per kind of element: ``xml`` (the tree with line numbers, ``$name`` parameters,
property values, references, ``MitsubaError``, and ``Reader``, the state of one load),
``transforms``, ``sensors`` (with film, rfilter and sampler), ``shapes``, ``materials``
(BSDFs), ``textures`` (bitmaps and colours), ``emitters``, ``integrator``; ``loader`` reads a
file's top level (``load_mitsuba``) and holds ``MitsubaScene``, what it returns.
"""

from .loader import UNBOUNDED_MAX_BOUNCES, MitsubaScene, load_mitsuba
from .materials import CONDUCTOR_F0, NAMED_IOR
from .shapes import DISK_SEGMENTS, SPHERE_RINGS, SPHERE_SEGMENTS
from .xml import MitsubaError

__all__ = ["load_mitsuba", "MitsubaScene", "MitsubaError", "UNBOUNDED_MAX_BOUNCES",
           "CONDUCTOR_F0", "NAMED_IOR", "SPHERE_RINGS", "SPHERE_SEGMENTS", "DISK_SEGMENTS"]
