#include "edges/primary.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <tbb/enumerable_thread_specific.h>
#include "edges/sides.h"
#include "sampling/warp.h"
#include "render/batch.h"
#include "render/path.h"
#include "render/tiles.h"
#include "math/frame.h"
#include "scene/bsdf.h"

namespace edgepath {

static_assert(2 * kPrimaryEdgeBatch <= kBatchSize, "a batch's side paths fit a PathBatch");

namespace {

// An edge's part on the film: the edge and the clipped segment (full-film pixels).
struct FilmEdge {
    size_t edge;  // in Scene::edges()
    // (curved, pair: the barycentrics of its part's ends on the (first) face, the solves' guesses)
    double ax, ay, bx, by;
    double weight = 1.0;  // the edge's density per unit film length, relative to a fold's
    double world = 0.0;   // world length (fisheye and panorama, uniform sampling)
    double len = 0.0;     // its sampling length (film length times weight; see the set-up)
    int plane = -1;       // seen in this plane of smooth faces (SmoothPlanes::planes), or directly (-1)
    bool refracted = false;  // through the plane (else reflected in it)
    int chain = -1;          // seen through this chain of two planes (Chains; plane: its first)
    int curved = -1;         // seen in or through this curved face (CurvedFace)
    int pair = -1;           // seen through this pair of curved faces (CurvedPair)
    double kept = 1.0;       // chained, curved: the probability its set-up was kept with (its samples count 1 / kept)
    double u0 = 0.0, u1 = 1.0;  // refracted, chained, curved: the part of the edge sampled (its ends' parameters)
};

// An edge's set-up through a chain or a curved face, chosen before the set-ups run: the chain or
// face (its index in the call's list) and the edge; for a curved face also the part of the edge
// on the side its lobe sends rays to, and the probability its choice kept it with.
struct ViaSetup {
    int32_t via = -1, edge = -1;
    double u0 = 0.0, u1 = 1.0, kept = 1.0;
};

// Where an edge's part (parameters [lo, hi], `span` long) was found seen at one point only, at
// parameter u and film point (fx, fy): its film length, from the chord to the film point of a
// point du beside it (film_at(v, gx, gy) finds that of parameter v), on either side within the
// part; 0 where neither is found.
template <class FilmAt>
double chord_length(double u, double du, double lo, double hi, double fx, double fy, double span, FilmAt&& film_at) {
    for (const double v : {u + du, u - du}) {
        if (v < lo || v > hi) continue;
        double gx, gy;
        if (film_at(v, gx, gy)) return std::hypot(gx - fx, gy - fy) * span / du;
    }
    return 0.0;
}

// Where one camera sample's rays start: the camera's position, or a thin lens's point of the
// aperture. Seen from a lens point, the camera is a pinhole at that point whose film is shifted
// by (shift_x, shift_y) in screen offsets: a world point q (camera axes, from the lens point) is at
// screen offset q.xy / q.z + shift, shift = the lens point's (right, up) offsets / focus distance.
struct Eye {
    Vec3f position;
    double shift_x = 0.0, shift_y = 0.0;
    float lu = kLensCentre, lv = kLensCentre;  // the lens sample
};

Eye lens_eye(const Camera& cam, float lu, float lv) {
    Eye eye;
    const Vec3f a = cam.lens_offset(lu, lv);
    eye.position = cam.position + a;
    eye.shift_x = double(dot(a, cam.right)) / cam.focus;
    eye.shift_y = double(dot(a, cam.up)) / cam.focus;
    eye.lu = lu;
    eye.lv = lv;
    return eye;
}

// Whether the edge is a fold seen from some point of a thin lens's aperture: each face's plane
// may have the aperture's points on both sides.
bool lens_may_fold(const Camera& cam, const Mesh& m, const Edge& e) {
    if (e.kind == EdgeKind::Boundary) return true;
    if (is_silhouette(cam.position, m.vertex(e.v0), m.face_normal(e.f0), m.face_normal(e.f1), e.kind)) return true;
    bool front[2], back[2];
    for (int i = 0; i < 2; ++i) {
        const Vec3f n = m.face_normal(i == 0 ? e.f0 : e.f1);
        const float s = dot(n, cam.position - m.vertex(e.v0));
        const float reach = cam.aperture * length(n - cam.forward * dot(n, cam.forward));
        front[i] = s + reach > 0.f;
        back[i] = s - reach < 0.f;
    }
    return (front[0] && back[1]) || (back[0] && front[1]);
}

// Clips the segment p(t) = a + t (b - a), t in [t0, t1], to lo <= p <= hi along one axis.
bool clip_axis(double a, double b, double lo, double hi, double& t0, double& t1) {
    const double d = b - a;
    if (d == 0.0) return a >= lo && a <= hi;
    double s0 = (lo - a) / d, s1 = (hi - a) / d;
    if (s0 > s1) std::swap(s0, s1);
    t0 = std::max(t0, s0);
    t1 = std::min(t1, s1);
    return t0 < t1;
}

// A world vector in the camera's axes (right, up, forward).
Vec3d camera_axes(const Camera& cam, const Vec3f& v) {
    return Vec3d(dot(v, cam.right), dot(v, cam.up), dot(v, cam.forward));
}

// Film pixels per unit screen offset, and the film point of screen offset (sx, sy): the inverse
// of Camera::screen.
double film_scale(const Camera& cam) { return cam.width / (2.0 * cam.tx); }
double film_x(const Camera& cam, double sx) { return (sx + cam.tx) * film_scale(cam); }
double film_y(const Camera& cam, double sy) { return cam.height * 0.5 - sy * film_scale(cam); }

// Projects the edge (p0, p1) onto the film from the camera's position and clips it to the window
// [x0, x1] x [y0, y1] (full-film pixels). False when nothing is left. A thin lens's other eyes
// see a point at depth z shifted on the film by at most aperture |1 / focus - 1 / z| in screen
// offsets: the window is widened by that much over the edge's depths, so that every part some
// lens point sees in the window is kept.
bool project_edge(const Camera& cam, const Vec3f& p0, const Vec3f& p1, double x0, double y0, double x1, double y1,
                  FilmEdge& fe) {
    Vec3d q0 = camera_axes(cam, p0 - cam.position), q1 = camera_axes(cam, p1 - cam.position);
    if (has_eye(cam.type)) {
        // Keep the part in front of the camera. (Both ends well in front, as nearly always: no
        // need of `near`, whose lengths' square roots cost more than the rest. The 1-norm bounds
        // the length.)
        auto norm1 = [](const Vec3d& q) { return std::abs(q.x) + std::abs(q.y) + std::abs(q.z); };
        if (!(std::min(q0.z, q1.z) > 2e-5 * std::max(norm1(q0), norm1(q1)))) {
            const double near = 1e-5 * std::max(length(q0), length(q1));
            if (q0.z < near && q1.z < near) return false;
            if (q0.z < near) q0 = q1 + (q0 - q1) * ((q1.z - near) / (q1.z - q0.z));
            if (q1.z < near) q1 = q0 + (q1 - q0) * ((q0.z - near) / (q0.z - q1.z));
        }
        q0.x /= q0.z;
        q0.y /= q0.z;
        q1.x /= q1.z;
        q1.y /= q1.z;
        if (cam.type == CameraType::ThinLens) {
            const double inv_focus = 1.0 / cam.focus;
            const double reach = cam.aperture * film_scale(cam) *
                                 std::max(std::abs(inv_focus - 1.0 / q0.z), std::abs(inv_focus - 1.0 / q1.z));
            x0 -= reach;
            y0 -= reach;
            x1 += reach;
            y1 += reach;
        }
    }
    const double ax = film_x(cam, q0.x), ay = film_y(cam, q0.y), bx = film_x(cam, q1.x), by = film_y(cam, q1.y);
    double t0 = 0.0, t1 = 1.0;
    // Both ends inside the window (most edges of a mesh in view): nothing to clip, and clip_axis
    // would leave t0 at 0 and t1 at 1.
    const bool inside = ax >= x0 && ax <= x1 && bx >= x0 && bx <= x1 && ay >= y0 && ay <= y1 && by >= y0 && by <= y1;
    if (!inside && (!clip_axis(ax, bx, x0, x1, t0, t1) || !clip_axis(ay, by, y0, y1, t0, t1))) return false;
    fe.ax = ax + (bx - ax) * t0;
    fe.ay = ay + (by - ay) * t0;
    fe.bx = ax + (bx - ax) * t1;
    fe.by = ay + (by - ay) * t1;
    return std::isfinite(fe.ax) && std::isfinite(fe.ay) && std::isfinite(fe.bx) && std::isfinite(fe.by);
}

// Film point of world point p seen from `eye` and the film length per unit world length along
// direction `dir` (unit). False behind the camera.
bool film_point(const Camera& cam, const Eye& eye, const Vec3f& p, const Vec3f& dir, double& x, double& y,
                double& jacobian) {
    const Vec3d q = camera_axes(cam, p - eye.position), dq = camera_axes(cam, dir);
    double sx = q.x, sy = q.y, dsx = dq.x, dsy = dq.y;
    if (has_eye(cam.type)) {
        if (!(q.z > 0.0)) return false;
        sx = q.x / q.z + eye.shift_x;
        sy = q.y / q.z + eye.shift_y;
        dsx = (dq.x * q.z - q.x * dq.z) / (q.z * q.z);
        dsy = (dq.y * q.z - q.y * dq.z) / (q.z * q.z);
    }
    x = film_x(cam, sx);
    y = film_y(cam, sy);
    jacobian = film_scale(cam) * std::hypot(dsx, dsy);
    return std::isfinite(x) && std::isfinite(y);
}

// Fisheye and panorama (scene/desc.h): the film point (x, y) that sees world direction w (unit)
// from the camera's position. False outside a fisheye's image circle.
bool spherical_film_point(const Camera& cam, const Vec3f& w, double& x, double& y) {
    const Vec3d q = camera_axes(cam, w);
    const double W = cam.width, H = cam.height;
    if (cam.type == CameraType::Fisheye) {
        const double rho = std::hypot(q.x, q.y), theta = std::atan2(rho, q.z);
        const double r = theta / double(cam.half_fov);
        // (Straight behind, rho = 0, is the whole rim of a 360 degree fisheye: no one point.)
        if (!(r <= 1.0) || (rho == 0.0 && q.z < 0.0)) return false;
        const double nx = rho > 0.0 ? r * q.x / rho : 0.0, ny = rho > 0.0 ? r * q.y / rho : 0.0;
        x = (nx + 1.0) * W * 0.5;
        y = H * 0.5 - ny * W * 0.5;
    } else {
        const double phi = std::atan2(q.x, q.z), lat = std::atan2(q.y, std::hypot(q.x, q.z));
        x = (phi / kCameraPi + 1.0) * W * 0.5;
        y = (1.0 - lat / (kCameraPi * 0.5)) * H * 0.5;
    }
    return std::isfinite(x) && std::isfinite(y);
}

// The smallest angle between the unit direction f and the directions from the camera's
// position to the points of a segment (a, b: its ends relative to the position): at an end, or
// where the great circle through the ends' directions comes nearest f, if that lies between them.
double min_angle_from(const Vec3d& a, const Vec3d& b, const Vec3d& f) {
    auto angle = [](const Vec3d& u, const Vec3d& v) { return std::atan2(length(cross(u, v)), dot(u, v)); };
    const Vec3d ua = normalize(a), ub = normalize(b);
    double best = std::min(angle(ua, f), angle(ub, f));
    const Vec3d n = cross(ua, ub);
    const double nl = length(n);
    if (!(nl > 0.0)) return best;
    const Vec3d un = n / nl, p = f - un * dot(f, un);
    const double pl = length(p);
    if (!(pl > 0.0)) return best;
    const Vec3d up = p / pl;
    if (dot(cross(ua, up), un) >= 0.0 && dot(cross(up, ub), un) >= 0.0) best = std::min(best, angle(up, f));
    return best;
}

// Fisheye and panorama: the derivatives of the unit direction of film point (x, y) with respect
// to x and y (world vectors).
void spherical_film_tangents(const Camera& cam, double x, double y, Vec3d& dx, Vec3d& dy) {
    const double W = cam.width, H = cam.height;
    const Vec3d R(cam.right), U(cam.up), F(cam.forward);
    double ax, bx, cx, ay, by, cy;  // d(a, b, c) / dx and / dy, d = a right + b up + c forward
    if (cam.type == CameraType::Fisheye) {
        const double h = cam.half_fov;
        const double nx = 2.0 * x / W - 1.0, ny = (1.0 - 2.0 * y / H) * H / W;
        const double r = std::hypot(nx, ny), theta = r * h;
        // s = sin(theta) / r and s'(r) / r, by their series near the centre
        double s, ds_r;
        if (r > 1e-4) {
            s = std::sin(theta) / r;
            ds_r = (h * std::cos(theta) * r - std::sin(theta)) / (r * r * r);
        } else {
            s = h - h * h * h * r * r / 6.0;
            ds_r = -h * h * h / 3.0;
        }
        // sin(theta) / r times h, the factor of dc / dn
        const double c_r = r > 1e-4 ? -std::sin(theta) * h / r : -h * h;
        // dn/dx = (2 / W, 0), dn/dy = (0, -2 / W)
        const double kx = 2.0 / W, ky = -2.0 / W;
        ax = (s + nx * nx * ds_r) * kx;
        bx = nx * ny * ds_r * kx;
        cx = c_r * nx * kx;
        ay = nx * ny * ds_r * ky;
        by = (s + ny * ny * ds_r) * ky;
        cy = c_r * ny * ky;
    } else {
        const double phi = (2.0 * x / W - 1.0) * kCameraPi, lat = (1.0 - 2.0 * y / H) * kCameraPi * 0.5;
        const double dphi = 2.0 * kCameraPi / W, dlat = -kCameraPi / H;
        ax = std::cos(lat) * std::cos(phi) * dphi;
        bx = 0.0;
        cx = -std::cos(lat) * std::sin(phi) * dphi;
        ay = -std::sin(lat) * std::sin(phi) * dlat;
        by = std::cos(lat) * dlat;
        cy = -std::sin(lat) * std::cos(phi) * dlat;
    }
    dx = R * ax + U * bx + F * cx;
    dy = R * ay + U * by + F * cy;
}

// The film length per unit displacement of a world direction along tangent vector t (at a
// point where the film's tangents are dx, dy): the norm of the film displacement whose
// direction change is t. Zero where the map is singular (a panorama's poles).
double spherical_jacobian(const Vec3d& dx, const Vec3d& dy, const Vec3d& t) {
    const double g00 = dot(dx, dx), g01 = dot(dx, dy), g11 = dot(dy, dy);
    const double det = g00 * g11 - g01 * g01;
    if (!(det > 0.0)) return 0.0;
    const double b0 = dot(dx, t), b1 = dot(dy, t);
    return std::hypot((g11 * b0 - g01 * b1) / det, (g00 * b1 - g01 * b0) / det);
}

// The parameter t of the point p0 + t (p1 - p0) of segment (p0, p1) nearest to the line
// o + s d (d unit).
float closest_on_segment(const Vec3f& p0, const Vec3f& p1, const Vec3f& o, const Vec3f& d) {
    const Vec3f e = p1 - p0, w = p0 - o;
    const float a = dot(e, e), b = dot(e, d), c = dot(e, w), f = dot(d, w);
    const float den = a - b * b;  // |d| = 1
    return den > 0.f ? std::clamp((b * f - c) / den, 0.f, 1.f) : 0.f;
}

// The lights of a render at one bounce without an environment, as boxes: each emitting mesh's
// (Scene::emitter_boxes) and each point light's position. Those are all the radiance a camera
// ray's first hit gets: next-event estimation towards them, and its one continuation meets only
// emission.
struct LightBoxes {
    std::vector<Vec3f> center, half;
    explicit LightBoxes(const Scene& scene) {
        for (const Scene::Box& b : scene.emitter_boxes) {
            center.push_back((b.lo + b.hi) * 0.5f);
            half.push_back((b.hi - b.lo) * 0.5f);
        }
        for (const PointLightDesc& l : scene.point_lights) {
            center.push_back(Vec3f(l.position[0], l.position[1], l.position[2]));
            half.push_back(Vec3f(0.f));
        }
    }
    // Whether some light may lie between the planes of the faces of edge e (a smooth edge with
    // two faces): neither in front of both nor behind both (by a margin for rounding). Where
    // none does, every light direction from the edge lies on one side of both planes.
    bool between(const Mesh& m, const Edge& e) const {
        const Vec3f p0 = m.vertex(e.v0), n0 = m.triangle_data[e.f0].ng, n1 = m.triangle_data[e.f1].ng;
        for (size_t k = 0; k < center.size(); ++k) {
            const Vec3f c = center[k] - p0, h = half[k];
            auto reach = [&](const Vec3f& n) { return std::abs(n.x) * h.x + std::abs(n.y) * h.y + std::abs(n.z) * h.z; };
            const float f0 = dot(n0, c), f1 = dot(n1, c), r0 = reach(n0), r1 = reach(n1);
            const float margin = 1e-5f * (length(c) + length(h));
            const bool front = f0 - r0 > margin && f1 - r1 > margin, back = f0 + r0 < -margin && f1 + r1 < -margin;
            if (!front && !back) return true;
        }
        return false;
    }
};

// The mirror image of point p across the plane (q, n).
inline Vec3f mirrored(const Vec3f& p, const Vec3f& q, const Vec3f& n) { return p - n * (2.f * dot(p - q, n)); }

// Whether the material reflects a smooth lobe everywhere (a mirror, smooth glass, a smooth
// plastic's coating) and has no normal map: glass and plastic are smooth where their
// roughness is 0.
bool smooth_lobe(const Material& mat) {
    if (mat.kind == MaterialKind::Standard || !mat.normal_map.empty()) return false;
    if (mat.kind == MaterialKind::Conductor) return true;
    const Texture& r = mat.roughness;
    const int64_t texels = int64_t(r.width) * r.height * r.channels;
    return r.empty() || *std::min_element(r.data, r.data + texels) <= 0.f;
}

// The direction part of a smooth material's delta_params (no textures: those weigh, they do not
// turn), in double.
DeltaParams<double> delta_turn(const Material& mat) {
    DeltaParams<double> d;
    d.dielectric = mat.kind == MaterialKind::Dielectric;
    d.coat = mat.kind == MaterialKind::Plastic;
    d.two_sided = mat.two_sided;
    d.eta = d.dielectric && mat.ior.is_constant() ? double(mat.ior.data[0]) : 1.0;  // (glass of one index refracts)
    return d;
}

// Planes of smooth faces: the faces of a mesh whose material reflects a smooth lobe (a mirror,
// smooth glass, a smooth plastic's coating) and whose shading normal is its geometric normal
// (no vertex normals, no normal map), grouped by the plane they lie in. What the camera sees
// in such a face is the scene mirrored across its plane: an edge seen there is the virtual edge
// (its mirror image), projected onto the film like any other, but seen only through the faces
// of that plane, and its step is the reflected lobe's weight times the step of the radiance
// arriving at the mirror. The faces' plane moves with their vertices, so their gradients get
// a share of the virtual edge's. Glass refracts too (Refraction, below).
struct SmoothPlane {
    int mesh = -1;
    Vec3f q, n;              // a point of the plane and its unit normal, turned towards the camera
    float tol = 0.f;         // distances from the plane below this count as in it
    EdgeEye eye;             // the camera's position mirrored: the eye that sees the virtual edges
    Camera lens;             // a thin lens mirrored (its position and axis), for lens_may_fold
    double x0, y0, x1, y1;   // the film window its faces cover, within the pass's
    // Smooth glass of one index (a constant texture) refracts too: the camera sees the far side
    // through its faces, the edges there bent (Refraction, below).
    bool refracts = false;
    double eta = 1.0;        // the far side's index over the camera's side's
    int material = -1;
    bool behind = false;     // the camera behind its faces (by their winding)
    TFrame<double> axes;     // about n
    // How its faces turn a ray (for chains of two planes, below): the direction's part of its
    // material's delta_params (no textures: those weigh, they do not turn), about the faces'
    // normal by their winding (delta_scatter finds the side a ray comes from).
    DeltaParams<double> delta;
    Vec3d winding_n;
    // The box its faces span in the plane, in those axes from q.
    double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    double hi[2] = {-std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};

    // Corner k (0 to 3) of that box, in world space.
    Vec3d corner(int k) const { return Vec3d(q) + axes.s * (k & 1 ? hi[0] : lo[0]) + axes.t * (k & 2 ? hi[1] : lo[1]); }
};

// At most kMirrorSetups edge set-ups over all planes (each plane sets up every edge of the
// scene, twice for glass): the planes the camera sees from their front first (inside a closed
// mesh, faces seen from behind are hidden by others), then those whose faces cover the most
// film. (A glass plane's refracted set-up costs a few tens of nanoseconds where it is culled.)
constexpr double kMirrorSetups = double(1 << 21);

struct SmoothPlanes {
    std::vector<SmoothPlane> planes;
    std::vector<std::vector<int32_t>> plane_of;  // per mesh, per triangle: its plane's index, or -1

    SmoothPlanes() = default;
    SmoothPlanes(const Scene& scene, const Camera& cam, double wx0, double wy0, double wx1, double wy1) {
        plane_of.resize(scene.meshes.size());
        std::vector<double> areas;
        const size_t num_edges = scene.edges().size();
        const bool parallel = cam.type == CameraType::Orthographic;
        // A thin lens's points see the faces shifted on the film: the whole window.
        const bool lens = cam.type == CameraType::ThinLens;
        for (size_t i = 0; i < scene.meshes.size(); ++i) {
            const Mesh& m = scene.meshes[i];
            const Material& mat = scene.materials[size_t(m.material)];
            if (m.normals || !smooth_lobe(mat)) continue;
            // Planes a ten-thousandth of the mesh's size apart are one (and the faces of one plane
            // further apart than rounding, as far from the origin as they may lie, several: that
            // costs samples only, since each face is seen only through its own plane's samples).
            Vec3f lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
            for (int64_t v = 0; v < m.num_vertices; ++v) {
                const Vec3f p = m.vertex(v);
                lo = Vec3f(std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z));
                hi = Vec3f(std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z));
            }
            const float quantum = 1e-4f * length(hi - lo);
            if (!(quantum > 0.f)) continue;
            // A one-sided mirror or coating reflects only on the front of its faces.
            const bool front_only = mat.kind != MaterialKind::Dielectric && !mat.two_sided;
            std::map<std::array<int64_t, 5>, int32_t> by_plane;
            // Glass of one index refracts: the far side's index over the near side's is the index
            // seen from outside, its inverse from inside.
            const bool refracts = mat.kind == MaterialKind::Dielectric && mat.ior.is_constant();
            const double ior = refracts ? double(mat.ior.data[0]) : 1.0;
            std::vector<int32_t>& of = plane_of[i];
            of.assign(size_t(m.num_triangles), -1);
            for (int64_t f = 0; f < m.num_triangles; ++f) {
                if (m.is_degenerate(f)) continue;
                const int32_t* t = m.indices + 3 * f;
                Vec3f n = m.unit_face_normal(f);
                const Vec3f a = m.vertex(t[0]);
                // (How far in front of the face the camera is, or for parallel rays how steeply.)
                float side = parallel ? -dot(n, cam.forward) : dot(n, cam.position - a);
                if (front_only && !(side > 0.f)) continue;
                const bool behind = side < 0.f;  // the camera inside (behind the faces)
                if (behind) n = -n, side = -side;
                if (!(side > 0.f)) continue;  // the camera in the plane: it sees the face edge-on
                const std::array<int64_t, 5> key = {std::llround(n.x * 1e4f), std::llround(n.y * 1e4f),
                                                    std::llround(n.z * 1e4f), std::llround(dot(n, a) / quantum),
                                                    behind};
                auto [it, added] = by_plane.emplace(key, int32_t(planes.size()));
                if (added) {
                    SmoothPlane mp;
                    mp.mesh = int(i);
                    mp.q = a;
                    mp.n = n;
                    mp.tol = 0.1f * quantum;
                    mp.eye.origin = mirrored(cam.position, a, n);
                    mp.eye.parallel = parallel;
                    mp.eye.dir = cam.forward - n * (2.f * dot(cam.forward, n));
                    mp.lens = cam;
                    mp.lens.position = mp.eye.origin;
                    mp.lens.forward = mp.eye.dir;
                    mp.behind = behind;
                    mp.axes = TFrame<double>(Vec3d(n));
                    mp.refracts = refracts;
                    mp.eta = behind ? 1.0 / ior : ior;
                    mp.material = m.material;
                    mp.delta = delta_turn(mat);
                    mp.winding_n = normalize(Vec3d(behind ? -n : n));
                    mp.x0 = mp.y0 = std::numeric_limits<double>::infinity();
                    mp.x1 = mp.y1 = -std::numeric_limits<double>::infinity();
                    planes.push_back(mp);
                    areas.push_back(0.0);
                }
                of[size_t(f)] = it->second;
                SmoothPlane& mp = planes[size_t(it->second)];
                for (int c = 0; c < 3; ++c) {
                    const Vec3d local = mp.axes.to_local(Vec3d(m.vertex(t[c])) - Vec3d(mp.q));
                    mp.lo[0] = std::min(mp.lo[0], local.x), mp.hi[0] = std::max(mp.hi[0], local.x);
                    mp.lo[1] = std::min(mp.lo[1], local.y), mp.hi[1] = std::max(mp.hi[1], local.y);
                }
                for (int c = 0; c < 3; ++c) {
                    const Vec3d qc = camera_axes(cam, m.vertex(t[c]) - cam.position);
                    if (lens || (!parallel && !(qc.z > 1e-6 * length(qc)))) {
                        // Reaches behind the camera, or a thin lens: the whole window.
                        mp.x0 = wx0, mp.y0 = wy0, mp.x1 = wx1, mp.y1 = wy1;
                        continue;
                    }
                    const double x = film_x(cam, parallel ? qc.x : qc.x / qc.z);
                    const double y = film_y(cam, parallel ? qc.y : qc.y / qc.z);
                    mp.x0 = std::min(mp.x0, x), mp.x1 = std::max(mp.x1, x);
                    mp.y0 = std::min(mp.y0, y), mp.y1 = std::max(mp.y1, y);
                }
            }
        }
        // The windows within the pass's (a pixel wider, against rounding), their areas; the
        // planes kept.
        std::vector<size_t> order;
        for (size_t k = 0; k < planes.size(); ++k) {
            SmoothPlane& mp = planes[k];
            mp.x0 = std::max(mp.x0 - 1.0, wx0), mp.y0 = std::max(mp.y0 - 1.0, wy0);
            mp.x1 = std::min(mp.x1 + 1.0, wx1), mp.y1 = std::min(mp.y1 + 1.0, wy1);
            if (mp.x0 < mp.x1 && mp.y0 < mp.y1) {
                areas[k] = (mp.x1 - mp.x0) * (mp.y1 - mp.y0);
                order.push_back(k);
            }
        }
        std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
            return planes[a].behind != planes[b].behind ? !planes[a].behind : areas[a] > areas[b];
        });
        // (Glass planes count twice: reflected and refracted.)
        size_t keep = 0;
        double setups = 0.0;
        for (; keep < order.size(); ++keep) {
            setups += double(num_edges) * (planes[order[keep]].refracts ? 2.0 : 1.0);
            if (keep > 0 && setups > kMirrorSetups) break;
        }
        std::vector<int32_t> index(planes.size(), -1);
        std::vector<SmoothPlane> kept;
        for (size_t r = 0; r < keep; ++r) {
            index[order[r]] = int32_t(kept.size());
            kept.push_back(planes[order[r]]);
        }
        planes = std::move(kept);
        for (std::vector<int32_t>& of : plane_of)
            for (int32_t& p : of)
                if (p >= 0) p = index[size_t(p)];
    }
};

// Adds to the adjoints of p, q and n (dp, dq, dn) that of mirrored(p, q, n) for its adjoint a.
inline void d_mirrored(const Vec3f& p, const Vec3f& q, const Vec3f& n, const Vec3f& a, Vec3f& dp, Vec3f& dq,
                       Vec3f& dn) {
    // m = p - 2 s n, s = (p - q) . n
    const float na = dot(n, a), s = dot(p - q, n);
    dp += a - n * (2.f * na);
    dq += n * (2.f * na);
    dn += a * (-2.f * s) - (p - q) * (2.f * na);
}

// Refraction. Seen through a flat face of smooth glass, a point e on the far side of its plane
// (q, n: unit, towards the eye) is where the ray from the eye bends towards it: at the point x
// of the plane where Snell's law holds, sin(i) = eta sin(t) (eta: the far side's index over the
// near side's), in the plane of incidence (the eye, e and the normal). With h1 the eye's height
// over the plane, h2 e's depth, d the distance between their feet and a x's distance from the
// eye's, f(a) = a / |(a, h1)| - eta (d - a) / |(d - a, h2)| rises from f(0) <= 0 to f(d) >= 0:
// one root, found by Newton's steps kept inside a bisection's bracket. An edge seen there is a
// curve on the film, no longer a segment: sampled along the edge, each point weighted by the
// film length per unit of the edge's parameter (a difference quotient of this map).
bool refraction_point(const Vec3d& eye, const Vec3d& e, const Vec3d& q, const Vec3d& n, double eta, Vec3d& x) {
    const double h1 = dot(eye - q, n), h2 = -dot(e - q, n);
    if (!(h1 > 0.0 && h2 >= 0.0)) return false;
    const Vec3d foot1 = eye - n * h1, u = (e + n * h2) - foot1;
    const double d = length(u);
    if (!(d > 0.0)) {
        x = foot1;
        return true;
    }
    double lo = 0.0, hi = d, a = d * h1 / (h1 + h2);  // the straight line's crossing
    for (int k = 0; k < 64; ++k) {
        const double b = d - a, r1 = std::sqrt(a * a + h1 * h1), r2 = std::sqrt(b * b + h2 * h2);
        const double f = a / r1 - (r2 > 0.0 ? eta * b / r2 : eta);
        (f > 0.0 ? hi : lo) = a;
        const double df = h1 * h1 / (r1 * r1 * r1) + (r2 > 0.0 ? eta * h2 * h2 / (r2 * r2 * r2) : 0.0);
        double next = a - f / df;
        if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
        const bool done = std::abs(next - a) <= 1e-14 * d;
        a = next;
        if (done) break;
    }
    x = foot1 + u * (a / d);
    return std::isfinite(x.x) && std::isfinite(x.y) && std::isfinite(x.z);
}

// The direction parallel rays w (unit, towards the plane) take past the plane (normal n towards
// them; eta as above). False under total internal reflection.
bool refracted_direction(const Vec3d& w, const Vec3d& n, double eta, Vec3d& r) {
    const double c1 = -dot(w, n), q = (1.0 - c1 * c1) / (eta * eta);
    if (!(c1 > 0.0) || q >= 1.0) return false;
    r = w / eta + n * (c1 / eta - std::sqrt(1.0 - q));
    return true;
}

// Chains of two planes. Some edges are seen after two smooth faces: through a pane (in at one
// face, out at the other), in a face of a glass object from inside after entering at another
// (a Fresnel or total internal reflection), in a mirror seen in another mirror. A chain is two
// planes of SmoothPlanes, each reflecting or (glass of one index) refracting, and the film point
// that sees an edge point e through it has no closed form: the point x1 of the first plane where
// the camera ray must meet it is found by Gauss-Newton steps on x1's coordinates in that plane
// (the ray from the eye through x1, turned there, meets the second plane, is turned there, and
// must pass e). An edge seen so is sampled like one seen through a plane: along the edge, each
// point weighted by the film length per unit of the edge's parameter.

// A bundle of rays, bounded (where `bounded`): their origins within the ball (origin,
// origin_radius), their directions within the cone about `axis` of half-angle `spread`. An edge
// outside every ray from that ball within that cone is not seen.
struct Beam {
    bool bounded = false;
    Vec3d origin, axis;
    double origin_radius = 0.0, spread = 0.0, cos_spread = -1.0, sin_spread = 0.0;

    // Whether a ray from the origin ball within the cone may meet the segment (p0, p1) (below): the
    // segment's ball seen from the origin ball's centre within the cone widened by both balls'
    // angular radius b, sin b = reach / dist (compared by cosines: cos(angle) >= cos(spread + b)).
    bool may_see(const Vec3d& p0, const Vec3d& p1) const { return may_see_ball((p0 + p1) * 0.5, 0.5 * length(p1 - p0)); }
    // The same for a ball (c, radius).
    bool may_see_ball(const Vec3d& c, double radius) const {
        if (!bounded) return true;
        const Vec3d to = c - origin;
        const double dist = length(to), reach = origin_radius + radius;
        if (!(dist > reach)) return true;
        // (spread < pi / 2 where bounded and b <= pi / 2: their sum below a half turn, where the
        // cosine falls.)
        const double sin_b = reach / dist, cos_b = std::sqrt(1.0 - sin_b * sin_b);
        return dot(to, axis) >= dist * (cos_spread * cos_b - sin_spread * sin_b);
    }

    // The cone of the unit directions d[0, k) (their sum nonzero): about their mean, as wide as
    // the widest angle from it times `widen`, plus `extra` radians. False where that is not
    // below a quarter turn (no bound).
    bool bound_directions(const Vec3d* d, int k, double widen, double extra) {
        Vec3d sum(0.0);
        for (int j = 0; j < k; ++j) sum = sum + d[j];
        if (!(length(sum) > 0.0)) return false;
        axis = normalize(sum);
        spread = 0.0;
        for (int j = 0; j < k; ++j) spread = std::max(spread, widen * std::acos(std::clamp(dot(d[j], axis), -1.0, 1.0)));
        spread += extra;
        cos_spread = std::cos(spread);
        sin_spread = std::sin(spread);
        return std::isfinite(spread) && spread < 0.5 * kPi;
    }
};

// A chain of two planes: the eye sees edge point e through face points x1 of the first plane and
// x2 of the second (the ray from the eye through x1, turned there, meets the second plane, is
// turned there, and must pass e). Its beam bounds the rays leaving the second plane.
struct Chain : Beam {
    int plane[2] = {-1, -1};
    bool refract[2] = {false, false};
};

// At most this many edge set-ups over all chains (each costs a few Newton solves), and this many
// edges tested against their beams in choosing them (chains without a beam test every edge).
constexpr double kChainSetups = double(1 << 18);
constexpr double kChainTests = double(1 << 24);

// Follows the ray from o along d through the chain's (unbounded) planes: x1, the first plane's
// point, x, the second's, and dir, the direction leaving it. False where the ray misses a plane
// (parallel to it, or behind) or a lobe does not exist there.
bool follow_chain(const std::vector<SmoothPlane>& planes, const Chain& ch, Vec3d o, Vec3d d, Vec3d& x1, Vec3d& x,
                  Vec3d& dir) {
    for (int k = 0; k < 2; ++k) {
        const SmoothPlane& mp = planes[size_t(ch.plane[k])];
        const double t = dot(Vec3d(mp.q) - o, mp.winding_n) / dot(d, mp.winding_n);
        if (!(t > 0.0) || !std::isfinite(t)) return false;
        o = o + d * t;
        if (k == 0) x1 = o;
        Vec3d weight;
        if (!delta_scatter(mp.delta, mp.winding_n, -d, ch.refract[k], 1.0, d, weight)) return false;
    }
    x = o;
    dir = d;
    return true;
}

// A first guess of x1 for edge point e: the ray from the eye (or along `forward`, parallel rays)
// to e's image unfolded across the reflecting planes (exact for two reflections, refractions
// taken straight), where it meets the first plane; e's foot on it where that line is parallel.
Vec3d chain_guess(const std::vector<SmoothPlane>& planes, const Chain& ch, const Vec3d& eye, bool parallel,
                  const Vec3d& forward, const Vec3d& e) {
    Vec3d v = e;
    for (int k = 1; k >= 0; --k)
        if (!ch.refract[k]) {
            const SmoothPlane& mp = planes[size_t(ch.plane[k])];
            v = v - mp.winding_n * (2.0 * dot(v - Vec3d(mp.q), mp.winding_n));
        }
    const SmoothPlane& first = planes[size_t(ch.plane[0])];
    const Vec3d q(first.q), n(first.winding_n);
    const Vec3d from = parallel ? v : eye, dir = parallel ? forward : v - eye;
    const Vec3d x = from + dir * (dot(q - from, n) / dot(dir, n));
    if (std::isfinite(x.x) && std::isfinite(x.y) && std::isfinite(x.z)) return x;
    return e - n * dot(e - q, n);
}

// Gauss-Newton steps on two coordinates (a, b) towards a zero of residual(a, b, r) (a 3-vector;
// false where it is not defined), the Jacobian by differences of 1e-7 (scale + |a| + |b|).
// Steps that do not lower |r| are halved, up to 10 times; three slow steps in a row far from a
// root give up. True where |r| <= 1e-10 at the (a, b) it leaves.
template <class Residual>
bool solve_2d(Residual&& residual, double scale, double& a, double& b) {
    Vec3d r;
    if (!residual(a, b, r)) return false;
    double err = length(r);
    int slow = 0;  // steps in a row that did not halve the error, far from a root
    for (int it = 0; it < 24 && err > 1e-13; ++it) {
        const double h = 1e-7 * (scale + std::abs(a) + std::abs(b));
        Vec3d ra, rb;
        double ha = h, hb = h;
        if (!residual(a + ha, b, ra)) {
            ha = -h;
            if (!residual(a + ha, b, ra)) return false;
        }
        if (!residual(a, b + hb, rb)) {
            hb = -h;
            if (!residual(a, b + hb, rb)) return false;
        }
        const Vec3d ja = (ra - r) / ha, jb = (rb - r) / hb;
        const double m00 = dot(ja, ja), m01 = dot(ja, jb), m11 = dot(jb, jb);
        const double g0 = dot(ja, r), g1 = dot(jb, r), det = m00 * m11 - m01 * m01;
        if (!(det > 0.0)) return false;
        double da = -(m11 * g0 - m01 * g1) / det, db = -(m00 * g1 - m01 * g0) / det;
        bool stepped = false;
        const double before = err;
        for (int halve = 0; halve < 10 && !stepped; ++halve, da *= 0.5, db *= 0.5) {
            Vec3d rn;
            if (residual(a + da, b + db, rn) && length(rn) < err) {
                a += da, b += db, r = rn, err = length(rn);
                stepped = true;
            }
        }
        // (Gauss-Newton steps near a root shrink the error fast: slow ones, far from any, tend
        // to a minimum of the error that is no root.)
        slow = err > 0.5 * before && err > 1e-6 ? slow + 1 : 0;
        if (!stepped || slow == 3) break;
    }
    return err <= 1e-10;
}

// The angle residual of a ray leaving x along dir that should pass e: the unit direction to e
// less dir's. False where e is at x or it is not finite.
bool towards(const Vec3d& x, const Vec3d& dir, const Vec3d& e, Vec3d& r) {
    const Vec3d to = e - x;
    const double len = length(to);
    if (!(len > 0.0)) return false;
    r = to / len - normalize(dir);
    return std::isfinite(r.x) && std::isfinite(r.y) && std::isfinite(r.z);
}

// The chain's point x1 (in: the guess) and x2 through which the eye (a point, or parallel rays
// along `forward`) sees e (solve_2d on x1's coordinates in the first plane).
bool chain_point(const std::vector<SmoothPlane>& planes, const Chain& ch, const Vec3d& eye, bool parallel,
                 const Vec3d& forward, const Vec3d& e, Vec3d& x1, Vec3d& x2) {
    const SmoothPlane& first = planes[size_t(ch.plane[0])];
    const Vec3d q(first.q);
    const TFrame<double>& axes = first.axes;
    // The size of the first plane's faces: the Jacobian's step and, for parallel rays, how far
    // before x1 they start (a unit would round away a small scene's detail).
    const double scale = std::abs(first.hi[0] - first.lo[0]) + std::abs(first.hi[1] - first.lo[1]);
    const double back = scale > 0.0 ? scale : 1.0;
    auto follow = [&](double a, double b, Vec3d& r, Vec3d& p1, Vec3d& p2) {
        const Vec3d x = q + axes.s * a + axes.t * b;
        Vec3d dir;
        return follow_chain(planes, ch, parallel ? x - forward * back : eye, parallel ? forward : normalize(x - eye),
                            p1, p2, dir) &&
               towards(p2, dir, e, r);
    };
    const Vec3d local = axes.to_local(x1 - q);
    double a = local.x, b = local.y;
    Vec3d r;
    Vec3d p1, p2;
    if (!solve_2d([&](double u, double v, Vec3d& res) { return follow(u, v, res, p1, p2); }, scale, a, b))
        return false;
    return follow(a, b, r, x1, x2);
}

// Curved smooth faces. A mesh with shading normals (interpolated across each face) whose
// material reflects a smooth lobe is a curved mirror or piece of glass: each face turns the rays
// through it by its own, varying normal, and the film point through which the camera sees an
// edge point e in it (or through it) has no closed form. A CurvedFace is one face with one lobe
// (reflection, or refraction for glass of one index): the point where the camera ray must meet
// it is found by Gauss-Newton steps on that point's barycentrics (solve_2d); the turned ray is
// the renderer's: the interpolated normal, normalised and bent (bend_normal), the delta lobe about
// it, kept on its side of the face (delta_side). Edges are sampled along their parameter and
// weighted by the film length per unit parameter (as through a plane), each face's samples only
// where the camera ray meets that face first. Its beam bounds the rays leaving it: from the
// face's ball, within the cone of the three corners' turned rays widened by a quarter (their
// normals and the camera's rays turn smoothly across it).
struct CurvedFace : Beam {
    int mesh = -1;
    int64_t prim = -1;
    bool refract = false;
    bool behind = false;  // the camera behind the face (by its winding)
    int32_t solid = -1;    // the solid its closed mesh bounds (mesh_solids), or -1
    DeltaParams<double> delta;
    Vec3d v0, e1, e2, ng;  // its first vertex, edges from there, unit geometric normal
    Vec3d n[3];            // its vertices' shading normals, as given (interpolated, then normalised)
    double film_area = 0.0;

    // How far p lies on the side of the face's plane its lobe sends rays to, and the tolerance
    // beyond which it counts as there (a millionth of the face's size).
    int out_sign() const { return behind != refract ? -1 : 1; }
    double out_height(const Vec3d& p) const { return out_sign() * dot(p - v0, ng); }
    double out_tol() const { return 1e-6 * (length(e1) + length(e2)); }

    // The normal interpolated at barycentrics (b1, b2) of its plane (beyond the face, at the
    // face's point clamp_into_triangle gives), normalised; the geometric one where it is zero.
    Vec3d shading_normal(double b1, double b2) const {
        clamp_into_triangle(b1, b2);
        const Vec3d N = n[0] * (1.0 - b1 - b2) + n[1] * b1 + n[2] * b2;
        const double l = length(N);
        return l > 0.0 ? N / l : ng;
    }

    CurvedFace() = default;
    // Face f of mesh `mesh` (one with shading normals and a smooth lobe): its corners, normals and
    // lobe (reflected; its sides, beam and film area unset).
    CurvedFace(const Scene& scene, int mesh_index, int64_t f) : mesh(mesh_index), prim(f) {
        const Mesh& m = scene.meshes[size_t(mesh_index)];
        const int32_t *t = m.indices + 3 * f, *ni = m.normal_indices + 3 * f;
        Vec3d v[3];
        for (int c = 0; c < 3; ++c) {
            v[c] = Vec3d(m.vertex(t[c]));
            n[c] = Vec3d(Vec3f::load(m.normals + 3 * ni[c]));
        }
        v0 = v[0], e1 = v[1] - v[0], e2 = v[2] - v[0];
        ng = Vec3d(m.unit_face_normal(f));
        delta = delta_turn(scene.materials[size_t(m.material)]);
    }
    Vec3d centre() const { return v0 + (e1 + e2) / 3.0; }
    // The barycentrics of its plane's point nearest x (least squares); false where not finite.
    bool barycentrics(const Vec3d& x, double& b1, double& b2) const {
        const Vec3d w = x - v0;
        const double a11 = dot(e1, e1), a12 = dot(e1, e2), a22 = dot(e2, e2);
        const double r1 = dot(w, e1), r2 = dot(w, e2), det = a11 * a22 - a12 * a12;
        const double g1 = (a22 * r1 - a12 * r2) / det, g2 = (a11 * r2 - a12 * r1) / det;
        if (!std::isfinite(g1) || !std::isfinite(g2)) return false;
        b1 = g1, b2 = g2;
        return true;
    }

    // The direction `dir` the face turns a ray of direction d into at barycentrics (b1, b2) of its
    // plane; false where the lobe does not exist. Outside the face the normal is that of the
    // face's point clamp_into_triangle gives: extrapolated normals turn rays so far that solves
    // for the points seen in a neighbouring face fail, and a part seen in a small face between
    // two points of an edge's set-up was lost (an 8-ring mirror ball's reflection 2.5% short).
    // (`lobe`, where given: the mean of the lobe's weight there.)
    bool turn(double b1, double b2, const Vec3d& d, Vec3d& dir, double* lobe = nullptr) const {
        const Vec3d wo = -d, ns = bend_normal(shading_normal(b1, b2), ng, wo);
        Vec3d weight;
        if (!delta_scatter(delta, ns, wo, refract, 1.0, dir, weight)) return false;
        dir = delta_side(dir, ng, delta_side_sign(wo, ng, refract));
        if (lobe) *lobe = (weight.x + weight.y + weight.z) / 3.0;
        return true;
    }

    // Whether a smooth edge (faces' unit normals n0, n1, a point q of it) may fold seen from
    // some point of the face: false where each of the two planes has the face's three corners on
    // one side or on the plane (within a billionth of the face's size), the same side for both
    // (the sides are linear over the face: it folds at most from a part of no area). From a face
    // of a convex closed mesh (a glass ball's refractions and internal reflections, its faces'
    // neighbours included) none of its edges folds: they were set up, and their samples found
    // nothing. (A plane that holds all three corners: the face's own, or one of its plane.)
    bool may_fold(const Vec3d& q, const Vec3d& n0, const Vec3d& n1) const {
        const double tol = 1e-9 * (length(e1) + length(e2));
        int sides[2] = {0, 0};
        for (int k = 0; k < 2; ++k)
            for (const Vec3d& c : {v0, v0 + e1, v0 + e2}) {
                const double h = dot(c - q, k == 0 ? n0 : n1);
                const int side = h > tol ? 1 : h < -tol ? -1 : 0;
                if (side != 0 && sides[k] != 0 && side != sides[k]) return true;
                if (side != 0) sides[k] = side;
            }
        return sides[0] == 0 || sides[0] != sides[1];
    }

    // The part (u0, u1) of the segment (p0, p1) on the side of the face's plane its lobe sends
    // rays to (reflected rays leave on the camera's side, refracted ones on the other); false
    // where none is (beyond a millionth of the face's size).
    bool out_side(const Vec3d& p0, const Vec3d& p1, double& u0, double& u1) const {
        const double h0 = out_height(p0), h1 = out_height(p1);
        const double tol = out_tol();
        if (!(h0 > tol || h1 > tol)) return false;
        u0 = h0 < 0.0 ? h0 / (h0 - h1) : 0.0;
        u1 = h1 < 0.0 ? h0 / (h0 - h1) : 1.0;
        return true;
    }
};

// At most this many edge set-ups over all curved faces, and this many edges tested against their
// beams in choosing them (faces without a beam test every edge).
constexpr double kCurvedSetups = double(1 << 16);
constexpr double kCurvedTests = double(1 << 20);
// The same for pairs of curved faces (the faces' beams' faces tested in choosing the pairs count
// too, apart).
constexpr double kPairSetups = double(1 << 20);
constexpr double kPairTests = double(1 << 20);

// Balls (a centre and a radius, each with an id) in a tree of balls, for finding those a beam may
// see: each node's ball holds its items', a leaf's up to 8; split at the median of the longest
// side of its items' centres' box.
class BallTree {
public:
    BallTree() = default;
    BallTree(std::vector<Vec3d> mid, std::vector<double> half, std::vector<int32_t> ids)
        : order_(std::move(ids)), mid_(std::move(mid)), half_(std::move(half)) {
        std::vector<int32_t> items(order_.size());
        for (size_t k = 0; k < items.size(); ++k) items[k] = int32_t(k);
        if (!items.empty()) build(items, 0, int32_t(items.size()));
        std::vector<int32_t> id_of(items.size());
        for (size_t k = 0; k < items.size(); ++k) id_of[k] = order_[size_t(items[k])];
        leaf_items_ = std::move(items);
        order_ = std::move(id_of);
    }
    // Calls fn(id) for each item whose ball `beam` may see, in the tree's order.
    template <class Fn>
    void visit(const Beam& beam, Fn&& fn) const {
        if (nodes_.empty()) return;
        int32_t stack[64];
        int top = 0;
        stack[top++] = 0;
        while (top > 0) {
            const Node& node = nodes_[size_t(stack[--top])];
            if (!beam.may_see_ball(node.c, node.r)) continue;
            if (node.left < 0) {
                for (int32_t k = node.begin; k < node.end; ++k) {
                    const size_t item = size_t(leaf_items_[size_t(k)]);
                    if (beam.may_see_ball(mid_[item], half_[item])) fn(order_[size_t(k)]);
                }
                continue;
            }
            stack[top++] = node.right;
            stack[top++] = node.left;
        }
    }

private:
    struct Node {
        Vec3d c;
        double r = 0.0;
        int32_t begin = 0, end = 0, left = -1, right = -1;
    };
    std::vector<int32_t> order_, leaf_items_;  // by position in the tree: the id, its item
    std::vector<Vec3d> mid_;                   // by item: the ball's centre and radius
    std::vector<double> half_;
    std::vector<Node> nodes_;

    int32_t build(std::vector<int32_t>& items, int32_t begin, int32_t end) {
        const int32_t index = int32_t(nodes_.size());
        nodes_.push_back(Node());
        Vec3d lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
        for (int32_t k = begin; k < end; ++k) {
            const Vec3d& c = mid_[size_t(items[size_t(k)])];
            lo = Vec3d(std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z));
            hi = Vec3d(std::max(hi.x, c.x), std::max(hi.y, c.y), std::max(hi.z, c.z));
        }
        Node node;
        node.c = (lo + hi) * 0.5;
        for (int32_t k = begin; k < end; ++k) {
            const size_t item = size_t(items[size_t(k)]);
            node.r = std::max(node.r, length(mid_[item] - node.c) + half_[item]);
        }
        node.r *= 1.0 + 1e-9;
        node.begin = begin;
        node.end = end;
        // (Depth below 64: a split halves the count, down to 8 a leaf.)
        if (end - begin > 8) {
            const Vec3d size = hi - lo;
            const int axis = size.x >= size.y && size.x >= size.z ? 0 : (size.y >= size.z ? 1 : 2);
            const int32_t half = begin + (end - begin) / 2;
            std::nth_element(items.begin() + begin, items.begin() + half, items.begin() + end, [&](int32_t a, int32_t b) {
                const Vec3d &ca = mid_[size_t(a)], &cb = mid_[size_t(b)];
                const double va = axis == 0 ? ca.x : axis == 1 ? ca.y : ca.z, vb = axis == 0 ? cb.x : axis == 1 ? cb.y : cb.z;
                return va < vb || (va == vb && a < b);
            });
            node.left = build(items, begin, half);
            node.right = build(items, half, end);
        }
        nodes_[size_t(index)] = node;
        return index;
    }
};

// The scene's edges that are not flat as balls (their midpoints, half their lengths), each by
// its index in scene.edges().
BallTree edge_balls_of(const Scene& scene) {
    const std::vector<Edge>& edges = scene.edges();
    std::vector<Vec3d> mid;
    std::vector<double> half;
    std::vector<int32_t> ids;
    for (size_t i = 0; i < edges.size(); ++i) {
        const Edge& e = edges[i];
        if (e.flat) continue;
        const Mesh& m = scene.meshes[size_t(e.mesh)];
        const Vec3d p0(m.vertex(e.v0)), p1(m.vertex(e.v1));
        ids.push_back(int32_t(i));
        mid.push_back((p0 + p1) * 0.5);
        half.push_back(0.5 * length(p1 - p0));
    }
    return BallTree(std::move(mid), std::move(half), std::move(ids));
}

// A first guess of the barycentrics (b1, b2) of curved face cf's point for edge point e, seen
// from the eye (a point, or parallel rays along `forward`): as if the face were the plane through
// its centre whose normal is its corners' normals' mean, e mirrored across it and seen from the
// eye, or the eye's ray refracted there to e (exact for a flat face); its centre where that
// fails.
void curved_guess(const CurvedFace& cf, const Vec3d& eye, bool parallel, const Vec3d& forward, const Vec3d& e,
                  double& b1, double& b2) {
    b1 = b2 = 1.0 / 3.0;
    const Vec3d c = cf.v0 + (cf.e1 + cf.e2) / 3.0;
    Vec3d n = normalize(normalize(cf.n[0]) + normalize(cf.n[1]) + normalize(cf.n[2]));
    if (parallel ? dot(n, forward) > 0.0 : dot(n, eye - c) < 0.0) n = -n;  // towards the eye
    Vec3d x;
    if (!cf.refract) {
        const Vec3d mirrored = e - n * (2.0 * dot(e - c, n));
        const Vec3d from = parallel ? mirrored : eye, dir = parallel ? forward : mirrored - eye;
        x = from + dir * (dot(c - from, n) / dot(dir, n));
    } else {
        // (The far side's index over the near side's: the material's from its front.)
        const double eta = cf.behind ? 1.0 / cf.delta.eta : cf.delta.eta;
        if (parallel) {
            Vec3d r;
            if (!refracted_direction(forward, n, eta, r)) return;
            x = e - r * (dot(e - c, n) / dot(r, n));
        } else if (!refraction_point(eye, e, c, n, eta, x)) {
            return;
        }
    }
    // Its barycentrics (least squares in the face's plane).
    cf.barycentrics(x, b1, b2);
}

bool inside_triangle(double b1, double b2) { return b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0; }

// Gauss-Newton steps (solve_2d) on a face's barycentrics (b1, b2; in: the guess) towards a zero
// of residual(b1, b2, r). Where they end outside the face (inside(b1, b2) false) or fail, and
// `restart` > 0, they start again from the face's point nearest the one found outside (where one
// was), then from up to `restart` (at most 9) more: its centre, points near its corners, then
// points between those; the first point found inside is kept (else the one found outside). False
// where none was found (with `restart` 0: never; the steps' last point is kept).
template <class Residual, class Inside>
bool solve_in_face(Residual&& residual, Inside&& inside, int restart, double& b1, double& b2) {
    const bool found = solve_2d(residual, 1.0, b1, b2);
    if (restart > 0 && (!found || !inside(b1, b2))) {
        // (First the point of the face nearest the one found outside, where one was.)
        double near1 = b1, near2 = b2;
        clamp_into_triangle(near1, near2);
        const double starts[10][2] = {{near1, near2}, {1.0 / 3.0, 1.0 / 3.0}, {0.1, 0.1}, {0.8, 0.1}, {0.1, 0.8},
                                      {0.45, 0.1}, {0.1, 0.45}, {0.45, 0.45}, {0.2, 0.6}, {0.6, 0.2}};
        for (int k = found ? 0 : 1; k <= restart; ++k) {
            double a = starts[k][0], b = starts[k][1];
            if (solve_2d(residual, 1.0, a, b) && inside(a, b)) {
                b1 = a, b2 = b;
                return true;
            }
        }
        return found;
    }
    return true;
}

// The point x of curved face cf (its barycentrics b1, b2; in: the guess) where the ray from the
// eye (a point, or parallel rays along `forward`) is turned to pass e. Beyond the face (CurvedFace::
// turn) rays may be turned to e at other points too: the solve restarts (solve_in_face) where it
// ends outside the face.
bool curved_point(const CurvedFace& cf, const Vec3d& eye, bool parallel, const Vec3d& forward, const Vec3d& e,
                  int restart, double& b1, double& b2, Vec3d& x) {
    auto follow = [&](double a, double b, Vec3d& r, Vec3d& p) {
        p = cf.v0 + cf.e1 * a + cf.e2 * b;
        Vec3d dir;
        return cf.turn(a, b, parallel ? forward : normalize(p - eye), dir) && towards(p, dir, e, r);
    };
    Vec3d r, p;
    if (!solve_in_face([&](double u, double v, Vec3d& res) { return follow(u, v, res, p); }, inside_triangle, restart,
                       b1, b2))
        return false;
    return follow(b1, b2, r, x);
}

// Two curved faces in a row: the camera ray meets the first, is turned there, meets the second,
// and is turned there (in at a glass ball's near side and out at its far side, or in a curved
// mirror seen in another). The film point through which the camera sees an edge point e is solved
// for on the first face's barycentrics, the second face's point being where the turned ray meets
// its plane. Its beam bounds the rays leaving the second face.
struct CurvedPair : Beam {
    CurvedFace face[2];  // (the second's `behind`: the rays from the first reach it from behind, by its winding)

    // From the first face's point at barycentrics (a, b), which the ray along d meets: the second
    // face's point x2 (its barycentrics c1, c2) and the direction `dir` leaving it. False where the
    // turned ray does not meet the second face's plane ahead or a lobe does not exist.
    bool follow(double a, double b, const Vec3d& d, Vec3d& x2, double& c1, double& c2, Vec3d& dir) const {
        const CurvedFace &f = face[0], &g = face[1];
        const Vec3d x1 = f.v0 + f.e1 * a + f.e2 * b;
        Vec3d mid;
        if (!f.turn(a, b, d, mid)) return false;
        const double t = dot(g.v0 - x1, g.ng) / dot(mid, g.ng);
        if (!(t > 0.0) || !std::isfinite(t)) return false;
        x2 = x1 + mid * t;
        return g.barycentrics(x2, c1, c2) && g.turn(c1, c2, mid, dir);
    }
};

// The point x of the pair's first face (its barycentrics b1, b2; in: the guess) where the ray from
// the eye (a point, or parallel rays along `forward`) is turned by both faces to pass e; (c1, c2):
// the barycentrics of the second face's point; `inside`: whether both faces' points lie in their
// faces (solve_in_face restarts where they do not).
bool pair_point(const CurvedPair& cp, const Vec3d& eye, bool parallel, const Vec3d& forward, const Vec3d& e,
                int restart, double& b1, double& b2, Vec3d& x, double& c1, double& c2, bool& inside) {
    const CurvedFace& f = cp.face[0];
    auto follow = [&](double a, double b, Vec3d& r) {
        const Vec3d p = f.v0 + f.e1 * a + f.e2 * b;
        Vec3d x2, dir;
        return cp.follow(a, b, parallel ? forward : normalize(p - eye), x2, c1, c2, dir) && towards(x2, dir, e, r);
    };
    auto both_inside = [&](double a, double b) {
        Vec3d r;
        return inside_triangle(a, b) && follow(a, b, r) && inside_triangle(c1, c2);
    };
    if (!solve_in_face(follow, both_inside, restart, b1, b2)) return false;
    x = f.v0 + f.e1 * b1 + f.e2 * b2;
    inside = both_inside(b1, b2);
    return true;
}

// The rays from the eye through a grid of a pair's first face's points (barycentrics in
// eighths), followed through both faces: where each leaves the second face, its direction, and
// whether that point lies in the second face (within a quarter of it); of the pair `pair` (-1:
// none yet).
struct PairRays {
    static constexpr int kGrid = 8;
    int pair = -1;
    Vec3d at[kGrid + 1][kGrid + 1], dir[kGrid + 1][kGrid + 1];
    bool valid[kGrid + 1][kGrid + 1] = {};
};

bool vertices_wanted(const SceneGradients& slots, int mesh) {
    return size_t(mesh) < slots.meshes.size() && slots.meshes[size_t(mesh)].vertices.wanted();
}

}  // namespace

bool primary_edges_wanted(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots) {
    if (!opt.primary_edges) return false;
    if (slots.camera.wanted()) return true;
    for (size_t i = 0; i < scene.meshes.size(); ++i)
        if (vertices_wanted(slots, int(i))) return true;
    // Curved mirrors' and glass's shading normals turn the edges seen in them (CurvedFace).
    for (size_t i = 0; i < scene.meshes.size(); ++i)
        if (i < slots.meshes.size() && slots.meshes[i].normals.wanted() && scene.meshes[i].normals &&
            smooth_lobe(scene.materials[size_t(scene.meshes[i].material)]))
            return true;
    // Glass's index bends the edges seen through it (Refraction).
    for (const SceneGradients::MaterialSlots& m : slots.materials)
        if (m.ior.wanted()) return true;
    return false;
}

void primary_edge_pass(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots,
                       const ChannelLayout& layout, const float* adjoint, float* out, int batch) {
    if (!(batch >= 1 && batch <= kPrimaryEdgeBatch))
        throw std::invalid_argument("primary_edge_pass: batch " + std::to_string(batch) + " is not in [1, " +
                                    std::to_string(kPrimaryEdgeBatch) + "]");
    if (!primary_edges_wanted(scene, opt, slots)) return;
    const Camera& cam = scene.camera;
    const bool camera_wanted = slots.camera.wanted();
    // The baseline: every edge, silhouette or not, by world length, points not stratified.
    const bool uniform = opt.edge_sampling == EdgeSampling::Uniform;
    // Fisheye and panorama: the film is a non-linear map of the direction from the camera's
    // position; edges are sampled in world space and each point mapped to the film.
    const bool spherical = is_spherical(cam.type);
    const int nv = layout.num_values;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    // The geometric normal jumps across every edge between faces at an angle, the barycentrics
    // across every edge.
    const bool smooth_edges_jump = layout.has(Channel::GeometryNormal) || layout.has(Channel::Barycentrics);

    // The film window whose pixels the filter reaches: the output, widened by the filter's
    // reach beyond a pixel.
    const double margin = double(scene.filter.radius()) - 0.5;
    const double wx0 = scene.crop_x - margin, wy0 = scene.crop_y - margin;
    const double wx1 = scene.crop_x + scene.out_width + margin, wy1 = scene.crop_y + scene.out_height + margin;

    // The eye the sides of an edge sample are found from (edges/sides.h): the camera, or per
    // sample a thin lens's point.
    EdgeEye camera_eye;
    camera_eye.origin = cam.position;
    camera_eye.parallel = cam.type == CameraType::Orthographic;
    camera_eye.dir = cam.forward;
    camera_eye.skip_emitters = opt.hide_emitters;
    // Each edge's part on the film and its sampling length, in parallel over chunks of the edge
    // list, summed after in the list's order (the same sums, whatever the thread count).
    const std::vector<Edge>& all_edges = scene.edges();
    // The share of the samples per unit film length given to a smooth edge that does not fold:
    // the angle between its faces over pi. Such an edge is a step only where the mesh shadows
    // itself along it, for the light arriving between the two faces' planes: a range of
    // directions as wide as that angle. (Any positive density is unbiased; this one puts the
    // samples where the steps are likely.)
    const Scene::EdgeMeasures& measures = scene.edge_measures();
    const std::vector<double>& smooth_weights = measures.smooth_weight;
    // An edge that does not fold, seen from behind both its faces on a mesh black from behind
    // (Scene::dark_behind), has black on both its sides: no step in the radiance, and no edge
    // sample there can add anything. Left out (before its projection) where radiance is all
    // the pass differentiates: the other channels (depth, normals, ...) are not black from behind.
    // (About half the edges of a closed mesh; their samples go to the edges that can step. A
    // thin lens's other eyes may see the faces from the front: none left out there.)
    std::vector<uint8_t> dark_behind(scene.meshes.size(), 0);
    if (!hit_values && cam.type != CameraType::ThinLens)
        for (size_t i = 0; i < scene.meshes.size(); ++i) dark_behind[i] = scene.dark_behind(scene.meshes[i]);
    // A smooth edge that does not fold separates two faces whose shading differs only where light
    // arrives between their planes (above): at one bounce without an environment, only from the
    // lights. One with every light in front of both its faces or behind both has no step either:
    // left out too (radiance only, not with a thin lens; up to 16 lights, whose test costs a
    // sixteenth of an edge's set-up each).
    const LightBoxes light_boxes(scene);
    const bool by_lights = !hit_values && cam.type != CameraType::ThinLens && opt.max_bounces <= 1 &&
                           !scene.has_envmap && light_boxes.center.size() <= 16;
    // Whether one of these two rules may apply to edge e, and whether one does, e not folding.
    auto may_leave_out = [&](const Edge& e) {
        return dark_behind[size_t(e.mesh)] || (by_lights && e.kind == EdgeKind::Smooth);
    };
    auto left_out = [&](const Mesh& m, const Edge& e) {
        return (dark_behind[size_t(e.mesh)] && seen_from_behind(camera_eye, m, e)) ||
               (by_lights && e.kind == EdgeKind::Smooth && !light_boxes.between(m, e));
    };
    // Edges seen in planar mirrors and through flat glass (SmoothPlanes, above): by a pinhole,
    // thin lens or orthographic camera, where the radiance is differentiated and paths scatter
    // at least once.
    const bool planes_seen = radiance && !uniform && opt.max_bounces >= 1 && !spherical;
    const SmoothPlanes smooth_planes = planes_seen ? SmoothPlanes(scene, cam, wx0, wy0, wx1, wy1) : SmoothPlanes();
    Eye centre;
    centre.position = cam.position;
    // The virtual edge of edge e of mesh m in mirror plane mp: its part on the camera's side of
    // the plane, mirrored, on the film within the plane's window.
    auto mirrored_film_edge = [&](const SmoothPlane& mp, const Mesh& m, const Edge& e, int64_t index, FilmEdge& fe) {
        if (!camera_wanted && !vertices_wanted(slots, e.mesh) && !vertices_wanted(slots, mp.mesh)) return false;
        Vec3f p0 = m.vertex(e.v0), p1 = m.vertex(e.v1);
        const float s0 = dot(p0 - mp.q, mp.n), s1 = dot(p1 - mp.q, mp.n);
        if (!(s0 > mp.tol || s1 > mp.tol)) return false;  // behind the mirror, or in its plane
        if (s0 < 0.f) p0 = p0 + (p1 - p0) * (s0 / (s0 - s1));
        if (s1 < 0.f) p1 = p1 + (p0 - p1) * (s1 / (s1 - s0));
        if (!project_edge(cam, mirrored(p0, mp.q, mp.n), mirrored(p1, mp.q, mp.n), mp.x0, mp.y0, mp.x1, mp.y1, fe))
            return false;
        const bool fold = cam.type == CameraType::ThinLens ? lens_may_fold(mp.lens, m, e) : is_fold(mp.eye, m, e);
        if (!fold && e.kind == EdgeKind::Smooth) {
            fe.weight = smooth_weights[size_t(index)];
            if (!(fe.weight > 0.0)) return false;
        }
        const double dx = fe.bx - fe.ax, dy = fe.by - fe.ay;
        fe.len = std::sqrt(dx * dx + dy * dy) * fe.weight;
        return fe.len > 0.0;
    };
    auto ior_wanted = [&](int material) {
        return size_t(material) < slots.materials.size() && slots.materials[size_t(material)].ior.wanted();
    };
    // The film point (fx, fy) through which `eye` sees point x of plane mp (parallel rays: the
    // camera's, whose direction is the forward axis).
    auto point_film = [&](const Eye& eye, const Vec3d& x, const Vec3f& n, double& fx, double& fy) {
        if (!has_eye(cam.type)) {
            const Vec3d qc = camera_axes(cam, Vec3f(x) - cam.position);
            fx = film_x(cam, qc.x);
            fy = film_y(cam, qc.y);
            return std::isfinite(fx) && std::isfinite(fy);
        }
        double jacobian;
        return film_point(cam, eye, Vec3f(x), n, fx, fy, jacobian);
    };
    // The film point (fx, fy) that `eye` sees point e (on the far side of refracting plane mp)
    // at: through the plane's refraction point (a pinhole, a lens point), or for parallel rays
    // along their refracted direction.
    auto refracted_film = [&](const SmoothPlane& mp, const Eye& eye, const Vec3d& e, double& fx, double& fy) {
        const Vec3d q(mp.q), n(mp.n);
        Vec3d x;
        if (!has_eye(cam.type)) {
            Vec3d r;
            if (!refracted_direction(Vec3d(cam.forward), n, mp.eta, r)) return false;
            x = e - r * (dot(e - q, n) / dot(r, n));
        } else if (!refraction_point(Vec3d(eye.position), e, q, n, mp.eta, x)) {
            return false;
        }
        return point_film(eye, x, mp.n, fx, fy);
    };
    // The sides of plane `of` (by its winding) that the box of plane p's faces reaches: bit 0
    // its front, bit 1 its back.
    auto sides_reached = [](const SmoothPlane& p, const SmoothPlane& of) {
        int sides = 0;
        for (int k = 0; k < 4; ++k) {
            const double h = dot(p.corner(k) - Vec3d(of.q), of.winding_n);
            sides |= (h > double(of.tol) ? 1 : 0) | (h < -double(of.tol) ? 2 : 0);
        }
        return sides;
    };
    // Runs work(j, slot) for j = 0, 1, ... up to `count` in parallel, `per_block` at a time (slot:
    // j's place in its block), then accept(j, slot) for each of the block in order, while open()
    // holds: what is accepted does not depend on the threads.
    auto in_blocks = [&](size_t count, size_t per_block, auto&& open, auto&& work, auto&& accept) {
        for (size_t begin = 0; begin < count && open(); begin += per_block) {
            const size_t block = std::min(per_block, count - begin);
            parallel_indices(opt, int64_t(block), [&](int64_t j) { work(begin + size_t(j), size_t(j)); });
            for (size_t j = 0; j < block && open(); ++j) accept(begin + j, j);
        }
    };
    // Of `count` candidates (chains, curved faces or pairs of them) in rank order, keeps the best
    // ranked first (keep(j) adds candidate j to its list), each with the edge set-ups find(j,
    // found) finds for it (it returns the number of edges it tested), added to `setups` (empty
    // before) with their candidate's place in that list, until the set-ups or the tests reach
    // their limits (found in parallel, a block of candidates at a time).
    auto keep_seen = [&](size_t count, auto&& find, double max_setups, double max_tests, std::vector<ViaSetup>& setups,
                         auto&& keep) {
        // (A candidate without a beam finds every edge: a block holds at most 64 candidates and
        // room for about 2^20 set-ups, or four. Which are kept does not depend on it.)
        const size_t per_block =
            std::clamp((size_t(1) << 20) / std::max<size_t>(all_edges.size(), 1), size_t(4), size_t(64));
        double tests = 0.0;
        int32_t kept = 0;
        std::vector<std::vector<ViaSetup>> found(per_block);
        std::vector<double> tested(per_block);
        in_blocks(
            count, per_block, [&] { return double(setups.size()) < max_setups && tests < max_tests; },
            [&](size_t j, size_t slot) {
                found[slot].clear();
                tested[slot] = find(j, found[slot]);
            },
            [&](size_t j, size_t slot) {
                tests += tested[slot];
                if (found[slot].empty()) return;
                for (ViaSetup setup : found[slot]) {
                    setup.via = kept;
                    setups.push_back(setup);
                }
                ++kept;
                keep(j);
            });
    };
    // The probability a chain or a curved face keeps its set-up of edge `index`, `from` (the
    // centre of a ball of that radius) where the rays leaving it start (a chain's ball of
    // origins, a curved face's centre; for parallel rays through a chain, their direction): 1 for
    // an edge that is not smooth, or folds seen from the ball's centre. A smooth edge that does
    // not (its faces seen from one side: its shading steps only where the mesh shadows itself
    // along it) is kept with the share of samples the direct edges give it (its weight: the
    // angle between its faces over pi) plus, for each face, the share of a disc of the ball's
    // radius beyond a line as far from its centre as the face's plane (an estimate of the share
    // of the ball it folds from, where it steps fully: without it, the smooth bunny behind a
    // glass cube's derivative had 3 times the standard error), drawn once per call, chain or
    // face and edge (`keeps`; `salt` sets chains' draws apart from faces'); its samples count the
    // inverse. (Inside a smooth glass ball every edge seen through its faces is such an edge; so
    // are most of a smooth-shaded scan's seen through a glass box. Creases step by their faces'
    // shading wherever they are seen: drawn so, they gave the derivative of a lit faceted ball
    // seen through a glass cube 36 times the standard error.)
    const uint64_t keep_seed = mix64(opt.seed ^ 0x6b65657065646765ull);
    auto keep_probability = [&](const EdgeEye& from, double radius, const Edge& e, int32_t index) {
        const Mesh& m = scene.meshes[size_t(e.mesh)];
        if (e.kind != EdgeKind::Smooth || is_fold(from, m, e)) return 1.0;
        double p = smooth_weights[size_t(index)];
        if (!from.parallel && radius > 0.0) {
            const Vec3d to = Vec3d(from.origin) - Vec3d(m.vertex(e.v0));
            for (const int64_t f : {e.f0, e.f1}) {
                const double x = std::min(1.0, std::abs(dot(to, Vec3d(m.triangle_data[f].ng))) / radius);
                p += (std::acos(x) - x * std::sqrt(1.0 - x * x)) / kPi;
            }
        }
        return std::min(1.0, p);
    };
    auto keeps = [&](uint64_t salt, size_t rank, int32_t index, double probability) {
        if (probability >= 1.0) return true;
        const uint64_t key = uint64_t(uint32_t(rank)) << 32 | uint32_t(index);
        return double(mix64(keep_seed ^ salt ^ mix64(key)) >> 11) * 0x1p-53 < probability;
    };
    // The tree of the scene's edges' balls, for the beams of chains and curved faces: built when
    // first needed (empty till then).
    BallTree balls_built;
    bool have_balls = false;
    auto edge_balls = [&](bool needed) -> const BallTree& {
        if (needed && !have_balls) balls_built = edge_balls_of(scene), have_balls = true;
        return balls_built;
    };
    // Chains of two planes (Chain, above): where the paths scatter at least twice, every ordered
    // pair of planes and each lobe of each (a refraction only where the plane refracts) whose
    // second plane has faces on the side of the first the first lobe sends rays to, and whose
    // first plane has faces on the side of a one-sided second plane's front. The chains whose
    // rays most likely meet their planes' faces first, each with the edges its beam may see,
    // up to kChainSetups edge set-ups (below).
    std::vector<Chain> chains;
    std::vector<ViaSetup> chain_setups;
    if (planes_seen && opt.max_bounces >= 2) {
        const std::vector<SmoothPlane>& planes = smooth_planes.planes;
        // The share of the rays from the camera through plane a's faces, turned there
        // (`refract`), that may meet plane b's faces: where they meet b's plane, the box of the
        // rays through the corners of a's faces' box (widened by a quarter, for a refraction's
        // bending), the part of it within b's faces' box. (Exact but for the widening: a
        // reflection's rays come from one point, and parallel rays refract into one direction;
        // a thin lens's from its centre, which ranks its chains.) All with a corner behind the
        // camera, a thousandth (any, but unlikely) where a corner's ray is not turned (total
        // internal reflection) or does not reach the plane.
        const Vec3d eye(cam.position), forward(cam.forward);
        const bool parallel = !has_eye(cam.type);
        // The bounds of a chain's beam (Chain::may_see): the four rays from the camera through
        // the corners of its first plane's faces' box (with a thin lens, from its centre and
        // from eight points of its aperture's rim: its rays through a corner spread between
        // those), followed through both planes; the cone of their directions, widened by a
        // quarter (the rays between the corners' bend), from the ball of their origins (below).
        // None where a corner's ray misses a plane. (Without the lens's bound, a glass cube's
        // chains each set up every edge of a scan behind it, the budget took the first few,
        // which saw nothing of it, and its derivative seen through the cube was 0.)
        const int num_eyes = cam.type == CameraType::ThinLens ? 9 : 1;
        Vec3d eyes[9];
        eyes[0] = eye;
        for (int k = 1; k < num_eyes; ++k) {
            const double t = 0.25 * kPi * double(k - 1);
            eyes[k] = eye + (Vec3d(cam.right) * std::cos(t) + Vec3d(cam.up) * std::sin(t)) * double(cam.aperture);
        }
        auto bound_beam = [&](Chain& ch) {
            const SmoothPlane& a = planes[size_t(ch.plane[0])];
            Vec3d o[36], d[36];
            int n = 0;
            const double back = std::abs(a.hi[0] - a.lo[0]) + std::abs(a.hi[1] - a.lo[1]);
            for (int k = 0; k < 4; ++k) {
                const Vec3d c = a.corner(k);
                for (int j = 0; j < num_eyes; ++j, ++n) {
                    if (!parallel && !(dot(c - eyes[j], forward) > 0.0)) return;
                    const Vec3d from = parallel ? c - forward * (back > 0.0 ? back : 1.0) : eyes[j];
                    Vec3d x1;
                    if (!follow_chain(planes, ch, from, parallel ? forward : normalize(c - eyes[j]), x1, o[n], d[n]))
                        return;
                    d[n] = normalize(d[n]);
                }
            }
            // The origins lie on the second plane's faces too: their box (widened) within those
            // faces' box, in the second plane's axes.
            const SmoothPlane& b = planes[size_t(ch.plane[1])];
            double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
            for (int j = 0; j < n; ++j) {
                const Vec3d l = b.axes.to_local(o[j] - Vec3d(b.q));
                lo[0] = std::min(lo[0], l.x), hi[0] = std::max(hi[0], l.x);
                lo[1] = std::min(lo[1], l.y), hi[1] = std::max(hi[1], l.y);
            }
            for (int j = 0; j < 2; ++j) {
                const double w = 0.125 * (hi[j] - lo[j]);
                lo[j] = std::max(lo[j] - w, b.lo[j]), hi[j] = std::min(hi[j] + w, b.hi[j]);
                if (!(lo[j] <= hi[j])) lo[j] = b.lo[j], hi[j] = b.hi[j];
            }
            ch.origin = Vec3d(b.q) + b.axes.s * (0.5 * (lo[0] + hi[0])) + b.axes.t * (0.5 * (lo[1] + hi[1]));
            ch.origin_radius = 0.5 * std::hypot(hi[0] - lo[0], hi[1] - lo[1]) * (1.0 + 1e-6);
            ch.bounded = ch.bound_directions(d, n, 1.25, 0.0) && std::isfinite(ch.origin_radius);
        };
        constexpr double kUnlikely = 1e-3;
        auto beam_share = [&](const SmoothPlane& a, bool refract, const SmoothPlane& b) {
            double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
            for (int k = 0; k < 4; ++k) {
                const Vec3d c = a.corner(k);
                // (A corner behind the camera: its rays through a's faces reach any way.)
                if (!parallel && !(dot(c - eye, forward) > 0.0)) return 1.0;
                const Vec3d d = parallel ? forward : normalize(c - eye);
                Vec3d dir, weight;
                if (!delta_scatter(a.delta, a.winding_n, -d, refract, 1.0, dir, weight)) return kUnlikely;
                // (A corner's ray that does not reach b's plane: the beam may meet b's faces where
                // it turns towards them, unlikely: ranked below the shares found.)
                const double t = dot(Vec3d(b.q) - c, b.winding_n) / dot(dir, b.winding_n);
                if (!(t > 0.0) || !std::isfinite(t)) return kUnlikely;
                const Vec3d l = b.axes.to_local(c + dir * t - Vec3d(b.q));
                lo[0] = std::min(lo[0], l.x), hi[0] = std::max(hi[0], l.x);
                lo[1] = std::min(lo[1], l.y), hi[1] = std::max(hi[1], l.y);
            }
            double area = 1.0, within = 1.0;
            for (int k = 0; k < 2; ++k) {
                const double w = 0.25 * (hi[k] - lo[k]) + 1e-9 * (std::abs(b.hi[k]) + std::abs(b.lo[k]));
                lo[k] -= w, hi[k] += w;
                area *= hi[k] - lo[k];
                within *= std::max(0.0, std::min(hi[k], b.hi[k]) - std::max(lo[k], b.lo[k]));
            }
            return area > 0.0 ? within / area : 1.0;
        };
        // The candidates, by the film area of their first plane's window times that share, and
        // a thousandth of that where the camera sees the first plane's faces from behind (inside
        // a closed mesh, others hide them: as SmoothPlanes orders them).
        std::vector<std::pair<double, Chain>> candidates;
        for (size_t p1 = 0; p1 < planes.size(); ++p1)
            for (size_t p2 = 0; p2 < planes.size(); ++p2) {
                if (p1 == p2) continue;
                const SmoothPlane &a = planes[p1], &b = planes[p2];
                // Reflected rays stay on the camera's side of the first plane (its front as the
                // camera sees it: mp.n), refracted ones cross it.
                const int reach = sides_reached(b, a);
                const int camera_side = a.behind ? 2 : 1;
                const bool one_sided = !b.delta.dielectric && !b.delta.two_sided;
                if (one_sided && !(sides_reached(a, b) & 1)) continue;
                const double film_area = (a.x1 - a.x0) * (a.y1 - a.y0) * (a.behind ? kUnlikely : 1.0);
                for (int r1 = 0; r1 < (a.refracts ? 2 : 1); ++r1) {
                    if (!(reach & (r1 ? 3 - camera_side : camera_side))) continue;
                    const double share = beam_share(a, r1 == 1, b);
                    if (!(share > 0.0)) continue;
                    for (int r2 = 0; r2 < (b.refracts ? 2 : 1); ++r2) {
                        Chain ch;
                        ch.plane[0] = int(p1), ch.plane[1] = int(p2);
                        ch.refract[0] = r1 == 1, ch.refract[1] = r2 == 1;
                        bound_beam(ch);
                        candidates.push_back({film_area * share, ch});
                    }
                }
            }
        std::stable_sort(candidates.begin(), candidates.end(),
                         [](const auto& x, const auto& y) { return x.first > y.first; });
        // (Found in the tree of the edges' balls; each chain's in the edges' order. Kept by
        // keep_probability seen from its beam's origin, or without a beam from the middle of its
        // second plane's faces' box; parallel rays without a beam keep every edge.)
        const BallTree& balls = edge_balls(!candidates.empty());
        constexpr uint64_t kChainSalt = 0x636861696e73ull;
        auto find = [&](size_t j, std::vector<ViaSetup>& found) {
            const Chain& ch = candidates[j].second;
            const SmoothPlane& b = planes[size_t(ch.plane[1])];
            EdgeEye from;
            from.origin = Vec3f(ch.bounded ? ch.origin : (b.corner(0) + b.corner(3)) * 0.5);
            const double radius = ch.bounded ? ch.origin_radius : 0.5 * length(b.corner(3) - b.corner(0));
            from.parallel = parallel;
            from.dir = Vec3f(ch.axis);
            const bool roulette = ch.bounded || !parallel;
            double visited = 0.0;
            balls.visit(ch, [&](int32_t index) {
                ++visited;
                ViaSetup setup;
                setup.edge = index;
                if (roulette) setup.kept = keep_probability(from, radius, all_edges[size_t(index)], index);
                if (keeps(kChainSalt, j, index, setup.kept)) found.push_back(setup);
            });
            std::sort(found.begin(), found.end(), [](const ViaSetup& a, const ViaSetup& b) { return a.edge < b.edge; });
            return visited;
        };
        keep_seen(candidates.size(), find, kChainSetups, kChainTests, chain_setups,
                  [&](size_t j) { chains.push_back(candidates[j].second); });
    }
    // Curved faces (CurvedFace, above), where paths scatter at least once: each face of a mesh
    // with shading normals and a smooth lobe that the camera may see from a side the lobe turns
    // rays from (a one-sided mirror's front), with each lobe, those covering the most film first
    // (faces seen from behind count a thousandth: inside a closed mesh others hide them), each
    // with the edges its beam may see, up to kCurvedSetups set-ups.
    std::vector<CurvedFace> curved;
    std::vector<ViaSetup> curved_setups;
    std::vector<Solid> solids;
    std::vector<CurvedPair> pairs;
    std::vector<ViaSetup> pair_setups;
    if (planes_seen) {
        const Vec3d eye(cam.position), forward(cam.forward);
        const bool parallel = !has_eye(cam.type), lens = cam.type == CameraType::ThinLens;
        // Every face of a mesh with shading normals and a smooth lobe (its lobe a reflection, its
        // side unset), and of its material whether only its front turns rays (a one-sided
        // mirror's or coating's) and whether it refracts (glass of one index).
        // (Each with the solid its mesh bounds where the mesh is closed.)
        std::vector<CurvedFace> faces;
        for (size_t i = 0; i < scene.meshes.size(); ++i) {
            const Mesh& m = scene.meshes[i];
            if (!m.normals || !smooth_lobe(scene.materials[size_t(m.material)])) continue;
            MeshDesc desc;
            desc.vertices = m.vertices, desc.num_vertices = m.num_vertices;
            desc.indices = m.indices, desc.num_triangles = m.num_triangles;
            std::vector<int32_t> solid_of;
            if (!mesh_solids(desc, int32_t(i), all_edges, solids, solid_of)) solid_of.clear();
            for (int64_t f = 0; f < m.num_triangles; ++f)
                if (!m.is_degenerate(f)) {
                    faces.emplace_back(scene, int(i), f);
                    if (!solid_of.empty()) faces.back().solid = solid_of[size_t(f)];
                }
        }
        auto material_of = [&](const CurvedFace& cf) -> const Material& {
            return scene.materials[size_t(scene.meshes[size_t(cf.mesh)].material)];
        };
        auto front_only = [&](const CurvedFace& cf) {
            const Material& mat = material_of(cf);
            return mat.kind != MaterialKind::Dielectric && !mat.two_sided;
        };
        auto refracts = [&](const CurvedFace& cf) {
            const Material& mat = material_of(cf);
            return mat.kind == MaterialKind::Dielectric && mat.ior.is_constant();
        };
        std::vector<CurvedFace> candidates;
        for (const CurvedFace& face : faces) {
            CurvedFace cf = face;
            const Vec3d v[3] = {cf.v0, cf.v0 + cf.e1, cf.v0 + cf.e2};
            const double side = parallel ? -dot(cf.ng, forward) : dot(cf.ng, eye - v[0]);
            if ((front_only(cf) && !(side > 0.0)) || !(side != 0.0)) continue;
            cf.behind = side < 0.0;
            // The film box its corners span (the whole window where one reaches behind the
            // camera, or with a thin lens), within the window.
            double x0 = wx0, y0 = wy0, x1 = wx1, y1 = wy1;
            bool whole = lens;
            for (int c = 0; c < 3 && !whole; ++c)
                whole = !parallel && !(camera_axes(cam, Vec3f(v[c]) - cam.position).z > 1e-6 * length(v[c] - eye));
            if (!whole) {
                x0 = y0 = std::numeric_limits<double>::infinity(), x1 = y1 = -x0;
                for (int c = 0; c < 3; ++c) {
                    const Vec3d qc = camera_axes(cam, Vec3f(v[c]) - cam.position);
                    const double x = film_x(cam, parallel ? qc.x : qc.x / qc.z);
                    const double y = film_y(cam, parallel ? qc.y : qc.y / qc.z);
                    x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
                }
                x0 = std::max(x0 - 1.0, wx0), y0 = std::max(y0 - 1.0, wy0);
                x1 = std::min(x1 + 1.0, wx1), y1 = std::min(y1 + 1.0, wy1);
                if (!(x0 < x1 && y0 < y1)) continue;
            }
            cf.film_area = (x1 - x0) * (y1 - y0) * (cf.behind ? 1e-3 : 1.0);
            const Vec3d centre = (v[0] + v[1] + v[2]) / 3.0;
            for (int r = 0; r < (refracts(cf) ? 2 : 1); ++r) {
                CurvedFace lobe = cf;
                lobe.refract = r == 1;
                Vec3d d[3];
                // A thin lens's points see the face from directions within the angle its
                // aperture subtends there (from the camera's position: the cone's axis); a
                // reflection, or a refraction into the denser side, turns them apart by no
                // more (into the thinner side it may spread them: no bound).
                bool bounded = true;
                double extra = 1e-6;
                if (lens) {
                    double nearest = std::numeric_limits<double>::infinity();
                    for (int c = 0; c < 3; ++c) nearest = std::min(nearest, length(v[c] - eye));
                    const double eta = cf.behind ? 1.0 / lobe.delta.eta : lobe.delta.eta;
                    bounded = !(lobe.refract && eta < 1.0) && nearest > double(cam.aperture);
                    if (bounded) extra += std::asin(double(cam.aperture) / nearest);
                }
                for (int c = 0; c < 3 && bounded; ++c) {
                    const Vec3d to = v[c] - eye;
                    bounded = (parallel || dot(to, forward) > 0.0) &&
                              lobe.turn(c == 1 ? 1.0 : 0.0, c == 2 ? 1.0 : 0.0, parallel ? forward : normalize(to), d[c]);
                    d[c] = normalize(d[c]);
                    lobe.origin_radius = std::max(lobe.origin_radius, length(v[c] - centre) * (1.0 + 1e-6));
                }
                lobe.origin = centre;
                lobe.bounded = bounded && lobe.bound_directions(d, 3, 1.25, extra) && std::isfinite(lobe.origin_radius);
                // (Without a beam it tests every edge: after those with one.)
                if (!lobe.bounded) lobe.film_area *= 1e-3;
                candidates.push_back(lobe);
            }
        }
        std::stable_sort(candidates.begin(), candidates.end(),
                         [](const CurvedFace& a, const CurvedFace& b) { return a.film_area > b.film_area; });
        // The best ranked first, each with the edges its beam may see on the side its lobe
        // sends rays to (found in a tree of the edges' balls), until those reach kCurvedSetups.
        const BallTree& balls = edge_balls(!candidates.empty());
        // Per mesh, whether its material reads a texture, or its emission one (by the uvs: a
        // seam of uvs alone steps nowhere on a mesh that reads none).
        std::vector<bool> reads_uvs(scene.meshes.size());
        for (size_t i = 0; i < scene.meshes.size(); ++i) {
            const Mesh& m = scene.meshes[i];
            const Material& mat = scene.materials[size_t(m.material)];
            auto textured = [](const Texture& t) { return !t.empty() && !t.is_constant(); };
            reads_uvs[i] = textured(mat.diffuse) || textured(mat.specular) || textured(mat.roughness) ||
                           textured(mat.ior) || !mat.normal_map.empty() || textured(m.emission);
        }
        // The edges beam `beam` may see with a part on the side of face `last` its lobe sends
        // rays to (the candidate `j`'s, drawn with `salt`), each kept by keep_probability from
        // the face's centre alone (its ball is small, and with its radius the glass ball of
        // test_specular's index recovery kept twice the set-ups); returns the edges tested.
        auto find_beyond = [&](const Beam& beam, const CurvedFace& last, uint64_t salt, size_t j,
                               std::vector<ViaSetup>& found) {
            EdgeEye from;
            from.origin = Vec3f(last.centre());
            double visited = 0.0;
            balls.visit(beam, [&](int32_t index) {
                ++visited;
                const Edge& e = all_edges[size_t(index)];
                const Mesh& m = scene.meshes[size_t(e.mesh)];
                ViaSetup setup;
                setup.edge = index;
                const Vec3d p0(m.vertex(e.v0)), p1(m.vertex(e.v1));
                if (!last.out_side(p0, p1, setup.u0, setup.u1)) return;
                if (last.solid >= 0 && last.out_sign() == solids[size_t(last.solid)].side) {
                    // (Into its solid: an edge wholly outside the solid's box is hidden.)
                    const Solid& sd = solids[size_t(last.solid)];
                    const double tol = 1e-6 * length(sd.hi - sd.lo);
                    const Vec3d lo = min(p0, p1), hi = max(p0, p1);
                    if (lo.x > sd.hi.x + tol || lo.y > sd.hi.y + tol || lo.z > sd.hi.z + tol ||
                        hi.x < sd.lo.x - tol || hi.y < sd.lo.y - tol || hi.z < sd.lo.z - tol)
                        return;
                }
                if ((e.kind == EdgeKind::Smooth || (e.uv_only && !reads_uvs[size_t(e.mesh)])) &&
                    !last.may_fold(p0, Vec3d(m.unit_face_normal(e.f0)), Vec3d(m.unit_face_normal(e.f1))))
                    return;
                setup.kept = keep_probability(from, 0.0, e, index);
                if (keeps(salt, j, index, setup.kept)) found.push_back(setup);
            });
            return visited;
        };
        auto find = [&](size_t j, std::vector<ViaSetup>& found) {
            return find_beyond(candidates[j], candidates[j], 0, j, found);
        };
        keep_seen(candidates.size(), find, kCurvedSetups, kCurvedTests, curved_setups,
                  [&](size_t j) { curved.push_back(candidates[j]); });
        // Pairs of curved faces (CurvedPair), where the paths scatter at least twice, seen by a
        // pinhole or parallel rays (a thin lens's rays through a face spread, and through a
        // second no bound of them is known): each face above, taken in their order, with each
        // curved face that rays through it meet (traced, with the faces beside those they meet
        // first: below), with each of that face's lobes, until the faces tested reach
        // kPairTests. The pairs whose rank is highest first, each with the edges its beam may see
        // on the side its second lobe sends rays to, up to kPairSetups set-ups.
        if (opt.max_bounces >= 2 && !lens && !candidates.empty()) {
            // Each curved face's place in `faces` (-1: none), by mesh and triangle, and its
            // neighbours there (sharing an edge; in `neighbours` from first[f] to first[f + 1]).
            std::vector<std::vector<int32_t>> face_at(scene.meshes.size());
            for (size_t f = 0; f < faces.size(); ++f) {
                std::vector<int32_t>& at = face_at[size_t(faces[f].mesh)];
                if (at.empty()) at.assign(size_t(scene.meshes[size_t(faces[f].mesh)].num_triangles), -1);
                at[size_t(faces[f].prim)] = int32_t(f);
            }
            auto face_index = [&](int mesh, int64_t prim) {
                const std::vector<int32_t>& at = face_at[size_t(mesh)];
                return at.empty() || prim < 0 ? int32_t(-1) : at[size_t(prim)];
            };
            std::vector<int32_t> first_neighbour(faces.size() + 1, 0), neighbours;
            {
                std::vector<std::pair<int32_t, int32_t>> links;
                for (const Edge& e : all_edges) {
                    if (e.f1 < 0 || face_at[size_t(e.mesh)].empty()) continue;
                    const int32_t a = face_index(e.mesh, e.f0), b = face_index(e.mesh, e.f1);
                    if (a < 0 || b < 0) continue;
                    links.emplace_back(a, b);
                    links.emplace_back(b, a);
                }
                for (const auto& [a, b] : links) ++first_neighbour[size_t(a) + 1];
                for (size_t f = 0; f < faces.size(); ++f) first_neighbour[f + 1] += first_neighbour[f];
                neighbours.resize(links.size());
                std::vector<int32_t> next(first_neighbour.begin(), first_neighbour.end() - 1);
                for (const auto& [a, b] : links) neighbours[size_t(next[size_t(a)]++)] = b;
            }
            // A candidate pair: the first face (in `candidates`), the second (in `faces`) with its
            // lobe and side, its beam and rank (the faces themselves copied for those kept only).
            struct PairChoice : Beam {
                int32_t first = -1, second = -1;
                bool refract = false, behind = false;
                double rank = 0.0;
            };
            auto second_face = [&](const PairChoice& pc) {
                CurvedFace g = faces[size_t(pc.second)];
                g.refract = pc.refract;
                g.behind = pc.behind;
                return g;
            };
            std::vector<PairChoice> pair_candidates;
            double tested = 0.0;
            // A grid of the first face's points (barycentrics i / kRayGrid, j / kRayGrid): the rays
            // from the eye through them, turned there. A second face is paired with it where
            // some of these meet its plane inside it (or within a quarter of it); the pair's beam
            // holds those rays turned by the second face, from the ball of the points they meet
            // it at (widened by two grid steps), in their cone widened by a half and 0.05 rad (the
            // rays between them); its rank is the first face's film area times the share of the
            // grid's rays that meet the second face and both lobes' weights. (A ray reflected
            // wholly there: the rays refracted near it leave along the face, in the limit along
            // its part in the tangent plane.)
            constexpr int kRayGrid = 4, kRays = (kRayGrid + 1) * (kRayGrid + 2) / 2;
            // (The first faces' pairs found in parallel, a block at a time, and kept in order
            // until the faces tested reach kPairTests.)
            auto choose = [&](size_t first_index, std::vector<PairChoice>& out) {
                double visits = 0.0;
                const CurvedFace& first = candidates[first_index];
                Vec3d x1[kRays], mid[kRays];
                double lobe1[kRays];
                bool turned[kRays];
                int num_turned = 0;
                for (int i = 0, k = 0; i <= kRayGrid; ++i)
                    for (int j = 0; i + j <= kRayGrid; ++j, ++k) {
                        const double b1 = double(i) / kRayGrid, b2 = double(j) / kRayGrid;
                        x1[k] = first.v0 + first.e1 * b1 + first.e2 * b2;
                        turned[k] = (parallel || dot(x1[k] - eye, forward) > 0.0) &&
                                    first.turn(b1, b2, parallel ? forward : normalize(x1[k] - eye), mid[k], &lobe1[k]);
                        if (turned[k]) mid[k] = normalize(mid[k]), ++num_turned;
                    }
                if (num_turned == 0) return 0.0;
                // The curved faces the grid's rays meet first (beyond a thousandth of the first
                // face's size: not the first face's neighbours from its own border), and their
                // neighbours (those the rays between them may meet): the second faces tested.
                const double near_t = 1e-3 * (length(first.e1) + length(first.e2));
                int32_t tests[4 * kRays];
                int num_tests = 0;
                auto test = [&](int32_t id) {
                    if (id >= 0 && std::find(tests, tests + num_tests, id) == tests + num_tests)
                        tests[num_tests++] = id;
                };
                for (int k = 0; k < kRays; ++k) {
                    if (!turned[k]) continue;
                    Ray ray;
                    ray.origin = Vec3f(x1[k]);
                    ray.dir = Vec3f(mid[k]);
                    ray.tmin = float(near_t);
                    Hit hit;
                    if (scene.intersect_excluding(ray, first.mesh, first.prim, -1, hit))
                        test(face_index(hit.mesh, hit.prim));
                }
                for (int h = 0, hits = num_tests; h < hits; ++h)
                    for (int32_t n = first_neighbour[size_t(tests[h])]; n < first_neighbour[size_t(tests[h]) + 1] &&
                                                                         num_tests < 4 * kRays; ++n)
                        test(neighbours[size_t(n)]);
                for (int h = 0; h < num_tests; ++h) {
                    const int32_t id = tests[h];
                    ++visits;
                    const CurvedFace& g = faces[size_t(id)];
                    if (g.mesh == first.mesh && g.prim == first.prim) continue;
                    // The grid's rays that meet the second face (within a quarter of it).
                    constexpr double kNear = 0.25;
                    int met[kRays], num_met = 0;
                    Vec3d at[kRays];
                    double c1[kRays], c2[kRays];
                    for (int k = 0; k < kRays; ++k) {
                        if (!turned[k]) continue;
                        // (Not from the first face's own border: a ray leaving it where it meets
                        // the second face there meets that face nowhere else.)
                        const double t = dot(g.v0 - x1[k], g.ng) / dot(mid[k], g.ng);
                        if (!(t > near_t) || !std::isfinite(t)) continue;
                        at[k] = x1[k] + mid[k] * t;
                        if (!g.barycentrics(at[k], c1[k], c2[k]) || c1[k] < -kNear || c2[k] < -kNear ||
                            c1[k] + c2[k] > 1.0 + kNear)
                            continue;
                        // (From the second face's front only, for a one-sided mirror.)
                        if (front_only(g) && !(dot(mid[k], g.ng) < 0.0)) continue;
                        met[num_met++] = k;
                    }
                    if (num_met == 0) continue;
                    const double step = std::max(length(first.e1), length(first.e2)) / kRayGrid;
                    for (int r = 0; r < (refracts(g) ? 2 : 1); ++r) {
                        PairChoice cp;
                        cp.first = int32_t(first_index);
                        cp.second = id;
                        cp.behind = dot(mid[met[0]], g.ng) > 0.0;
                        cp.refract = r == 1;
                        const CurvedFace second = second_face(cp);
                        Vec3d dirs[kRays], centre_at(0.0);
                        double lobe = 0.0;
                        bool ok = true;
                        for (int q = 0; q < num_met && ok; ++q) {
                            const int k = met[q];
                            double lobe2 = 0.0;
                            if (second.turn(c1[k], c2[k], mid[k], dirs[q], &lobe2)) {
                                dirs[q] = normalize(dirs[q]);
                            } else {
                                const Vec3d n = g.shading_normal(c1[k], c2[k]);
                                dirs[q] = normalize(mid[k] - n * dot(mid[k], n));
                                ok = cp.refract && std::isfinite(dirs[q].x);
                            }
                            lobe += lobe1[k] * lobe2;
                            centre_at = centre_at + at[k];
                        }
                        if (!ok) continue;
                        cp.origin = centre_at / double(num_met);
                        for (int q = 0; q < num_met; ++q)
                            cp.origin_radius = std::max(cp.origin_radius, length(at[met[q]] - cp.origin));
                        cp.origin_radius = (cp.origin_radius + 2.0 * step) * (1.0 + 1e-6);
                        cp.bounded = cp.bound_directions(dirs, num_met, 1.5, 0.05) && std::isfinite(cp.origin_radius);
                        // (Without a beam it tests every edge: after those with one.)
                        cp.rank = first.film_area * lobe / double(num_turned) * (cp.bounded ? 1.0 : 1e-3);
                        out.push_back(cp);
                    }
                }
                return visits;
            };
            constexpr size_t kChooseBlock = 64;
            std::vector<std::vector<PairChoice>> chosen(kChooseBlock);
            std::vector<double> visits(kChooseBlock);
            in_blocks(
                candidates.size(), kChooseBlock, [&] { return tested < kPairTests; },
                [&](size_t j, size_t slot) {
                    chosen[slot].clear();
                    visits[slot] = choose(j, chosen[slot]);
                },
                [&](size_t, size_t slot) {
                    tested += visits[slot];
                    pair_candidates.insert(pair_candidates.end(), chosen[slot].begin(), chosen[slot].end());
                });
            std::stable_sort(pair_candidates.begin(), pair_candidates.end(),
                             [](const PairChoice& a, const PairChoice& b) { return a.rank > b.rank; });
            constexpr uint64_t kPairSalt = 0x7061697273ull;
            auto find_seen = [&](size_t j, std::vector<ViaSetup>& found) {
                return find_beyond(pair_candidates[j], second_face(pair_candidates[j]), kPairSalt, j, found);
            };
            keep_seen(pair_candidates.size(), find_seen, kPairSetups, kPairTests, pair_setups, [&](size_t j) {
                const PairChoice& pc = pair_candidates[j];
                CurvedPair cp;
                static_cast<Beam&>(cp) = pc;
                cp.face[0] = candidates[size_t(pc.first)];
                cp.face[1] = second_face(pc);
                pairs.push_back(cp);
            });
        }
    }
    // The film point that `eye` sees point e at through chain ch; x1 (in: a guess where `guessed`)
    // and x2 its planes' points.
    auto chain_film = [&](const Chain& ch, const Eye& eye, const Vec3d& e, bool guessed, Vec3d& x1, Vec3d& x2,
                          double& fx, double& fy) {
        const bool parallel = !has_eye(cam.type);
        const Vec3d from(eye.position), forward(cam.forward);
        if (!guessed) x1 = chain_guess(smooth_planes.planes, ch, from, parallel, forward, e);
        return chain_point(smooth_planes.planes, ch, from, parallel, forward, e, x1, x2) &&
               point_film(eye, x1, smooth_planes.planes[size_t(ch.plane[0])].n, fx, fy);
    };
    // Whether the refraction points of the segment (e0, e1) beyond plane mp (from the camera's
    // position, or from any point of a thin lens) may lie on the plane's faces: whether the
    // region that holds them meets the box of the faces (widened by the lens's radius). A point
    // e's refraction point lies between the eye's foot and e's foot on the plane, on the far side
    // of the straight line's crossing when eta > 1 (the ray bends towards the normal), on the near
    // side when eta < 1: within the box of those points over the segment's ends. Parallel rays
    // all bend into one direction: the refraction points of a segment are a segment.
    auto refraction_may_meet = [&](const SmoothPlane& mp, const Vec3d& e0, const Vec3d& e1) {
        const Vec3d q(mp.q), n(mp.n);
        const TFrame<double>& axes = mp.axes;
        double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
        double hi[2] = {-lo[0], -lo[1]};
        auto hold = [&](const Vec3d& p) {
            const Vec3d local = axes.to_local(p - q);
            lo[0] = std::min(lo[0], local.x), hi[0] = std::max(hi[0], local.x);
            lo[1] = std::min(lo[1], local.y), hi[1] = std::max(hi[1], local.y);
        };
        if (!has_eye(cam.type)) {
            Vec3d r;
            if (!refracted_direction(Vec3d(cam.forward), n, mp.eta, r)) return false;
            for (const Vec3d& e : {e0, e1}) hold(e - r * (dot(e - q, n) / dot(r, n)));
        } else {
            const Vec3d eye(cam.position);
            const double h1 = dot(eye - q, n);
            if (mp.eta < 1.0) hold(eye - n * h1);
            for (const Vec3d& e : {e0, e1}) {
                const double h2 = std::max(0.0, -dot(e - q, n));
                hold(eye + (e - eye) * (h1 / (h1 + h2)));  // the straight line's crossing
                if (mp.eta >= 1.0) hold(e + n * h2);        // e's foot
            }
        }
        const double reach = cam.type == CameraType::ThinLens ? double(cam.aperture) : 0.0;
        const double margin = 1e-6 * (std::abs(mp.hi[0] - mp.lo[0]) + std::abs(mp.hi[1] - mp.lo[1])) + reach;
        return lo[0] <= mp.hi[0] + margin && hi[0] >= mp.lo[0] - margin && lo[1] <= mp.hi[1] + margin &&
               hi[1] >= mp.lo[1] - margin;
    };
    // The refracted edge of edge e of mesh m seen through plane mp: its part on the far side of
    // the plane (the parameters u0, u1 of its ends), sampled by the film length of the chord
    // between their film points (any length would do: the samples are weighted by the curve's).
    auto refracted_film_edge = [&](const SmoothPlane& mp, const Mesh& m, const Edge& e, int64_t index, FilmEdge& fe) {
        if (!mp.refracts) return false;
        if (!camera_wanted && !vertices_wanted(slots, e.mesh) && !vertices_wanted(slots, mp.mesh) &&
            !ior_wanted(mp.material))
            return false;
        const Vec3d p0(m.vertex(e.v0)), p1(m.vertex(e.v1)), q(mp.q), n(mp.n);
        const double s0 = dot(p0 - q, n), s1 = dot(p1 - q, n);
        if (!(s0 < -mp.tol || s1 < -mp.tol)) return false;  // in front of the plane, or in it
        fe.u0 = s0 > 0.0 ? s0 / (s0 - s1) : 0.0;
        fe.u1 = s1 > 0.0 ? s0 / (s0 - s1) : 1.0;
        if (!(refraction_may_meet(mp, p0 + (p1 - p0) * fe.u0, p0 + (p1 - p0) * fe.u1))) return false;
        if (!refracted_film(mp, centre, p0 + (p1 - p0) * fe.u0, fe.ax, fe.ay) ||
            !refracted_film(mp, centre, p0 + (p1 - p0) * fe.u1, fe.bx, fe.by))
            return false;
        // Whether it folds, as seen from the refraction point of its middle.
        EdgeEye middle;
        Vec3d x;
        if (has_eye(cam.type)) {
            if (!refraction_point(Vec3d(cam.position), p0 + (p1 - p0) * (0.5 * (fe.u0 + fe.u1)), q, n, mp.eta, x))
                return false;
            middle.origin = Vec3f(x);
        } else {
            Vec3d r;
            if (!refracted_direction(Vec3d(cam.forward), n, mp.eta, r)) return false;
            middle.parallel = true;
            middle.dir = Vec3f(r);
        }
        if (!is_fold(middle, m, e) && e.kind == EdgeKind::Smooth) {
            fe.weight = smooth_weights[size_t(index)];
            if (!(fe.weight > 0.0)) return false;
        }
        const double dx = fe.bx - fe.ax, dy = fe.by - fe.ay;
        fe.len = std::sqrt(dx * dx + dy * dy) * fe.weight;
        fe.refracted = true;
        return fe.len > 0.0;
    };
    // The edge e of mesh m seen through chain ch: its part on the side of the second plane the
    // rays leave it to (the parameters u0, u1 of its ends), sampled by the film length of the
    // polyline through the film points of five of its points (those the chain sees; where one
    // is, a short chord beside it). Left out where no first-plane or second-plane point found
    // comes near the faces of its plane (the chain's beam was tested in choosing the set-up).
    auto chained_film_edge = [&](const Chain& ch, const Mesh& m, const Edge& e, const ViaSetup& setup, FilmEdge& fe) {
        const SmoothPlane& a = smooth_planes.planes[size_t(ch.plane[0])];
        const SmoothPlane& b = smooth_planes.planes[size_t(ch.plane[1])];
        if (!camera_wanted && !vertices_wanted(slots, e.mesh) && !vertices_wanted(slots, a.mesh) &&
            !vertices_wanted(slots, b.mesh) && !(ch.refract[0] && ior_wanted(a.material)) &&
            !(ch.refract[1] && ior_wanted(b.material)))
            return false;
        // The sides of the second plane rays arrive from (where the first plane's faces are),
        // and leave to.
        const int in = sides_reached(a, b);
        const int out = ch.refract[1] ? ((in & 1) << 1) | ((in & 2) >> 1) : in;
        const Vec3d p0(m.vertex(e.v0)), p1(m.vertex(e.v1));
        const double s0 = dot(p0 - Vec3d(b.q), b.winding_n), s1 = dot(p1 - Vec3d(b.q), b.winding_n);
        if (out == 1 || out == 2) {
            const double sign = out == 1 ? 1.0 : -1.0, h0 = sign * s0, h1 = sign * s1;
            if (!(h0 > double(b.tol) || h1 > double(b.tol))) return false;
            fe.u0 = h0 < 0.0 ? h0 / (h0 - h1) : 0.0;
            fe.u1 = h1 < 0.0 ? h0 / (h0 - h1) : 1.0;
        } else if (out == 0) {
            return false;
        }
        // Five points' film points, each solve starting from the last's.
        constexpr int kPoints = 5;
        double fx[kPoints], fy[kPoints];
        bool ok[kPoints];
        Vec3d x1, x2, middle_x1, middle_x2, found_x1[kPoints];
        bool guessed = false, any_middle = false;
        double box1[4] = {1e300, 1e300, -1e300, -1e300}, box2[4] = {1e300, 1e300, -1e300, -1e300};
        auto hold = [](double* box, const SmoothPlane& mp, const Vec3d& x) {
            const Vec3d l = mp.axes.to_local(x - Vec3d(mp.q));
            box[0] = std::min(box[0], l.x), box[1] = std::min(box[1], l.y);
            box[2] = std::max(box[2], l.x), box[3] = std::max(box[3], l.y);
        };
        int found = 0;
        for (int k = 0; k < kPoints; ++k) {
            const double u = fe.u0 + (fe.u1 - fe.u0) * double(k) / double(kPoints - 1);
            ok[k] = chain_film(ch, centre, p0 + (p1 - p0) * u, guessed, x1, x2, fx[k], fy[k]);
            guessed = ok[k];
            if (!ok[k]) continue;
            ++found;
            found_x1[k] = x1;
            hold(box1, a, x1);
            hold(box2, b, x2);
            if (!any_middle || k <= kPoints / 2) middle_x1 = x1, middle_x2 = x2, any_middle = true;
        }
        double len = 0.0;
        for (int k = 1, last = -1; k <= kPoints; ++k) {
            const int j = k - 1;
            if (!ok[j]) continue;
            if (last >= 0) len += std::hypot(fx[j] - fx[last], fy[j] - fy[last]);
            last = j;
        }
        if (found == 1) {
            // Seen near one point only: the film length there, per unit parameter, from a point
            // an eighth of the spacing on either side, stands for the part's.
            const int j = int(std::find(ok, ok + kPoints, true) - ok);
            const double uj = fe.u0 + (fe.u1 - fe.u0) * double(j) / double(kPoints - 1);
            const double du = (fe.u1 - fe.u0) / double(8 * (kPoints - 1));
            auto film_at = [&](double u, double& gx, double& gy) {
                Vec3d y1 = found_x1[j], y2;
                if (!chain_film(ch, centre, p0 + (p1 - p0) * u, true, y1, y2, gx, gy)) return false;
                hold(box1, a, y1);
                hold(box2, b, y2);
                return true;
            };
            len = chord_length(uj, du, fe.u0, fe.u1, fx[j], fy[j], fe.u1 - fe.u0, film_at);
            if (!(len > 0.0)) return false;
        } else if (found < 2) {
            return false;
        }
        // The points found, and the faces' boxes, each widened by half the points' spread (the
        // curve between the points bends).
        auto near = [](const double* box, const SmoothPlane& mp) {
            const double wx = 0.5 * (box[2] - box[0]), wy = 0.5 * (box[3] - box[1]);
            const double margin = 1e-6 * (std::abs(mp.hi[0] - mp.lo[0]) + std::abs(mp.hi[1] - mp.lo[1]));
            return box[0] - wx <= mp.hi[0] + margin && box[2] + wx >= mp.lo[0] - margin &&
                   box[1] - wy <= mp.hi[1] + margin && box[3] + wy >= mp.lo[1] - margin;
        };
        if (!near(box1, a) || !near(box2, b)) return false;
        // Whether it folds, seen from the second plane's point of a middle point (parallel rays
        // stay parallel through flat faces).
        EdgeEye seen_from;
        if (has_eye(cam.type)) {
            seen_from.origin = Vec3f(middle_x2);
        } else {
            Vec3d o1, o2, dir;
            const double back = length(middle_x2 - middle_x1) + std::abs(a.hi[0] - a.lo[0]) + std::abs(a.hi[1] - a.lo[1]);
            if (!follow_chain(smooth_planes.planes, ch, middle_x1 - Vec3d(cam.forward) * back, Vec3d(cam.forward), o1,
                              o2, dir))
                return false;
            seen_from.parallel = true;
            seen_from.dir = Vec3f(dir);
        }
        // (A smooth edge that does not fold seen from the beam's origin was kept with a
        // probability: its samples count its inverse, at a fold's density.)
        if (setup.kept < 1.0) {
            fe.kept = setup.kept;
        } else if (!is_fold(seen_from, m, e) && e.kind == EdgeKind::Smooth) {
            fe.weight = smooth_weights[size_t(setup.edge)];
            if (!(fe.weight > 0.0)) return false;
        }
        fe.len = len * fe.weight;
        fe.chain = int(&ch - chains.data());
        fe.plane = ch.plane[0];
        return fe.len > 0.0;
    };
    auto normals_wanted = [&](int mesh) {
        return size_t(mesh) < slots.meshes.size() && slots.meshes[size_t(mesh)].normals.wanted();
    };
    // The film point that `eye` sees point e at in or through curved face cf; (b1, b2) (in: a
    // guess) the barycentrics of its point there.
    auto curved_film = [&](const CurvedFace& cf, const Eye& eye, const Vec3d& e, bool guessed, int restart,
                           double& b1, double& b2, double& fx, double& fy) {
        const Vec3d from(eye.position), forward(cam.forward);
        const bool parallel = !has_eye(cam.type);
        if (!guessed) curved_guess(cf, from, parallel, forward, e, b1, b2);
        Vec3d x;
        return curved_point(cf, from, parallel, forward, e, restart, b1, b2, x) &&
               point_film(eye, x, Vec3f(cf.ng), fx, fy);
    };
    // The same through the pair of curved faces cp, (b1, b2) those of its first face's point (in:
    // the guess), (c1, c2) its second's; `inside`: whether both lie inside their faces.
    auto pair_film = [&](const CurvedPair& cp, const Eye& eye, const Vec3d& e, int restart, double& b1, double& b2,
                         double& fx, double& fy, double& c1, double& c2, bool& inside) {
        const Vec3d from(eye.position), forward(cam.forward);
        const bool parallel = !has_eye(cam.type);
        Vec3d x;
        return pair_point(cp, from, parallel, forward, e, restart, b1, b2, x, c1, c2, inside) &&
               point_film(eye, x, Vec3f(cp.face[0].ng), fx, fy);
    };
    // The edge e of mesh m seen in or through a curved face, or a pair of them, whose beam is
    // `beam` (`setup`: its part on the side of the (last) face the lobe sends rays to), of that
    // part the sixteenths the beam may see, sampled by the film length of the polyline through the
    // film points of `points` (at most 33) of its points spread evenly, and of the `crossings`
    // (parameters with the barycentrics of the first face to solve from; at most 32 of them) in
    // the part (from the last of them outside the face before the first inside to the first
    // outside after the last inside; where one point only is found, a short chord beside it).
    // film(p, guessed, restart, b1, b2, fx, fy, c1, c2, inside) finds edge point p's film point
    // and the (first) face's barycentrics there (in: the guess, where `guessed`), the second
    // face's (c1, c2; a single face's own again) and whether they lie inside the face (both
    // faces). Through one face each solve starts from the last point's, and where it ends outside
    // the face, again from the face's centre (more restarts change nothing measurable for one
    // face; the samples' solves make four, through a pair nine). Left out where no point found
    // lies near the face (each face), or `through_pair` where none lies inside both; through a
    // pair each solve starts from film's own guess or its crossing's point, then grows the parts
    // found inside (below).
    auto face_film_edge = [&](const Beam& beam, const Mesh& m, const Edge& e, const ViaSetup& setup, auto&& film,
                              int points, bool through_pair, FilmEdge& fe,
                              const std::vector<std::array<double, 3>>* crossings = nullptr) {
        const Vec3d p0(m.vertex(e.v0)), p1(m.vertex(e.v1));
        double u0 = setup.u0, u1 = setup.u1;
        constexpr int kPieces = 16;
        int first = -1, last = -1;
        for (int k = 0; k < kPieces; ++k) {
            const double a = u0 + (u1 - u0) * double(k) / kPieces, b = u0 + (u1 - u0) * double(k + 1) / kPieces;
            if (!beam.may_see(p0 + (p1 - p0) * a, p0 + (p1 - p0) * b)) continue;
            if (first < 0) first = k;
            last = k;
        }
        if (first < 0) return false;
        const double span = u1 - u0;
        u1 = u0 + span * double(last + 1) / kPieces;
        u0 = u0 + span * double(first) / kPieces;
        // The points' film points (through one face each solve starting from the last's, the
        // first from the face's guess).
        constexpr int kEven = 33, kCrossings = 32, kMaxPoints = kEven + kCrossings;
        // (Each point's parameter, and for a crossing its solve's start.)
        std::array<double, 3> points_at[kMaxPoints];
        const int num_even = std::min(points, kEven);
        int num_points = num_even;
        for (int k = 0; k < num_points; ++k)
            points_at[k] = {u0 + (u1 - u0) * double(k) / double(num_points - 1), -1.0, -1.0};
        if (crossings && !crossings->empty()) {
            // (Up to kCrossings of them, spread over the list, inside the part.)
            const size_t n = crossings->size(), take = std::min<size_t>(n, kCrossings);
            for (size_t q = 0; q < take; ++q) {
                const std::array<double, 3>& c = (*crossings)[take == n ? q : q * (n - 1) / (take - 1)];
                if (c[0] > u0 && c[0] < u1) points_at[num_points++] = c;
            }
            std::sort(points_at, points_at + num_points);
        }
        auto at = [&](int k) { return points_at[k][0]; };
        double fx[kMaxPoints], fy[kMaxPoints], bb1[kMaxPoints], bb2[kMaxPoints];
        bool ok[kMaxPoints], inside[kMaxPoints];
        double b1 = 0.0, b2 = 0.0;
        bool guessed = false;
        int first_in = -1, last_in = -1;
        double box[2][4] = {{1e300, 1e300, -1e300, -1e300}, {1e300, 1e300, -1e300, -1e300}};
        double cc1[kMaxPoints], cc2[kMaxPoints];
        auto solve_point = [&](int k, bool from_guess, int restart) {
            if (!from_guess && points_at[k][1] >= 0.0) b1 = points_at[k][1], b2 = points_at[k][2], from_guess = true;
            ok[k] = film(p0 + (p1 - p0) * at(k), from_guess, restart, b1, b2, fx[k], fy[k], cc1[k], cc2[k], inside[k]);
            if (!ok[k]) inside[k] = false;
            bb1[k] = b1, bb2[k] = b2;
            return ok[k];
        };
        for (int k = 0; k < num_points; ++k) guessed = solve_point(k, guessed && !through_pair, 1);
        if (through_pair) {
            // Through a pair a point's solve may end at a root outside the faces where one
            // inside lies near a neighbour's: a point beside one found inside is solved again
            // from that one's point, until no more are found (else the part ends early). Where
            // none is inside, the crossings are solved again with every restart first (the
            // faces' clamped normals fold the map near their borders: Gauss-Newton steps from
            // a grid point beside a small part seen through a corner of the pair often fail).
            bool tried[kMaxPoints][2] = {};
            auto grow = [&] {
                for (bool grown = true; grown;) {
                    grown = false;
                    for (int k = 0; k < num_points; ++k)
                        for (int side = 0; side < 2 && !inside[k]; ++side) {
                            const int j = side == 0 ? k - 1 : k + 1;
                            if (j < 0 || j >= num_points || !inside[j] || tried[k][side]) continue;
                            tried[k][side] = true;
                            const double keep[6] = {fx[k], fy[k], bb1[k], bb2[k], cc1[k], cc2[k]};
                            const bool kept_ok = ok[k];
                            b1 = bb1[j], b2 = bb2[j];
                            if (solve_point(k, true, 1) && inside[k]) {
                                grown = true;
                            } else {
                                // (Not inside from there either: the first solve's point stays.)
                                fx[k] = keep[0], fy[k] = keep[1], bb1[k] = keep[2], bb2[k] = keep[3];
                                cc1[k] = keep[4], cc2[k] = keep[5], ok[k] = kept_ok, inside[k] = false;
                            }
                        }
                }
            };
            grow();
            if (std::find(inside, inside + num_points, true) == inside + num_points) {
                bool any = false;
                for (int k = 0; k < num_points; ++k)
                    if (points_at[k][1] >= 0.0 && solve_point(k, false, 9) && inside[k]) any = true;
                if (any) grow();
            }
        }
        for (int k = 0; k < num_points; ++k) {
            if (!ok[k]) continue;
            if (inside[k]) last_in = k, first_in = first_in < 0 ? k : first_in;
            const double at_face[2][2] = {{bb1[k], bb2[k]}, {cc1[k], cc2[k]}};
            for (int f = 0; f < 2; ++f) {
                box[f][0] = std::min(box[f][0], at_face[f][0]), box[f][1] = std::min(box[f][1], at_face[f][1]);
                box[f][2] = std::max(box[f][2], at_face[f][0]), box[f][3] = std::max(box[f][3], at_face[f][1]);
            }
        }
        // Near the face (each face): the points' box of barycentrics, widened by half its size
        // (the curve between the points bends), meets the face's.
        for (const double* bx : box) {
            const double wx = 0.5 * (bx[2] - bx[0]) + 1e-9, wy = 0.5 * (bx[3] - bx[1]) + 1e-9;
            if (!(bx[2] + wx >= 0.0 && bx[3] + wy >= 0.0 && bx[0] - wx + bx[1] - wy <= 1.0)) return false;
        }
        // (A point whose solve failed may lie inside: the part runs on to the next one found
        // outside.)
        if (first_in < 0 && through_pair) return false;
        int lo = 0, hi = num_points - 1;
        if (first_in >= 0) {
            lo = first_in, hi = last_in;
            while (lo > 0 && !(ok[lo] && !inside[lo] && lo < first_in)) --lo;
            while (hi < num_points - 1 && !(ok[hi] && !inside[hi] && hi > last_in)) ++hi;
        }
        double len = 0.0, len_inside = 0.0;
        int found = 0, middle = -1;
        for (int k = lo, prev = -1; k <= hi; ++k) {
            if (!ok[k]) continue;
            ++found;
            if (middle < 0 || (inside[k] && !inside[middle])) middle = k;
            if (prev >= 0) {
                const double piece = std::hypot(fx[k] - fx[prev], fy[k] - fy[prev]);
                len += piece;
                if (inside[k] && inside[prev]) len_inside += piece;
            }
            prev = k;
        }
        // (Through a pair the part's share of the samples is its film length between points found
        // inside, where two are: the roots outside lie elsewhere on the film.)
        if (through_pair && len_inside > 0.0) len = len_inside;
        if (found == 0) return false;
        if (found == 1) {
            // Seen near one point only: the film length there, per unit parameter, from a point
            // an eighth of the spacing on either side, stands for the part's.
            const double du = (u1 - u0) / double(8 * (num_even - 1));
            len = chord_length(at(middle), du, u0, u1, fx[middle], fy[middle], at(hi) - at(lo),
                               [&](double u, double& gx, double& gy) {
                                   double a1 = bb1[middle], a2 = bb2[middle], c1, c2;
                                   bool in;
                                   return film(p0 + (p1 - p0) * u, true, 1, a1, a2, gx, gy, c1, c2, in);
                               });
            if (!(len > 0.0)) return false;
        }
        // (A smooth edge that does not fold, seen from the face's centre, was kept with a
        // probability: its samples count its inverse.)
        fe.kept = setup.kept;
        fe.u0 = at(lo);
        fe.u1 = at(hi);
        // The barycentrics found nearest the part's ends: the guesses of its samples' solves
        // (along a line between them).
        int near_lo = hi, near_hi = lo;
        for (int k = hi; k >= lo; --k)
            if (ok[k]) near_lo = k;
        for (int k = lo; k <= hi; ++k)
            if (ok[k]) near_hi = k;
        if (!ok[near_lo]) near_lo = near_hi = middle;
        fe.ax = bb1[near_lo], fe.ay = bb2[near_lo], fe.bx = bb1[near_hi], fe.by = bb2[near_hi];
        fe.len = len;  // (weight 1: its density factor is `kept`)
        return fe.len > 0.0 && fe.u1 > fe.u0;
    };
    // Whether something wanted moves the film curve of an edge seen through face cf: its mesh's
    // vertices or normals, or where it refracts its index.
    auto face_wanted = [&](const CurvedFace& cf) {
        return vertices_wanted(slots, cf.mesh) || normals_wanted(cf.mesh) ||
               (cf.refract && ior_wanted(scene.meshes[size_t(cf.mesh)].material));
    };
    auto curved_film_edge = [&](const CurvedFace& cf, const Mesh& m, const Edge& e, const ViaSetup& setup,
                                FilmEdge& fe) {
        if (!camera_wanted && !vertices_wanted(slots, e.mesh) && !face_wanted(cf)) return false;
        fe.curved = int(&cf - curved.data());
        auto film = [&](const Vec3d& p, bool guessed, int restart, double& b1, double& b2, double& fx, double& fy,
                        double& c1, double& c2, bool& inside) {
            if (!curved_film(cf, centre, p, guessed, restart, b1, b2, fx, fy)) return false;
            c1 = b1, c2 = b2;
            inside = inside_triangle(b1, b2);
            return true;
        };
        return face_film_edge(cf, m, e, setup, film, 5, false, fe);
    };
    auto pair_film_edge = [&](const CurvedPair& cp, const Mesh& m, const Edge& e, const ViaSetup& setup,
                              PairRays& rays, FilmEdge& fe) {
        if (!camera_wanted && !vertices_wanted(slots, e.mesh) && !face_wanted(cp.face[0]) && !face_wanted(cp.face[1]))
            return false;
        fe.pair = int(&cp - pairs.data());
        // The rays from the eye through a grid of the first face's points, followed through both
        // faces (those that meet the second face inside it, within a quarter; found once for the
        // pair's set-ups in a row; within 5%, a part seen through a corner was often missed):
        // where two neighbours pass the edge's line on either side, the edge
        // is seen between them. The edge's parameters nearest those rays (each with its grid
        // point) bound the part seen; its solves start from the grid point whose parameter is
        // nearest theirs. (The faces' normals are clamped beyond them, so a solve continued from
        // the last point's root may follow a root outside them past a part inside, too short
        // for the points to land in.)
        constexpr int kGrid = PairRays::kGrid;
        if (rays.pair != fe.pair) {
            rays.pair = fe.pair;
            const Vec3d from(centre.position), forward(cam.forward);
            const bool parallel = !has_eye(cam.type);
            const CurvedFace& f = cp.face[0];
            for (int i = 0; i <= kGrid; ++i)
                for (int j = 0; i + j <= kGrid; ++j) {
                    const double b1 = double(i) / kGrid, b2 = double(j) / kGrid;
                    const Vec3d x = f.v0 + f.e1 * b1 + f.e2 * b2;
                    double c1, c2;
                    const Vec3d d = parallel ? forward : normalize(x - from);
                    rays.valid[i][j] = cp.follow(b1, b2, d, rays.at[i][j], c1, c2, rays.dir[i][j]) && c1 >= -0.25 &&
                                       c2 >= -0.25 && c1 + c2 <= 1.25;
                }
        }
        const Vec3d p0(m.vertex(e.v0)), p1(m.vertex(e.v1)), along = p1 - p0;
        double side[kGrid + 1][kGrid + 1], at_u[kGrid + 1][kGrid + 1];
        const auto& valid = rays.valid;
        for (int i = 0; i <= kGrid; ++i)
            for (int j = 0; i + j <= kGrid; ++j) {
                if (!valid[i][j]) continue;
                const Vec3d &x2 = rays.at[i][j], &dir = rays.dir[i][j];
                side[i][j] = dot(cross(p0 - x2, p1 - x2), dir);
                // The edge's parameter nearest the ray (x2, dir).
                const Vec3d w = p0 - x2;
                const double a = dot(along, along), b = dot(along, dir), c = dot(dir, dir), d = dot(along, w),
                             g = dot(dir, w), den = a * c - b * b;
                at_u[i][j] = den > 0.0 ? (b * g - c * d) / den : 0.5;
            }
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        std::vector<std::array<double, 3>> starts;  // (u, b1, b2)
        auto pair_up = [&](int i, int j, int k, int l) {
            if (k < 0 || l < 0 || k + l > kGrid || !valid[i][j] || !valid[k][l]) return;
            if ((side[i][j] > 0.0) == (side[k][l] > 0.0)) return;
            for (const auto& [a, b] : {std::pair<int, int>{i, j}, std::pair<int, int>{k, l}}) {
                lo = std::min(lo, at_u[a][b]), hi = std::max(hi, at_u[a][b]);
                starts.push_back({at_u[a][b], double(a) / kGrid, double(b) / kGrid});
            }
        };
        for (int i = 0; i <= kGrid; ++i)
            for (int j = 0; i + j <= kGrid; ++j) {
                pair_up(i, j, i + 1, j);
                pair_up(i, j, i, j + 1);
                pair_up(i, j, i + 1, j - 1);
            }
        if (!(lo <= hi)) return false;
        ViaSetup narrowed = setup;
        const double w = 0.5 * (hi - lo) + 0.02 * (setup.u1 - setup.u0);
        narrowed.u0 = std::max(setup.u0, lo - w), narrowed.u1 = std::min(setup.u1, hi + w);
        if (!(narrowed.u0 < narrowed.u1)) return false;
        auto film = [&](const Vec3d& p, bool guessed, int restart, double& b1, double& b2, double& fx, double& fy,
                        double& c1, double& c2, bool& inside) {
            if (!guessed) {
                const double u = dot(p - p0, along) / dot(along, along);
                double best = std::numeric_limits<double>::infinity();
                for (const auto& st : starts)
                    if (std::abs(st[0] - u) < best) best = std::abs(st[0] - u), b1 = st[1], b2 = st[2];
            }
            return pair_film(cp, centre, p, restart, b1, b2, fx, fy, c1, c2, inside);
        };
        // (Also at the parameters where the grid's rays pass the edge: a part seen through a
        // small corner of the pair can lie between the evenly spread points.)
        std::vector<std::array<double, 3>> crossings = starts;
        std::sort(crossings.begin(), crossings.end());
        crossings.erase(std::unique(crossings.begin(), crossings.end()), crossings.end());
        return face_film_edge(cp, m, e, narrowed, film, 33, true, fe, &crossings);
    };
    constexpr int64_t kSetupChunk = 4096;
    const int64_t num_edges = int64_t(all_edges.size());
    // Each edge directly, then reflected in each plane of smooth faces, then refracted by each,
    // then (after these) through each chain, then in or through each curved face, as chosen.
    const int64_t num_planes = int64_t(smooth_planes.planes.size());
    const int64_t num_setups = num_edges * (1 + 2 * num_planes);
    std::vector<std::vector<FilmEdge>> chunk_edges(size_t((num_setups + kSetupChunk - 1) / kSetupChunk));
    for_each_chunk(opt, num_setups, kSetupChunk, [&](int64_t begin, int64_t end) {
        // Filled here and moved into place at the end: the chunks' vectors lie side by side, and
        // two threads adding to neighbours would share their cache line at every addition.
        std::vector<FilmEdge> film_edges;
        film_edges.reserve(size_t(end - begin));
        for (int64_t setup = begin; setup < end; ++setup) {
            const int64_t index = setup % num_edges, slot = setup / num_edges - 1;
            const Edge& e = all_edges[size_t(index)];
            if (e.flat) continue;
            if (slot >= 0) {
                FilmEdge fe;
                const int64_t plane = slot % num_planes;
                const SmoothPlane& mp = smooth_planes.planes[size_t(plane)];
                const Mesh& m = scene.meshes[size_t(e.mesh)];
                const bool kept = slot < num_planes ? mirrored_film_edge(mp, m, e, index, fe)
                                                    : refracted_film_edge(mp, m, e, index, fe);
                if (!kept) continue;
                fe.edge = size_t(index);
                fe.plane = int(plane);
                film_edges.push_back(fe);
                continue;
            }
            if (!camera_wanted && !vertices_wanted(slots, e.mesh)) continue;
            const Mesh& m = scene.meshes[size_t(e.mesh)];
            FilmEdge fe;
            double len;
            if (uniform || spherical) fe.world = measures.length[size_t(index)];
            if (uniform) {
                len = fe.world;  // world length; the film part is found per sample
            } else if (spherical) {
                // Folds (and the smooth edges by their weight, as below), by the angle they subtend
                // at the camera's position; the points of an edge by world length.
                const bool fold = is_fold(camera_eye, m, e);
                if (!fold && left_out(m, e)) continue;
                if (!fold && e.kind == EdgeKind::Smooth && !smooth_edges_jump) {
                    fe.weight = smooth_weights[size_t(index)];
                    if (!(fe.weight > 0.0)) continue;
                }
                const Vec3d a(m.vertex(e.v0) - cam.position), b(m.vertex(e.v1) - cam.position);
                // A fisheye sees nothing beyond half its fov from its axis (up to rounding).
                if (cam.type == CameraType::Fisheye && min_angle_from(a, b, Vec3d(cam.forward)) > double(cam.half_fov) + 1e-5)
                    continue;
                len = std::atan2(length(cross(a, b)), dot(a, b)) * fe.weight;
            } else {
                // Folds and creases (shading or texture jumps) at full density. A smooth edge that
                // does not fold separates different values of the geometric normal, and steps where
                // the mesh shadows itself along it (the light between its faces' planes reaches one
                // face and not the other, while the smooth normals give both a weight): sampled in
                // proportion to the angle between its faces, the weight dividing the sample's.
                // (Its part on the film first, where no rule above can leave it out: an edge off
                // the film needs neither its faces nor its weight. Where one can, whether it folds
                // is found first: a projection costs more than the faces' tests.)
                const bool known = may_leave_out(e);
                const bool fold_known = known && is_fold(camera_eye, m, e);
                if (known && !fold_known && left_out(m, e)) continue;
                if (!project_edge(cam, m.vertex(e.v0), m.vertex(e.v1), wx0, wy0, wx1, wy1, fe)) continue;
                const bool fold = known                               ? fold_known
                                  : cam.type == CameraType::ThinLens ? lens_may_fold(cam, m, e)
                                                                      : is_fold(camera_eye, m, e);
                if (!fold && e.kind == EdgeKind::Smooth && !smooth_edges_jump) {
                    fe.weight = smooth_weights[size_t(index)];
                    if (!(fe.weight > 0.0)) continue;
                }
                // (Film lengths are far from overflow: no need of hypot's care, which costs as
                // much as the rest of an edge's set-up.)
                const double dx = fe.bx - fe.ax, dy = fe.by - fe.ay;
                len = std::sqrt(dx * dx + dy * dy) * fe.weight;
            }
            fe.edge = size_t(index);
            fe.len = len;
            if (!(len > 0.0)) continue;
            film_edges.push_back(fe);
        }
        chunk_edges[size_t(begin / kSetupChunk)] = std::move(film_edges);
    });
    // Then the edges seen through chains, in or through curved faces and through pairs of them
    // (their set-ups chosen above), in chunks of their own after those.
    {
        constexpr int64_t kViaChunk = 256;
        const int64_t num_chained = int64_t(chain_setups.size());
        const int64_t num_curved = num_chained + int64_t(curved_setups.size());
        const int64_t count = num_curved + int64_t(pair_setups.size());
        const size_t first = chunk_edges.size();
        chunk_edges.resize(first + size_t((count + kViaChunk - 1) / kViaChunk));
        for_each_chunk(opt, count, kViaChunk, [&](int64_t begin, int64_t end) {
            std::vector<FilmEdge> film_edges;
            PairRays rays;
            for (int64_t k = begin; k < end; ++k) {
                const ViaSetup& setup = k < num_chained  ? chain_setups[size_t(k)]
                                        : k < num_curved ? curved_setups[size_t(k - num_chained)]
                                                         : pair_setups[size_t(k - num_curved)];
                const Edge& e = all_edges[size_t(setup.edge)];
                const Mesh& m = scene.meshes[size_t(e.mesh)];
                FilmEdge fe;
                if (!(k < num_chained  ? chained_film_edge(chains[size_t(setup.via)], m, e, setup, fe)
                      : k < num_curved ? curved_film_edge(curved[size_t(setup.via)], m, e, setup, fe)
                                       : pair_film_edge(pairs[size_t(setup.via)], m, e, setup, rays, fe)))
                    continue;
                fe.edge = size_t(setup.edge);
                film_edges.push_back(fe);
            }
            chunk_edges[first + size_t(begin / kViaChunk)] = std::move(film_edges);
        });
    }
    // The edges on the film, k = 0, 1, ... in the list's order, stay in their chunks (not copied
    // into one array): chunk c holds k from starts[c] on.
    std::vector<size_t> starts(chunk_edges.size() + 1, 0);
    for (size_t c = 0; c < chunk_edges.size(); ++c) starts[c + 1] = starts[c] + chunk_edges[c].size();
    const size_t num_film = starts.back();
    if (num_film == 0) return;
    auto film_edge = [&](size_t k) -> const FilmEdge& {
        const size_t c = size_t(std::upper_bound(starts.begin(), starts.end(), k) - starts.begin()) - 1;
        return chunk_edges[c][k - starts[c]];
    };
    // Cumulative film length: sample i takes the point at length (i + u) / n * total, so the
    // samples are stratified along all the edges together. (Uniform: world length, u alone.)
    std::vector<double> cumulative(num_film + 1, 0.0);
    size_t k_all = 0;
    for (const std::vector<FilmEdge>& chunk : chunk_edges)
        for (const FilmEdge& fe : chunk) cumulative[k_all + 1] = cumulative[k_all] + fe.len, ++k_all;
    const int64_t n = opt.edge_samples > 0 ? opt.edge_samples
                                           : int64_t(scene.out_width) * scene.out_height * int64_t(opt.spp);
    // The edges seen directly come first (k < num_direct), then those seen in planes of smooth
    // faces: each group gets n samples of its own, so that the second, whose samples mostly
    // meet no face of their plane where there are many small ones, takes none from the first.
    size_t num_direct = 0;
    for (const std::vector<FilmEdge>& chunk : chunk_edges)
        for (const FilmEdge& fe : chunk) num_direct += fe.plane < 0 && fe.curved < 0 && fe.pair < 0;
    const double total_direct = cumulative[num_direct], total_smooth = cumulative[num_film] - total_direct;
    const int64_t n_direct = total_direct > 0.0 ? n : 0, n_smooth = total_smooth > 0.0 ? n : 0;
    // Every point of every edge is drawn with density 1 / total (its group's) per unit film length
    // (per unit world length for uniform sampling, converted to film length per sample).
    const double weight_direct = total_direct / double(n), weight_smooth = total_smooth / double(n);
    const double px_scale = 2.0 * cam.tx / cam.width;  // d(screen offset) / d(film pixel)

    const float radius = scene.filter.radius();
    const bool thin_lens = cam.type == CameraType::ThinLens;
    const uint64_t seed = mix64(opt.seed ^ 0x70726d6564676573ull);
    // Each chunk's additions (the gradients' or the derivative image's) in the chunks' order: the
    // same sums, bit for bit, whatever the thread count.
    tbb::enumerable_thread_specific<GradSink> sinks([&] { return GradSink(adjoint == nullptr, true); });
    OrderedAdds adds;
    // An edge sample's splat in three steps: its two sides and their channel values (found at
    // once), then its two side paths, traced with those of up to batch - 1 other samples by a
    // PathBatch (render/batch.h: trace_path's radiance, bit for bit), then the jump and its splat,
    // sample by sample in the samples' order: the sink gets the same additions in the same order
    // whatever the batch size.
    struct Pending {
        const Edge* edge;
        float x, y, lu, lv;  // the film point, the lens sample
        EdgeSideGradient g;
        float weight;  // the film length the sample stands for over the film gradient's norm
        float value_u[kMaxChannelValues], value_l[kMaxChannelValues];
        // The sample's edge, film point and lens sample (from `eye`), side function and weight.
        void place(const Edge& e, float fx, float fy, const Eye& eye, const EdgeSideGradient& side, float w) {
            edge = &e;
            x = fx;
            y = fy;
            lu = eye.lu;
            lv = eye.lv;
            g = side;
            weight = w;
        }
        // Seen in a mirror or through glass: the faces met (up to two, through a chain), each
        // with its mesh and vertex indices and the adjoints of g for its three vertices and,
        // where it refracts, for its material's index (g's camera part is the camera ray's, its
        // edge part the edge's).
        struct Face {
            int mesh = -1, material = -1;
            int32_t tri[3] = {-1, -1, -1};
            Vec3f dv[3];
            float deta = 0.f;
            // A curved face's: its shading normals' indices and the adjoints of g for them.
            bool normals = false;
            int32_t normal_tri[3] = {-1, -1, -1};
            Vec3f dn[3];
        };
        Face faces[2];
    };
    // The side paths of edges seen in mirrors or through glass: from the mirror's or the glass's
    // point, a bounce fewer, emitters seen.
    RenderOptions reflected_opt = opt;
    reflected_opt.max_bounces = opt.max_bounces - 1;
    reflected_opt.hide_emitters = false;
    // Through a chain of two faces: from the second face's point, two bounces fewer.
    RenderOptions chained_opt = reflected_opt;
    chained_opt.max_bounces = opt.max_bounces - 2;
    constexpr int64_t kSampleChunk = 4096;
    for_each_chunk(opt, n_direct + n_smooth, kSampleChunk, [&](int64_t begin, int64_t end) {
        GradSink& sink = sinks.local();
        RayCounters counters;
        std::vector<Pending> pending(static_cast<size_t>(batch));
        int npending = 0;
        // The side paths of the pending samples (upper, lower, upper, ...) and their radiance.
        std::unique_ptr<PathBatch> side_paths;
        std::vector<CameraSample> sides;
        std::vector<Vec3f> side_L;
        if (radiance) {
            side_paths = std::make_unique<PathBatch>(scene, opt);
            sides.resize(size_t(2 * batch));
            side_L.resize(size_t(2 * batch));
        }
        // Adds s * dg/d(the face's vertices and index) of a sample seen in a mirror or through glass.
        auto add_face_gradient = [&](const Pending& pd, float s) {
            for (const Pending::Face& face : pd.faces) {
                if (face.mesh < 0) break;
                if (vertices_wanted(slots, face.mesh)) {
                    const GradSlot& fs = slots.meshes[size_t(face.mesh)].vertices;
                    for (int c = 0; c < 3; ++c) {
                        const Vec3f a = face.dv[c] * s;
                        sink.add3(fs, face.tri[c], a.x, a.y, a.z);
                    }
                }
                if (ior_wanted(face.material))
                    sink.add(slots.materials[size_t(face.material)].ior, 0, s * face.deta);
                if (face.normals && normals_wanted(face.mesh)) {
                    const GradSlot& ns = slots.meshes[size_t(face.mesh)].normals;
                    for (int c = 0; c < 3; ++c) {
                        const Vec3f a = face.dn[c] * s;
                        sink.add3(ns, face.normal_tri[c], a.x, a.y, a.z);
                    }
                }
            }
        };
        // The jump of pending sample pd (its side paths' radiance difference L) and its splat.
        auto finish = [&](Pending& pd, const Vec3f& L) {
            float* value_u = pd.value_u;
            float* value_l = pd.value_l;
            float delta[kMaxChannelValues];
            if (radiance)
                for (int c = 0; c < 3; ++c) value_u[ro + c] = L[c], value_l[ro + c] = 0.f;
            bool jump = false;
            for (int c = 0; c < nv; ++c) {
                delta[c] = value_u[c] - value_l[c];
                jump = jump || delta[c] != 0.f;
            }
            if (!jump) return;
            const Edge& edge = *pd.edge;
            const EdgeSideGradient& g = pd.g;
            const float x = pd.x, y = pd.y, weight = pd.weight;

            // Output pixels the filter reaches from the sample (pixel centres at i + 0.5).
            const float ox = x - float(scene.crop_x) - 0.5f, oy = y - float(scene.crop_y) - 0.5f;
            const int px0 = std::max(0, int(std::ceil(ox - radius))), px1 = std::min(scene.out_width - 1, int(std::floor(ox + radius)));
            const int py0 = std::max(0, int(std::ceil(oy - radius))), py1 = std::min(scene.out_height - 1, int(std::floor(oy + radius)));
            auto for_each_pixel = [&](auto&& fn) {
                for (int py = py0; py <= py1; ++py) {
                    const float ky = scene.filter.eval(oy - float(py));
                    if (ky == 0.f) return;
                    for (int px = px0; px <= px1; ++px) {
                        const float k = ky * scene.filter.eval(ox - float(px));
                        if (k != 0.f) fn(int64_t(py) * scene.out_width + px, k);
                    }
                }
            };
            // Adds s * dg/d(parameter) to the sink.
            auto add_side_gradient = [&](float s) {
                if (vertices_wanted(slots, edge.mesh)) {
                    const GradSlot& vs = slots.meshes[size_t(edge.mesh)].vertices;
                    sink.add3(vs, edge.v0, s * g.d_e0.x, s * g.d_e0.y, s * g.d_e0.z);
                    sink.add3(vs, edge.v1, s * g.d_e1.x, s * g.d_e1.y, s * g.d_e1.z);
                }
                if (pd.faces[0].mesh >= 0) add_face_gradient(pd, s);
                if (camera_wanted) {
                    float cg[kCameraParams] = {};
                    d_camera_ray(scene.camera_params, x, y, pd.lu, pd.lv, g.d_o * s, g.d_d * s, cg);
                    for (int k = 0; k < kCameraParams; ++k) sink.add(slots.camera, k, cg[k]);
                }
            };
            if (adjoint) {
                double s = 0.0;
                for_each_pixel([&](int64_t p, float k) {
                    const float* a = adjoint + nv * p;
                    float ad = 0.f;
                    for (int c = 0; c < nv; ++c) ad += a[c] * delta[c];
                    s += double(k) * ad;
                });
                if (s != 0.0) add_side_gradient(float(s * weight));
            } else {
                add_side_gradient(1.f);
                const float dg = float(sink.take_projection()) * weight;
                if (dg == 0.f) return;
                for_each_pixel([&](int64_t p, float k) {
                    for (int c = 0; c < nv; ++c)
                        if (delta[c] != 0.f) sink.add_out(out + nv * p + c, k * dg * delta[c]);
                });
            }
        };
        // Traces the pending samples' side paths and finishes them, in order.
        auto flush = [&] {
            if (npending == 0) return;
            if (radiance) side_paths->trace(sides.data(), 2 * npending, side_L.data(), counters);
            for (int k = 0; k < npending; ++k)
                finish(pending[size_t(k)], radiance ? side_L[size_t(2 * k)] - side_L[size_t(2 * k + 1)] : Vec3f(0.f));
            npending = 0;
        };
        // The norm of the film gradient of side function g at film point (x, y), whose ray from
        // `eye` has direction d: a pinhole's, a thin lens's or parallel rays'.
        auto film_gradient_norm = [&](float x, float y, const Eye& eye, const Vec3f& d, const EdgeSideGradient& g) {
            if (!has_eye(cam.type)) return std::hypot(dot(g.d_o, cam.right) * px_scale, -dot(g.d_o, cam.up) * px_scale);
            // d = normalize(D), D = focus w - a (a pinhole: focus 1, a = 0), w = forward + sx right
            // + sy up; d(sx)/dx = px_scale, d(sy)/dy = -px_scale.
            const Vec2f sc = cam.screen(x, y);
            const float focus = thin_lens ? cam.focus : 1.f;
            const Vec3f D = (cam.forward + cam.right * sc.x + cam.up * sc.y) * focus - (eye.position - cam.position);
            const double scale = focus / length(D);
            const Vec3f dr = cam.right - d * dot(d, cam.right), du = cam.up - d * dot(d, cam.up);
            return std::hypot(dot(g.d_d, dr) * px_scale * scale, -dot(g.d_d, du) * px_scale * scale);
        };
        // The boundary term of edge `edge` at film point (x, y): the side function's film gradient,
        // the two sides and the splat of the jump through the pixel filter. `point_weight`: the
        // film length the sample stands for (fisheye and panorama: per unit of the edge point's
        // world length, given as edge_point). Its side paths are traced, and the jump splatted, at
        // the next flush.
        auto splat = [&](int64_t i, const Eye& eye, const Edge& edge, const Vec3f& p0, const Vec3f& p1,
                         float x, float y, double point_weight, const Vec3f* edge_point) {
            EdgeEye side_eye = camera_eye;
            side_eye.origin = eye.position;

            // The side function at the sample and its film-space gradient.
            Vec3f o, d;
            camera_ray(scene.camera_params, x, y, eye.lu, eye.lv, o, d);
            const EdgeSideGradient g = edge_side_gradient(p0, p1, o, d);
            double glen;
            if (spherical) {
                // d is the film point's unit direction: the side function's film gradient is its
                // direction gradient along the film's tangents; the film length per unit world
                // length of the edge point is the norm of the film displacement that turns the
                // direction as moving along the edge does.
                Vec3d tx, ty;
                spherical_film_tangents(cam, x, y, tx, ty);
                const Vec3d dd(g.d_d);
                glen = std::hypot(dot(dd, tx), dot(dd, ty));
                const Vec3d to(*edge_point - cam.position), u(normalize(p1 - p0));
                const double dist = length(to);
                const Vec3d w = to / dist;
                point_weight *= spherical_jacobian(tx, ty, (u - w * dot(w, u)) / dist);
                if (!(point_weight > 0.0)) return;
            } else {
                glen = film_gradient_norm(x, y, eye, d, g);
            }
            if (!(glen > 0.0) || !std::isfinite(glen)) return;

            // Both sides, g > 0 (upper) and g < 0 (lower), in the limit at the edge point the
            // camera ray passes (edges/sides.h); none where that point is hidden.
            Ray ray;
            ray.origin = o;
            ray.dir = d;
            const float edge_t = closest_on_segment(p0, p1, o, d);
            const float t_x = dot(p0 + (p1 - p0) * edge_t - o, d);
            EdgeSide first_u, first_l;
            if (!edge_sides(scene, side_eye, edge, ray, edge_t, t_x, first_u, first_l)) return;
            // The channels' values on both sides.
            Pending& pd = pending[size_t(npending)];
            if (hit_values) {
                eval_hit_channels(scene, layout, first_u.ray, first_u.found, first_u.hit, pd.value_u);
                eval_hit_channels(scene, layout, first_l.ray, first_l.found, first_l.hit, pd.value_l);
            }
            pd.place(edge, x, y, eye, g, float(point_weight / glen));
            if (radiance) {
                // Both side paths with the same stream: trace_path's radiance from each side's
                // ray and hit.
                const Rng stream = Rng::for_sample(seed, uint64_t(i), 1);
                const EdgeSide* side[2] = {&first_u, &first_l};
                for (int s = 0; s < 2; ++s) {
                    CameraSample& cs = sides[size_t(2 * npending + s)];
                    cs.rng = stream;
                    cs.ray = side[s]->ray;
                    cs.first = *side[s];
                    cs.outside = false;
                }
            }
            if (++npending == batch) flush();
        };
        // Whether `ray` meets a face of plane `plane` first (`hide`: past hidden emitters), smooth
        // and not met edge-on (then its shading normal is bent, bend_normal: no plane's mirror or
        // pane); its point, material and vertices tv, its mesh and vertex indices into `face`.
        auto meets_face = [&](const Ray& ray, bool hide, int plane, SurfacePoint& sp, BsdfParams& bp, Vec3f* tv,
                              Pending::Face& face) {
            const FirstHit at = first_hit(scene, ray, hide, Tracing::Exact);
            if (!at.found || smooth_planes.plane_of[size_t(at.hit.mesh)].empty() ||
                smooth_planes.plane_of[size_t(at.hit.mesh)][size_t(at.hit.prim)] != plane)
                return false;
            sp = scene.surface_point(at.hit);
            bp = scene.bsdf_params(sp);
            const Mesh& fm = scene.meshes[size_t(at.hit.mesh)];
            face.mesh = at.hit.mesh;
            for (int c = 0; c < 3; ++c) {
                face.tri[c] = fm.indices[3 * at.hit.prim + c];
                tv[c] = fm.vertex(face.tri[c]);
            }
            return bp.kind != MaterialKind::Standard && !bp.rough && std::abs(dot(ray.dir, sp.ng)) >= kMinShadingCosine;
        };
        // The camera ray (o, d) through film point (x, y) from `eye`.
        auto eye_ray = [&](const Eye& eye, float x, float y, Vec3f& o, Vec3f& d) {
            camera_ray(scene.camera_params, x, y, eye.lu, eye.lv, o, d);
            Ray ray;
            ray.origin = o;
            ray.dir = d;
            return ray;
        };
        // The same as meets_face for the camera ray through film point (x, y) from `eye` (o, d),
        // into pd's first face.
        auto meets_plane = [&](const Eye& eye, float x, float y, int plane, Vec3f& o, Vec3f& d, SurfacePoint& sp,
                               BsdfParams& bp, Vec3f* tv, Pending& pd) {
            return meets_face(eye_ray(eye, x, y, o, d), opt.hide_emitters, plane, sp, bp, tv, pd.faces[0]);
        };
        // A face's adjoints for the adjoints dq, dn of its plane: q its first vertex, n =
        // cross_normal(u, v) of its edges u, v from there (d_cross_normal gives the adjoint of
        // c = cross(u, v)).
        auto set_face_adjoints = [&](Pending::Face& face, const Vec3f& u, const Vec3f& v, const Vec3f& dq,
                                     const Vec3f& dn) {
            const Vec3f dc = d_cross_normal(u, v, dn);
            const Vec3f du = cross(v, dc), dv = cross(dc, u);
            face.dv[0] = dq - du - dv;
            face.dv[1] = du;
            face.dv[2] = dv;
        };
        // Through a face of plane (q, n) met by the ray o + t d at x, scattered into the direction
        // dir by the delta lobe dp (`refract`): the adjoints of o and d (into do_, dd_) and of the
        // face's plane and index (into `face`, its edges u, v) for the adjoints ax of x and adir
        // of dir. x = o + t d, t = (q - o) . n / (d . n).
        auto scatter_adjoints = [&](const DeltaParams<float>& dp, const Vec3f& q, const Vec3f& u, const Vec3f& v,
                                    const Vec3f& n, const Vec3f& o, const Vec3f& d, bool refract, Vec3f ax,
                                    Vec3f adir, Pending::Face& face, Vec3f& do_, Vec3f& dd_) {
            const float dn = dot(d, n), t = dot(q - o, n) / dn;
            const Vec3f x = o + d * t;
            DDelta<float> dd;
            dd.specular = dd.n = dd.wo = Vec3f(0.f);
            dd.eta = 0.f;
            d_delta_scatter(dp, n, -d, refract, 1.f, adir, Vec3f(0.f), dd);
            const float k = dot(d, ax) / dn;
            do_ = ax - n * k;
            dd_ = do_ * t - dd.wo;
            set_face_adjoints(face, u, v, n * k, (q - x) * k + dd.n);
            face.deta = dd.eta;
            face.material = refract ? scene.meshes[size_t(face.mesh)].material : -1;
        };
        // The rest of a sample seen in a mirror or through glass, given its side function g, the
        // norm of g's film gradient glen (nothing where that is not positive) and the film length
        // the sample stands for: the edge's point at parameter s, which the scattered direction
        // `dir` from the face's point sp passes; its two sides, found from there as from an eye
        // (`swap`: the upper and lower sides exchanged, as a reflection does); their paths, traced
        // from there with options `side_opt` and the sample's stream after the pending samples
        // (the sink gets its additions in the samples' order); and the jump, the lobe's weight
        // (`lobe`: through a chain, both faces') times theirs, splatted.
        auto finish_smooth = [&](int64_t i, Pending& pd, const Edge& edge, const Eye& eye, float x, float y,
                                 const EdgeSideGradient& g, double point_weight, double glen, const SurfacePoint& sp,
                                 float s, const Vec3f& dir, const Vec3f& lobe, bool swap,
                                 const RenderOptions& side_opt) {
            if (!(glen > 0.0) || !std::isfinite(glen)) return;
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f target = m.vertex(edge.v0) + (m.vertex(edge.v1) - m.vertex(edge.v0)) * s;
            Ray out = spawn_ray(sp, normalize(target - sp.p));
            out.dir = normalize(target - out.origin);
            // (Off the scattered direction by more than rounding: the plane's faces disagree.)
            if (!(dot(out.dir, dir) > 0.9999f)) return;
            EdgeEye face_eye;
            face_eye.origin = out.origin;
            EdgeSide upper, lower;
            if (!edge_sides(scene, face_eye, edge, out, s, dot(target - out.origin, out.dir), upper, lower)) return;
            if (swap) std::swap(upper, lower);
            flush();
            const Rng stream = Rng::for_sample(seed, uint64_t(i), 1);
            Rng ru = stream, rl = stream;
            const Vec3f Lu = trace_path(scene, side_opt, upper.ray, ru, counters, nullptr, &upper);
            const Vec3f Ll = trace_path(scene, side_opt, lower.ray, rl, counters, nullptr, &lower);
            pd.place(edge, x, y, eye, g, float(point_weight / glen));
            std::fill(pd.value_u, pd.value_u + nv, 0.f);
            std::fill(pd.value_l, pd.value_l + nv, 0.f);
            finish(pd, lobe * (Lu - Ll));
        };
        // The boundary term of the virtual edge of `edge` in mirror plane `plane` at film point
        // (x, y) (SmoothPlanes, above): where the camera ray meets a face of that plane and is
        // reflected past the edge. The side function is the virtual edge's, across the plane of
        // the face met (the plane's faces may differ from it by rounding); a reflection turns its
        // sign, so the virtual edge's upper side is the edge's lower one seen from the mirror.
        auto splat_mirrored = [&](int64_t i, const Eye& eye, const Edge& edge, int plane, float x, float y,
                                  double point_weight) {
            Vec3f o, d, reflected, lobe, tv[3];
            SurfacePoint sp;
            BsdfParams bp;
            Pending pd;
            if (!meets_plane(eye, x, y, plane, o, d, sp, bp, tv, pd) ||
                !delta_scatter(delta_params(bp), sp.ng, -d, false, 1.f, reflected, lobe))
                return;
            const Vec3f u = tv[1] - tv[0], v = tv[2] - tv[0], n = cross_normal(u, v);
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f p0 = m.vertex(edge.v0), p1 = m.vertex(edge.v1);
            const Vec3f v0 = mirrored(p0, tv[0], n), v1 = mirrored(p1, tv[0], n);
            // The virtual edge's side function; its edge part taken back through the mirroring to
            // the edge's vertices and the face's plane.
            EdgeSideGradient g = edge_side_gradient(v0, v1, o, d);
            const Vec3f a0 = g.d_e0, a1 = g.d_e1;
            Vec3f dq(0.f), dn(0.f);
            g.d_e0 = g.d_e1 = Vec3f(0.f);
            d_mirrored(p0, tv[0], n, a0, g.d_e0, dq, dn);
            d_mirrored(p1, tv[0], n, a1, g.d_e1, dq, dn);
            set_face_adjoints(pd.faces[0], u, v, dq, dn);
            finish_smooth(i, pd, edge, eye, x, y, g, point_weight, film_gradient_norm(x, y, eye, d, g), sp,
                          closest_on_segment(v0, v1, o, d), reflected, lobe, true, reflected_opt);
        };
        // The boundary term of the edge `edge` seen through plane `plane` at film point (x, y)
        // (Refraction, above): where the camera ray meets a face of that plane and is refracted
        // past the edge. The side function is the refracted ray's; its gradient reaches the
        // camera ray through the point of the face's plane it meets and the refraction
        // (d_delta_scatter), and the face's vertices and index likewise.
        auto splat_refracted = [&](int64_t i, const Eye& eye, const Edge& edge, int plane, float x, float y,
                                   double point_weight) {
            Vec3f o, d, refracted, lobe, tv[3];
            SurfacePoint sp;
            BsdfParams bp;
            Pending pd;
            if (!meets_plane(eye, x, y, plane, o, d, sp, bp, tv, pd) || bp.kind != MaterialKind::Dielectric) return;
            const Vec3f u = tv[1] - tv[0], v = tv[2] - tv[0], n = cross_normal(u, v);
            const DeltaParams<float> dp = delta_params(bp);
            if (!delta_scatter(dp, n, -d, true, 1.f, refracted, lobe)) return;
            // The point of the face's plane the camera ray meets, x = o + t d.
            const float tp = dot(tv[0] - o, n) / dot(d, n);
            const Vec3f xh = o + d * tp;
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f p0 = m.vertex(edge.v0), p1 = m.vertex(edge.v1);
            EdgeSideGradient g = edge_side_gradient(p0, p1, xh, refracted);
            // x's and the refracted direction's adjoints to the camera ray, the face and the index.
            scatter_adjoints(dp, tv[0], u, v, n, o, d, true, g.d_o, g.d_d, pd.faces[0], g.d_o, g.d_d);
            finish_smooth(i, pd, edge, eye, x, y, g, point_weight, film_gradient_norm(x, y, eye, d, g), sp,
                          closest_on_segment(p0, p1, xh, refracted), refracted, lobe, false, reflected_opt);
        };
        // The boundary term of the edge `edge` seen through chain `chain` at film point (x, y)
        // (Chain, above): where the camera ray meets a face of its first plane, is turned there,
        // meets a face of its second plane first, and is turned there past the edge. The side
        // function is the last ray's; its gradient reaches the camera ray back through both
        // faces' points and lobes, and both faces' vertices (and indices) likewise.
        auto splat_chained = [&](int64_t i, const Eye& eye, const Edge& edge, const Chain& chain, float x, float y,
                                 double point_weight) {
            Vec3f o, d, tv[2][3], lobe[2];
            SurfacePoint sp[2];
            BsdfParams bp;
            Pending pd;
            DeltaParams<float> dp[2];
            Vec3f dir[3], from[3], u[2], v[2], n[2];
            if (!meets_plane(eye, x, y, chain.plane[0], o, d, sp[0], bp, tv[0], pd)) return;
            from[0] = o;
            dir[0] = d;
            for (int k = 0; k < 2; ++k) {
                if (k == 1) {
                    Ray ray = spawn_ray(sp[0], dir[1]);
                    if (!meets_face(ray, false, chain.plane[1], sp[1], bp, tv[1], pd.faces[1])) return;
                }
                dp[k] = delta_params(bp);
                if (chain.refract[k] && bp.kind != MaterialKind::Dielectric) return;
                u[k] = tv[k][1] - tv[k][0], v[k] = tv[k][2] - tv[k][0], n[k] = cross_normal(u[k], v[k]);
                if (!delta_scatter(dp[k], n[k], -dir[k], chain.refract[k], 1.f, dir[k + 1], lobe[k])) return;
                // The point of the face's plane the ray meets.
                from[k + 1] = from[k] + dir[k] * (dot(tv[k][0] - from[k], n[k]) / dot(dir[k], n[k]));
            }
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f p0 = m.vertex(edge.v0), p1 = m.vertex(edge.v1);
            EdgeSideGradient g = edge_side_gradient(p0, p1, from[2], dir[2]);
            // Back through the second face, then the first: the adjoints of each ray's origin and
            // direction in turn.
            for (int k = 1; k >= 0; --k)
                scatter_adjoints(dp[k], tv[k][0], u[k], v[k], n[k], from[k], dir[k], chain.refract[k], g.d_o, g.d_d,
                                 pd.faces[k], g.d_o, g.d_d);
            finish_smooth(i, pd, edge, eye, x, y, g, point_weight, film_gradient_norm(x, y, eye, d, g), sp[1],
                          closest_on_segment(p0, p1, from[2], dir[2]), dir[2], lobe[0] * lobe[1], false, chained_opt);
        };
        // A ray (o, d) met by curved face cf and turned there as the renderer turns it (the
        // interpolated normal, normalised and bent, the lobe, delta_side): the face's corners and
        // normals, the point x met, the bent normal and the turned direction `dir`, with what
        // turn_back needs.
        struct Turn {
            Vec3f tv[3], N[3], o, d, u, v, ng, wo, Ns, ns, nb, turned, x, dir, lobe;
            TriangleHit<float> th;
            DeltaParams<float> dp;
            float side = 1.f;
        };
        // Turns (o, d) at face cf met there (material bp), its indices into `face`; false where the
        // ray misses the face's triangle or the lobe does not exist.
        auto turn_at = [&](const CurvedFace& cf, const BsdfParams& bp, const Vec3f& o, const Vec3f& d, Turn& tr,
                           Pending::Face& face) {
            const Mesh& fm = scene.meshes[size_t(cf.mesh)];
            face.mesh = cf.mesh;
            face.normals = true;
            for (int c = 0; c < 3; ++c) {
                face.tri[c] = fm.indices[3 * cf.prim + c];
                face.normal_tri[c] = fm.normal_indices[3 * cf.prim + c];
                tr.tv[c] = fm.vertex(face.tri[c]);
                tr.N[c] = Vec3f::load(fm.normals + 3 * face.normal_tri[c]);
            }
            // The face's point, its normal and the turned ray.
            if (!intersect_triangle(o, d, tr.tv[0], tr.tv[1], tr.tv[2], tr.th)) return false;
            tr.o = o, tr.d = d;
            tr.x = o + d * tr.th.t;
            tr.u = tr.tv[1] - tr.tv[0], tr.v = tr.tv[2] - tr.tv[0], tr.ng = cross_normal(tr.u, tr.v), tr.wo = -d;
            tr.Ns = tr.N[0] * (1.f - tr.th.b1 - tr.th.b2) + tr.N[1] * tr.th.b1 + tr.N[2] * tr.th.b2;
            if (!(length(tr.Ns) > 0.f)) return false;
            tr.ns = normalize(tr.Ns), tr.nb = bend_normal(tr.ns, tr.ng, tr.wo);
            tr.dp = delta_params(bp);
            if (!delta_scatter(tr.dp, tr.nb, tr.wo, cf.refract, 1.f, tr.turned, tr.lobe)) return false;
            tr.side = delta_side_sign(tr.wo, tr.ng, cf.refract);
            tr.dir = delta_side(tr.turned, tr.ng, tr.side);
            face.material = cf.refract ? fm.material : -1;
            return true;
        };
        // The adjoints of the ray (a_o, a_d) and of the face's vertices, normals and index (into
        // `face`) for the adjoints a_x of the point met and a_dir of the turned direction: back
        // through delta_side, the lobe, the bend and the normalised interpolation, and x = o + t d
        // with (t, b1, b2) from the ray and the face (d_intersect_triangle).
        auto turn_back = [&](const CurvedFace& cf, const Turn& tr, Vec3f a_x, Vec3f a_dir, Pending::Face& face,
                             Vec3f& a_o, Vec3f& a_d) {
            Vec3f a_turned(0.f), a_ng(0.f), a_ns(0.f);
            d_delta_side(tr.turned, tr.ng, tr.side, a_dir, a_turned, a_ng);
            DDelta<float> dd;
            dd.specular = dd.n = dd.wo = Vec3f(0.f);
            dd.eta = 0.f;
            d_delta_scatter(tr.dp, tr.nb, tr.wo, cf.refract, 1.f, a_turned, Vec3f(0.f), dd);
            Vec3f a_wo = dd.wo;
            d_bend_normal(tr.ns, tr.ng, tr.wo, dd.n, a_ns, a_wo);
            const Vec3f a_N = d_normalize(tr.Ns, a_ns);
            face.dn[0] = a_N * (1.f - tr.th.b1 - tr.th.b2);
            face.dn[1] = a_N * tr.th.b1;
            face.dn[2] = a_N * tr.th.b2;
            DTriangle<float> dt;
            d_intersect_triangle(tr.o, tr.d, tr.tv[0], tr.tv[1], tr.tv[2], tr.th, dot(a_x, tr.d),
                                 dot(a_N, tr.N[1] - tr.N[0]), dot(a_N, tr.N[2] - tr.N[0]), dt);
            a_o = a_x + dt.o;
            a_d = a_x * tr.th.t - a_wo + dt.d;
            // The geometric normal's adjoint (delta_side's) to the vertices through its cross
            // product, beside the point's.
            set_face_adjoints(face, tr.u, tr.v, Vec3f(0.f), a_ng);
            face.dv[0] += dt.v0;
            face.dv[1] += dt.v1;
            face.dv[2] += dt.v2;
            face.deta = dd.eta;
        };
        // Whether `ray` meets face cf first (`hide`: past hidden emitters), smooth, with a lobe of
        // cf's kind; its point and material.
        auto meets_curved = [&](const Ray& ray, bool hide, const CurvedFace& cf, SurfacePoint& sp, BsdfParams& bp) {
            const FirstHit hit = first_hit(scene, ray, hide, Tracing::Exact);
            if (!hit.found || hit.hit.mesh != cf.mesh || hit.hit.prim != cf.prim) return false;
            sp = scene.surface_point(hit.hit);
            bp = scene.bsdf_params(sp);
            return bp.kind != MaterialKind::Standard && !bp.rough &&
                   (!cf.refract || bp.kind == MaterialKind::Dielectric);
        };
        // The boundary term of the edge `edge` seen in or through curved face cf at film point
        // (x, y) (CurvedFace, above): where the camera ray meets that face first and is turned
        // there past the edge, as the renderer turns it. The side function is the turned ray's;
        // its gradient reaches the camera ray through the face's point (its distance and
        // barycentrics) and the turning, and the face's vertices, shading normals and index
        // likewise.
        auto splat_curved = [&](int64_t i, const Eye& eye, const Edge& edge, const CurvedFace& cf, float x, float y,
                                double point_weight) {
            Vec3f o, d;
            SurfacePoint sp;
            BsdfParams bp;
            Pending pd;
            Turn tr;
            if (!meets_curved(eye_ray(eye, x, y, o, d), opt.hide_emitters, cf, sp, bp) ||
                !turn_at(cf, bp, o, d, tr, pd.faces[0]))
                return;
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f p0 = m.vertex(edge.v0), p1 = m.vertex(edge.v1);
            EdgeSideGradient g = edge_side_gradient(p0, p1, tr.x, tr.dir);
            turn_back(cf, tr, g.d_o, g.d_d, pd.faces[0], g.d_o, g.d_d);
            finish_smooth(i, pd, edge, eye, x, y, g, point_weight, film_gradient_norm(x, y, eye, d, g), sp,
                          closest_on_segment(p0, p1, tr.x, tr.dir), tr.dir, tr.lobe, false, reflected_opt);
        };
        // The same through the pair of curved faces cp (CurvedPair, above): where the camera ray
        // meets its first face first, and the ray turned there its second face first. The
        // gradient goes back through the second face, then the first.
        auto splat_pair = [&](int64_t i, const Eye& eye, const Edge& edge, const CurvedPair& cp, float x, float y,
                              double point_weight) {
            Vec3f o, d;
            SurfacePoint sp[2];
            BsdfParams bp;
            Pending pd;
            Turn tr[2];
            if (!meets_curved(eye_ray(eye, x, y, o, d), opt.hide_emitters, cp.face[0], sp[0], bp) ||
                !turn_at(cp.face[0], bp, o, d, tr[0], pd.faces[0]))
                return;
            if (!meets_curved(spawn_ray(sp[0], tr[0].dir), false, cp.face[1], sp[1], bp) ||
                !turn_at(cp.face[1], bp, tr[0].x, tr[0].dir, tr[1], pd.faces[1]))
                return;
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f p0 = m.vertex(edge.v0), p1 = m.vertex(edge.v1);
            EdgeSideGradient g = edge_side_gradient(p0, p1, tr[1].x, tr[1].dir);
            for (int k = 1; k >= 0; --k) turn_back(cp.face[k], tr[k], g.d_o, g.d_d, pd.faces[k], g.d_o, g.d_d);
            finish_smooth(i, pd, edge, eye, x, y, g, point_weight, film_gradient_norm(x, y, eye, d, g), sp[1],
                          closest_on_segment(p0, p1, tr[1].x, tr[1].dir), tr[1].dir, tr[0].lobe * tr[1].lobe, false,
                          chained_opt);
        };
        for (int64_t i = begin; i < end; ++i) {
            Rng rng = Rng::for_sample(seed, uint64_t(i), 0);
            const bool direct = i < n_direct;
            const int64_t j = direct ? i : i - n_direct;
            const double total = direct ? total_direct : total_smooth;
            const double sample_weight = direct ? weight_direct : weight_smooth;
            const double at = (direct ? 0.0 : total_direct) +
                              (uniform ? rng.next_double() : (double(j) + rng.next_double()) / double(n)) * total;
            const size_t k = std::clamp(size_t(std::upper_bound(cumulative.begin(), cumulative.end(), at) -
                                               cumulative.begin()) - 1,
                                        direct ? size_t(0) : num_direct, (direct ? num_direct : num_film) - 1);
            const FilmEdge& fe = film_edge(k);
            const double t = std::clamp((at - cumulative[k]) / fe.len, 0.0, 1.0);
            const Edge& edge = scene.edges()[fe.edge];
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f p0 = m.vertex(edge.v0), p1 = m.vertex(edge.v1);
            float x, y;
            double point_weight = sample_weight / fe.weight;
            // A thin lens: this sample's lens point, the eye the sample sees the edge from.
            const Eye eye = thin_lens ? lens_eye(cam, rng.next_float(), rng.next_float()) : centre;
            if (fe.chain >= 0 || fe.refracted || fe.curved >= 0 || fe.pair >= 0) {
                // At parameter u of the edge (its part beyond the plane, past the chain's second
                // plane, or the curved face's or pair's part), as the eye sees it through the plane,
                // the chain, the curved face or the pair, weighted by
                // the film length per unit of t there: a central difference quotient 1e-4 wide.
                // (Through a chain each solve near t starts from t's.)
                const Vec3d a(p0), b(p1);
                const double span = fe.u1 - fe.u0;
                const Chain* ch = fe.chain >= 0 ? &chains[size_t(fe.chain)] : nullptr;
                const CurvedFace* cf = fe.curved >= 0 ? &curved[size_t(fe.curved)] : nullptr;
                const CurvedPair* cp = fe.pair >= 0 ? &pairs[size_t(fe.pair)] : nullptr;
                Vec3d at_t, x1, x2;
                auto film_at = [&](double tt, bool near_t, double& fx, double& fy) {
                    const Vec3d e = a + (b - a) * (fe.u0 + span * tt);
                    if (cf || cp) {
                        // (From the line between the part's ends' points, near t from t's point.)
                        double b1 = near_t ? at_t.x : fe.ax + (fe.bx - fe.ax) * tt;
                        double b2 = near_t ? at_t.y : fe.ay + (fe.by - fe.ay) * tt;
                        double c1, c2;
                        bool inside;
                        if (!(cf ? curved_film(*cf, eye, e, true, near_t ? 0 : 4, b1, b2, fx, fy)
                                 : pair_film(*cp, eye, e, near_t ? 0 : 9, b1, b2, fx, fy, c1, c2, inside)))
                            return false;
                        if (!near_t) at_t = Vec3d(b1, b2, 0.0);
                        return true;
                    }
                    if (!ch) return refracted_film(smooth_planes.planes[size_t(fe.plane)], eye, e, fx, fy);
                    x1 = at_t;
                    if (!chain_film(*ch, eye, e, near_t, x1, x2, fx, fy)) return false;
                    if (!near_t) at_t = x1;
                    return true;
                };
                double fx, fy, lx, ly, hx, hy;
                if (!film_at(t, false, fx, fy) || fx < wx0 || fx > wx1 || fy < wy0 || fy > wy1) continue;
                const double lo_t = std::max(0.0, t - 1e-4), hi_t = std::min(1.0, t + 1e-4);
                if (!film_at(lo_t, true, lx, ly) || !film_at(hi_t, true, hx, hy)) continue;
                const double per_t = std::hypot(hx - lx, hy - ly) / (hi_t - lo_t);
                const double w = sample_weight * per_t / fe.len / fe.kept;
                if (cf)
                    splat_curved(i, eye, edge, *cf, float(fx), float(fy), w);
                else if (cp)
                    splat_pair(i, eye, edge, *cp, float(fx), float(fy), w);
                else if (ch)
                    splat_chained(i, eye, edge, *ch, float(fx), float(fy), w);
                else
                    splat_refracted(i, eye, edge, fe.plane, float(fx), float(fy), w);
                continue;
            }
            if (spherical) {
                // Drawn with density fe.len / total / world per unit world length; the film
                // points that see it get its film length per unit world length (in splat).
                const Vec3f p = p0 + (p1 - p0) * float(t);
                double fx, fy;
                if (!spherical_film_point(cam, normalize(p - cam.position), fx, fy)) continue;
                const double w = sample_weight * fe.world / fe.len;
                if (cam.type == CameraType::Panorama) {
                    // The film's images of the point: longitude wraps every W pixels, and rows past
                    // a pole see the other half of the sphere (mirrored, half a turn around): a
                    // filter reaching past the film's sides or rows sees these.
                    const double W = cam.width, H = cam.height;
                    const double rows[3][2] = {{fy, 0.0}, {-fy, 0.5 * W}, {2.0 * H - fy, 0.5 * W}};
                    for (const auto& row : rows)
                        for (int wrap = -2; wrap <= 2; ++wrap) {
                            const double ix = fx + row[1] + wrap * W, iy = row[0];
                            if (ix < wx0 || ix > wx1 || iy < wy0 || iy > wy1) continue;
                            splat(i, eye, edge, p0, p1, float(ix), float(iy), w, &p);
                        }
                } else if (fx >= wx0 && fx <= wx1 && fy >= wy0 && fy <= wy1 && cam.sees(float(fx), float(fy))) {
                    splat(i, eye, edge, p0, p1, float(fx), float(fy), w, &p);
                }
                continue;
            }
            if (uniform) {
                double fx, fy, jacobian;
                if (!film_point(cam, eye, p0 + (p1 - p0) * float(t), normalize(p1 - p0), fx, fy, jacobian)) continue;
                if (fx < wx0 || fx > wx1 || fy < wy0 || fy > wy1) continue;
                x = float(fx);
                y = float(fy);
                point_weight *= jacobian;
            } else {
                x = float(fe.ax + (fe.bx - fe.ax) * t);
                y = float(fe.ay + (fe.by - fe.ay) * t);
                if (thin_lens) {
                    // The edge point the camera's position sees there, seen from the lens point:
                    // drawn with density 1 / total per unit film length from the position, it
                    // has density (jacobian_centre / jacobian_lens) / total per unit film length
                    // from the lens point. (Seen in a mirror: the virtual edge's.)
                    Vec3f e0 = p0, e1 = p1;
                    if (fe.plane >= 0) {
                        const SmoothPlane& mp = smooth_planes.planes[size_t(fe.plane)];
                        e0 = mirrored(p0, mp.q, mp.n);
                        e1 = mirrored(p1, mp.q, mp.n);
                    }
                    const Vec2f sc = cam.screen(x, y);
                    const Vec3f dir = normalize(e1 - e0);
                    const Vec3f p = e0 + (e1 - e0) * closest_on_segment(e0, e1, cam.position,
                                                                        normalize(cam.forward + cam.right * sc.x + cam.up * sc.y));
                    double fx, fy, j_lens, cx, cy, j_centre;
                    if (!film_point(cam, eye, p, dir, fx, fy, j_lens) || !film_point(cam, centre, p, dir, cx, cy, j_centre))
                        continue;
                    if (fx < wx0 || fx > wx1 || fy < wy0 || fy > wy1 || !(j_centre > 0.0)) continue;
                    x = float(fx);
                    y = float(fy);
                    point_weight *= j_lens / j_centre;
                }
            }
            if (fe.plane >= 0) {
                splat_mirrored(i, eye, edge, fe.plane, x, y, point_weight);
                continue;
            }
            splat(i, eye, edge, p0, p1, x, y, point_weight, nullptr);
        }
        flush();
        sink.commit(adds, begin / kSampleChunk);
    });
}

}  // namespace edgepath
