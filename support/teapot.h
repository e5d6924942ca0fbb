// Martin Newell's teapot (1975) as a triangle mesh, for tests, benchmarks and examples.
#pragma once
#include <cstdint>
#include "support/shapes.h"

namespace edgepath {

// Tessellates the 32 bicubic Bezier patches of the teapot (rim, body, handle, spout, lid knob,
// lid, bottom) into `subdivisions` x `subdivisions` quads per patch, two triangles each. The
// lid and the bottom close in a pole; the zero-area triangles there are left out, so the mesh
// has teapot_triangle_count(subdivisions) = 64 n^2 - 8 n triangles (52 for n = 1, where the
// corners of the two spout-tip patches are collinear as well). Patches do not share
// vertices, but the vertices on a seam are bit-identical in both patches (no cracks).
//
// Normals: analytic, from the patch derivatives, outward, unit length; where a derivative
// vanishes (the poles) they come from a parameter nudged into the patch. uvs: the parameters of
// each patch, (along its rows, along its columns), in [0, 1]^2.
//
// Units of the original data: the teapot stands on its base at height 0, is 3.15 high (knob
// top), 4 wide across the body (|horizontal radius| <= 2), with the handle reaching -3 and the
// spout about +3.43 along x. `y_up` (default) stands it on the plane y = 0 with y up, the
// spout towards +x; otherwise z is up, as in the original data. Scale and move it with
// MeshData::transform.
MeshData make_teapot(int subdivisions, bool y_up = true);

// Number of triangles make_teapot(subdivisions) produces.
int64_t teapot_triangle_count(int subdivisions);

}  // namespace edgepath
