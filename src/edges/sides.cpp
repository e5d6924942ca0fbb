#include "edges/sides.h"

#include <cmath>
#include <limits>

namespace edgepath {

namespace {

// Hits on anything but the edge's own faces closer than this fraction of the distance (plus the
// coordinates' magnitude) before x are taken for x itself: rounding, not occlusion.
constexpr float kEdgeRounding = 1e-6f;
// Near misses (see meets_triangle) and hidden emitters skipped along the ray before the sample
// is dropped.
constexpr int kMaxSkips = 8;

bool same_position(const Vec3f& a, const Vec3f& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

// The vertex of face f that is at neither end of the edge (p0, p1); false if none (degenerate).
bool third_vertex(const Mesh& m, int64_t f, const Vec3f& p0, const Vec3f& p1, Vec3f& c) {
    // The triangle's vertices in its order, from the scene's copy (one record, not the index
    // array and three vertices).
    const TriangleData& td = m.triangle_data[f];
    for (const Vec3f* v : {&td.v0, &td.v1, &td.v2})
        if (!same_position(*v, p0) && !same_position(*v, p1)) {
            c = *v;
            return true;
        }
    return false;
}

// The hit on face f at the edge point x = p0 + s (p1 - p0), at distance t along the ray.
Hit hit_at_edge(const Mesh& m, int mesh, int64_t f, const Vec3f& p0, const Vec3f& p1, float s, float t) {
    const int32_t* tri = m.indices + 3 * f;
    float b[3];
    for (int k = 0; k < 3; ++k) {
        const Vec3f v = m.vertex(tri[k]);
        b[k] = same_position(v, p0) ? 1.f - s : (same_position(v, p1) ? s : 0.f);
    }
    Hit h;
    h.mesh = mesh;
    h.prim = f;
    h.b1 = b[1];
    h.b2 = b[2];
    h.t = t;
    return h;
}

// Where the line o + s d meets the plane of triangle f of mesh m, in double precision: the
// barycentrics (b1, b2) of the point and its parameter s. False when the line runs parallel to
// the plane.
bool line_on_plane(const Mesh& m, int64_t f, const Vec3d& o, const Vec3d& d, double& b1, double& b2, double& s) {
    const int32_t* t = m.indices + 3 * f;
    const Vec3d p0(m.vertex(t[0])), e1 = Vec3d(m.vertex(t[1])) - p0, e2 = Vec3d(m.vertex(t[2])) - p0;
    const Vec3d q = cross(d, e2);
    const double det = dot(e1, q);
    if (det == 0.0) return false;
    const Vec3d w = o - p0, r = cross(w, e1);
    b1 = dot(w, q) / det;
    b2 = dot(d, r) / det;
    s = dot(e2, r) / det;
    return true;
}

// Whether the line through o and x meets triangle f of mesh m, in double precision. Embree's
// float test reports rays that pass outside a triangle by up to about 1e-4 of its size (in
// barycentric terms) as hits, and a float ray's direction is itself off by some 1e-7: a ray
// through the point of a fold's edge passes that close to the slivers that border it on a
// scanned mesh's outline (faces within 1e-5 rad of edge-on), and would take one of them for
// the far side or for an occluder.
bool meets_triangle(const Mesh& m, int64_t f, const Vec3d& o, const Vec3d& x) {
    double b1, b2, s;
    return line_on_plane(m, f, o, x - o, b1, b2, s) && b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0;
}

// The hit on the plane of triangle f of mesh m of the ray (o, d), inside the triangle or not, in
// double precision; false when the ray runs parallel to the plane or meets it behind o.
bool hit_on_plane(const Mesh& m, int mesh, int64_t f, const Ray& ray, Hit& h) {
    double b1, b2, dist;
    if (!line_on_plane(m, f, Vec3d(ray.origin), Vec3d(ray.dir), b1, b2, dist)) return false;
    if (!(dist > double(ray.tmin)) || !std::isfinite(dist)) return false;
    h.mesh = mesh;
    h.prim = f;
    h.b1 = float(b1);
    h.b2 = float(b2);
    h.t = float(dist);
    return true;
}

}  // namespace

namespace {

// side_of for the one edge (e0, e1) and any point c: the plane through the eye and the edge found
// once (a parallel eye's plane depends on c, so it is found per point).
struct EyePlane {
    const EdgeEye& eye;
    Vec3f e0, e1;
    Vec3d n;
    EyePlane(const EdgeEye& eye_, const Vec3f& a, const Vec3f& b) : eye(eye_), e0(a), e1(b) {
        if (!eye.parallel) n = cross(Vec3d(e0 - eye.origin), Vec3d(e1 - eye.origin));
    }
    double side(const Vec3f& c) const {
        if (eye.parallel) return dot(cross(Vec3d(e0 - c), Vec3d(e1 - c)), Vec3d(eye.dir));
        return dot(n, Vec3d(c - eye.origin));
    }
};

}  // namespace

double side_of(const EdgeEye& eye, const Vec3f& e0, const Vec3f& e1, const Vec3f& c) {
    return EyePlane(eye, e0, e1).side(c);
}

bool is_fold(const EdgeEye& eye, const Mesh& m, const Edge& e) {
    if (e.kind == EdgeKind::Boundary) return true;
    const Vec3f p0 = m.vertex(e.v0), p1 = m.vertex(e.v1);
    Vec3f c0, c1;
    if (!third_vertex(m, e.f0, p0, p1, c0) || !third_vertex(m, e.f1, p0, p1, c1)) return true;
    const EyePlane plane(eye, p0, p1);
    return (plane.side(c0) > 0.0) == (plane.side(c1) > 0.0);
}

bool seen_from_behind(const EdgeEye& eye, const Mesh& m, const Edge& e) {
    if (e.f0 < 0 || e.f1 < 0) return false;
    const Vec3f p0 = m.vertex(e.v0);  // on both faces' planes
    auto behind = [&](int64_t f) {
        const Vec3f& ng = m.triangle_data[f].ng;
        return eye.parallel ? dot(ng, eye.dir) > 0.f : dot(ng, eye.origin - p0) < 0.f;
    };
    return behind(e.f0) && behind(e.f1);
}

bool edge_sides(const Scene& scene, const EdgeEye& eye, const Edge& e, const Ray& ray, float s, float t_x,
                EdgeSide& upper, EdgeSide& lower) {
    const Mesh& m = scene.meshes[size_t(e.mesh)];
    const Vec3f p0 = m.vertex(e.v0), p1 = m.vertex(e.v1);
    const Vec3f x = p0 + (p1 - p0) * s;
    if (!(t_x > ray.tmin)) return false;  // behind the eye (an orthographic camera's film plane)
    if (eye.skip_emitters && m.is_emitter()) return false;  // the eye sees through the edge

    // The first hit on anything but the edge's own faces that the ray truly meets: before x, x
    // is hidden; past x, it is what the outer side of a fold or a boundary sees.
    const Vec3d o_exact(ray.origin), x_exact = Vec3d(p0) + (Vec3d(p1) - Vec3d(p0)) * double(s);
    FirstHit beyond;
    Ray r = ray;
    for (int k = 0;; ++k) {
        beyond.found = scene.intersect_excluding(r, e.mesh, e.f0, e.f1, beyond.hit);
        if (!beyond.found) break;
        const Mesh& hit_mesh = scene.meshes[size_t(beyond.hit.mesh)];
        if (!(eye.skip_emitters && hit_mesh.is_emitter()) && meets_triangle(hit_mesh, beyond.hit.prim, o_exact, x_exact))
            break;
        if (k == kMaxSkips) return false;
        r.tmin = std::nextafter(beyond.hit.t, std::numeric_limits<float>::infinity());
    }
    const float rounding = kEdgeRounding * (t_x + max_abs_component(x));
    if (beyond.found && beyond.hit.t < t_x - rounding) return false;

    // The own faces on each side; where both lie on one side, the nearer one just off the edge:
    // moving the ray by u towards that side moves its hit on face i's plane (normal n) nearer by
    // an amount proportional to (n . u) / (n . d).
    const Vec3d d(ray.dir);
    const Vec3d up_dir = eye.parallel ? cross(d, Vec3d(p1 - p0)) : cross(Vec3d(p0 - eye.origin), Vec3d(p1 - eye.origin));
    int64_t near_face[2] = {-1, -1};  // upper, lower
    Vec3f near_corner[2];             // their third vertices
    double nearness[2] = {0.0, 0.0};
    bool any = false;
    for (int64_t f : {e.f0, e.f1}) {
        Vec3f c;
        if (f < 0 || !third_vertex(m, f, p0, p1, c)) continue;
        const double side = side_of(eye, p0, p1, c);
        if (side == 0.0) continue;
        const int k = side > 0.0 ? 0 : 1;
        const Vec3d n(m.face_normal(f));
        const double nd = dot(n, d);
        if (nd == 0.0) continue;
        const double near = (k == 0 ? 1.0 : -1.0) * dot(n, up_dir) / nd;
        if (near_face[k] < 0 || near > nearness[k]) {
            near_face[k] = f;
            near_corner[k] = c;
            nearness[k] = near;
        }
        any = true;
    }
    if (!any) return false;
    // Touching: what lies beyond passes through x, up to rounding.
    const bool touching = beyond.found && beyond.hit.t <= t_x + 4.f * rounding;
    const double up_len = length(up_dir);
    EdgeSide* out[2] = {&upper, &lower};
    for (int k = 0; k < 2; ++k) {
        EdgeSide& side = *out[k];
        side.ray = ray;
        side.off_edge = false;
        if (near_face[k] >= 0) {
            side.found = true;
            side.hit = hit_at_edge(m, e.mesh, near_face[k], p0, p1, s, t_x);
            // On the face just off the edge (towards its third vertex c), not on the edge: a
            // path leaving the edge itself can pass the edge's other face, by rounding, where
            // the limit from inside the face meets it (a mirror box's top face reflecting into
            // the box past its back face: which one happened changed as the scene was turned,
            // and the box's back corners' gradients with it, 6 and 13 times). Four times the
            // rounding bound off, past the offset a path's origin gets (its point's rounding
            // error); not the touching surfaces' step (1e-5 of the distance), which moved the
            // bunny's outline derivative by 2.5% and a sun's elevation derivative by 2% (and
            // further from their finite differences). Not where the face is narrower than twice
            // that.
            const Vec3d c(near_corner[k]), along = Vec3d(p1) - Vec3d(p0);
            const double h = length(cross(c - x_exact, along)) / length(along);
            const double w = 4.0 * double(rounding) / h;
            if (!(w > 0.0 && w < 0.5)) continue;
            const Vec3d moved = x_exact * (1.0 - w) + c * w;
            side.off_edge = true;
            const Vec3d dx = moved - x_exact;
            if (eye.parallel) {
                side.ray.origin = Vec3f(Vec3d(ray.origin) + dx - d * dot(d, dx));
                side.hit.t = float(double(t_x) + dot(d, dx));
            } else {
                side.ray.dir = Vec3f(normalize(moved - o_exact));
                side.hit.t = float(length(moved - o_exact));
            }
            const int32_t* tri = m.indices + 3 * near_face[k];
            float b[3] = {1.f - side.hit.b1 - side.hit.b2, side.hit.b1, side.hit.b2};
            for (int j = 0; j < 3; ++j) {
                const bool corner = same_position(m.vertex(tri[j]), near_corner[k]);
                b[j] = corner ? float(w) : float(double(b[j]) * (1.0 - w));
            }
            side.hit.b1 = b[1];
            side.hit.b2 = b[2];
            continue;
        }
        static_cast<FirstHit&>(side) = beyond;
        if (!touching) continue;
        // The touching surface a step off the edge, to this side: the ray aimed there, on the
        // plane of the face it touches with (not traced: a step may leap over a thin face).
        if (!(up_len > 0.0)) return false;
        side.off_edge = true;
        const double offset = double(eye.step) * (eye.parallel ? double(t_x) + max_abs_component(x) : double(t_x));
        const Vec3d shift = up_dir * ((k == 0 ? offset : -offset) / up_len);
        if (eye.parallel) {
            side.ray.origin = Vec3f(Vec3d(ray.origin) + shift);
        } else {
            side.ray.dir = Vec3f(normalize(x_exact + shift - o_exact));
        }
        if (!hit_on_plane(scene.meshes[size_t(beyond.hit.mesh)], beyond.hit.mesh, beyond.hit.prim, side.ray,
                          side.hit))
            return false;
    }
    return true;
}

}  // namespace edgepath
