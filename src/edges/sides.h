// The two sides of an edge sample, found without stepping off the edge.
//
// An edge sample is a ray from an eye (the camera, edges/primary.cpp, or a shading point,
// edges/secondary.cpp) through a point x on an edge. Its boundary term needs the two one-sided
// limits of what the ray sees as it crosses the edge: on the side function's upper side (g > 0,
// scene/edges.h) and on its lower side. Tracing
// two rays a fixed small offset either side of x gets those limits wrong wherever the faces next
// to x are thinner (as seen from the eye) than the offset, as they are along the zig-zag outline
// of a scanned mesh: a side ray leaps over a sliver that hides the edge or borders it, and the
// jump is credited to an edge that does not have it (and counted again at the sliver's own edge).
// In the limit there is no step:
//   - x must be visible: nothing but the edge's own faces lies on the ray before x (up to
//     rounding); otherwise the sample is dropped;
//   - a side on which one of the edge's own faces lies sees that face at x (the nearer of the two
//     when both lie on it, as where the surface folds back: the nearer one is the one whose
//     depth grows least as the ray moves to that side);
//   - a side on which none lies (the outer side of a fold or of a boundary) sees what the ray
//     meets beyond x, leaving out the edge's own faces, however close behind x it is.
//   - where what lies beyond touches the edge (a wall standing on a floor: the floor passes
//     through the wall's lower edge), the limit is the surface seen there but not its value at
//     x itself: rays leaving x graze the edge's faces (a shadow ray from the floor at the foot
//     of the wall slips under it). That side is evaluated on the same surface a small angle
//     away from x, off the edge, on the ray aimed there (EdgeSide::ray).
// Which side a face lies on is the sign of the side function at its third vertex; none of this
// depends on the faces' winding.
#pragma once
#include "scene/edges.h"
#include "render/path.h"
#include "scene/scene.h"

namespace edgepath {

// The eye an edge is seen from: rays from `origin` (perspective), or, when `parallel` (an
// orthographic camera), rays of direction `dir` through any point.
struct EdgeEye {
    Vec3f origin;
    bool parallel = false;
    Vec3f dir;  // the parallel rays' direction
    // How far off the edge a side touching it is evaluated: this fraction of the distance (plus
    // the coordinates' magnitude, for a parallel eye).
    float step = 1e-5f;
    // Emitters are transparent to the eye's rays (a camera with hide_emitters, render/path.h).
    bool skip_emitters = false;
};

// What one side of an edge sample sees, and the ray its path continues from: the eye's ray
// through the edge point, or, where the surface on that side touches the edge, the ray aimed a
// small step off the edge on that surface.
struct EdgeSide : FirstHit {
    Ray ray;
    bool off_edge = false;  // ray is aimed off the edge
};

// The side of the plane through the eye and the edge (e0, e1) that point c lies on: the sign of
// the side function of the eye's ray through c (positive: the upper side).
double side_of(const EdgeEye& eye, const Vec3f& e0, const Vec3f& e1, const Vec3f& c);

// Whether the eye sees edge `e` of mesh `m` as a fold: a boundary, or two faces on the same side
// of the plane through the eye and the edge (the outline of the surface can run along it).
// Independent of the faces' winding.
bool is_fold(const EdgeEye& eye, const Mesh& m, const Edge& e);

// Whether the eye lies behind the planes of both faces of edge `e` (an edge with two faces), by
// their geometric normals: the side from which the renderer shades a one-sided surface black.
// Strictly: an eye in a face's plane is not behind it.
bool seen_from_behind(const EdgeEye& eye, const Mesh& m, const Edge& e);

// The hits on the upper and lower sides of edge `e` (side function of the eye's rays through
// the edge's vertices e.v0, e.v1, in that order) for the eye's ray `ray` (unit direction) through
// the point x = v0 + s (v1 - v0) of the edge, at distance t_x along it. False when x is hidden
// (or no face of the edge can be told to lie on either side: seen edge-on).
bool edge_sides(const Scene& scene, const EdgeEye& eye, const Edge& e, const Ray& ray, float s, float t_x,
                EdgeSide& upper, EdgeSide& lower);

}  // namespace edgepath
