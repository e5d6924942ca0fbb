#include "edges/hierarchy.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif
#include <tbb/blocked_range.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include "math/simd4.h"
#include "scene/chunks.h"
#include "scene/scene.h"

namespace edgepath {

namespace {

float sine(float cosine) { return std::sqrt(std::max(0.f, 1.f - cosine * cosine)); }
// cos(max(0, angle - beta)) from cos(angle) and beta's cosine and sine: the largest cosine
// between a direction and the directions within beta of another.
float cos_minus(float cos_a, float cos_b, float sin_b) {
    return cos_a >= cos_b ? 1.f : cos_a * cos_b + sine(cos_a) * sin_b;
}
// A crease seen with both faces on the same side of p: its share of a silhouette's importance,
// the angle between the faces' normals (radians). A seam (Edge::seam: uvs, colours or split
// normals differ) no less than kMinSeamWeight, whatever the angle: textures may jump along it.
// A crease of flat shading jumps by the angle alone: no less than kMinCreaseWeight, which only
// keeps the density positive (the angle of nearly flat faces is lost to rounding). (With the
// seams' floor for every crease, the float rounding of flat-shaded emitters, a sun's disk or a
// tessellated sphere light, made thousands of nearly flat creases that drew samples where
// nothing jumps.)
constexpr float kMinSeamWeight = 0.05f, kMinCreaseWeight = 1e-3f;
float crease_weight(float dihedral, bool seam) {
    return std::clamp(dihedral, seam ? kMinSeamWeight : kMinCreaseWeight, 1.f);
}
// Ranges larger than this are split in parallel.
constexpr int kParallelRange = 8192;
// When a descent splits (EdgeHierarchy::splits): the light cone's cos(half angle) above which it
// is narrow; children comparable when the smaller importance is at least this share of the
// larger, large when together at least this share of the root's.
constexpr float kNarrowCone = 0.95f, kComparable = 0.25f, kLarge = 0.25f;
bool bitwise_equal(const Vec3f& a, const Vec3f& b) { return std::memcmp(&a, &b, sizeof(Vec3f)) == 0; }

}  // namespace

// ---- the lobe bound ---------------------------------------------------------------------------

LobeBound LobeBound::make(const Vec3f& n, const Vec3f& wo, float diffuse, float specular, float alpha) {
    LobeBound b;
    b.n = n;
    const float co = dot(n, wo);
    b.r = n * (2.f * co) - wo;
    b.diffuse = std::max(0.f, diffuse) / kPi;
    if (specular > 0.f) {
        // GGX's peak D = 1 / (pi a^2), times F G / (4 cos_o); near the peak D falls as
        // 1 / (1 + tan^2(theta_h) / a^2)^2 with tan^2(theta_h) ~ (1 - r.w) / 2.
        const float a = std::max(alpha, 0.02f);
        b.specular = specular / (4.f * kPi * a * a * std::max(co, 0.1f));
        b.sharpness = 1.f / (2.f * a * a);
        b.width = kPi * a;  // the integral of 1 / (1 + x^2 / (2 a^2))^2 over the line
    }
    return b;
}

float LobeBound::glossy_share(const BoundsCone& cone) const {
    if (!(specular > 0.f)) return 0.f;
    if (cone.cos_half <= -1.f) return 1.f;  // every direction
    const float angle = std::acos(std::clamp(dot(r, cone.axis), -1.f, 1.f));
    const float q = 1.f + sharpness * (1.f - std::cos(std::max(0.f, angle - cone.half)));
    return 1.f / (q * q);
}

double LobeBound::integral(const Vec3f& p, const Vec3f& v0, const Vec3f& v1, double* h_out) const {
    // The arc: w(phi) = a cos(phi) + b sin(phi), phi in [phi0, phi1] (less than pi apart), with b
    // along the edge and a towards the foot of the perpendicular from p; h the distance to the
    // edge's line. Everything below needs only w and dw/dphi = -a sin(phi) + b cos(phi) at the
    // two ends (no angles): the antiderivatives are written in those.
    const Vec3d q(p.x, p.y, p.z), x0(v0.x, v0.y, v0.z), x1(v1.x, v1.y, v1.z);
    const Vec3d e = x1 - x0;
    const double len = length(e);
    if (h_out) *h_out = 0.0;
    if (!(len > 0.0)) return 0.0;
    const Vec3d b = e / len;
    const double foot = dot(q - x0, b);
    const Vec3d hv = x0 + b * foot - q;
    const double h = length(hv);
    if (h_out) *h_out = h;
    if (!(h > 1e-12 * (len + length(x0 - q)))) return 0.0;
    const Vec3d a = hv / h;
    // The ends: cos and sin of phi0, phi1.
    const double r0 = std::sqrt(h * h + foot * foot), r1 = std::sqrt(h * h + (len - foot) * (len - foot));
    const double c0 = h / r0, s0 = -foot / r0, c1 = h / r1, s1 = (len - foot) / r1;
    const Vec3d w0 = a * c0 + b * s0, w1 = a * c1 + b * s1, d0 = b * c0 - a * s0, d1 = b * c1 - a * s1;
    double total = 0.0;
    // Diffuse: the antiderivative of n . w is -n . dw/dphi, counted where n . w > 0: an arc
    // shorter than pi meets that half circle in one piece, entered (n . w rising through 0)
    // where the antiderivative is -|n_plane| and left where it is +|n_plane|.
    if (diffuse > 0.f) {
        const Vec3d nn(n.x, n.y, n.z);
        const double A = dot(nn, a), B = dot(nn, b), N = std::sqrt(A * A + B * B);
        const bool in0 = dot(nn, w0) > 0.0, in1 = dot(nn, w1) > 0.0;
        if (in0 || in1) total += diffuse * ((in1 ? -dot(nn, d1) : N) - (in0 ? -dot(nn, d0) : -N));
    }
    // Glossy: with r . w = R cos(x), x = phi - psi, the integrand 1 / (1 + s (1 - r . w))^2 is
    // 1 / (A + B cos x)^2, A = 1 + s, B = -s R, whose antiderivative (A > |B|) is
    //   (-B sin x / (A + B cos x) + (2 A / k) atan(c tan(x / 2))) / k^2,
    //   k^2 = A^2 - B^2,  c = sqrt((A - B) / (A + B)).
    // The first term is -s (r . dw/dphi) / (1 + s (1 - r . w)). The second's change along the arc
    // is the angle turned by (cos(x / 2), c sin(x / 2)) as x / 2 goes from x0 / 2 to
    // x0 / 2 + (phi1 - phi0) / 2 (less than pi / 2, so less than pi after the map).
    if (specular > 0.f) {
        const Vec3d rr(r.x, r.y, r.z);
        const double s = sharpness, Ar = dot(rr, a), Br = dot(rr, b), R = std::min(1.0, std::sqrt(Ar * Ar + Br * Br));
        const double k2 = (1.0 + s * (1.0 - R)) * (1.0 + s * (1.0 + R)), k = std::sqrt(k2);
        const double c = std::sqrt((1.0 + s * (1.0 + R)) / (1.0 + s * (1.0 - R)));
        const double rw0 = dot(rr, w0), rw1 = dot(rr, w1);
        const double first = -s * dot(rr, d1) / (1.0 + s * (1.0 - rw1)) + s * dot(rr, d0) / (1.0 + s * (1.0 - rw0));
        // Half of x0: cos x0 = r . w0 / R, sin x0 = -r . dw0 / R (any x0 where R = 0).
        const double cx = R > 0.0 ? std::clamp(rw0 / R, -1.0, 1.0) : 1.0, sx = R > 0.0 ? -dot(rr, d0) : 0.0;
        const double ch = std::sqrt(0.5 * (1.0 + cx)), sh = std::copysign(std::sqrt(0.5 * (1.0 - cx)), sx);
        // Half the arc's angle: cos(phi1 - phi0) = w0 . w1.
        const double cd = std::clamp(dot(w0, w1), -1.0, 1.0), chd = std::sqrt(0.5 * (1.0 + cd)), shd = std::sqrt(0.5 * (1.0 - cd));
        const double ch1 = ch * chd - sh * shd, sh1 = sh * chd + ch * shd;
        const double turned = std::atan2(c * shd, ch * ch1 + c * c * sh * sh1);
        total += specular * std::max(0.0, (first + (2.0 * (1.0 + s) / k) * turned) / k2);
    }
    return total;
}

bool BoundsCone::towards(const Vec3f& p, const Vec3f& c, float r) {
    const Vec3f v = c - p;
    const float d = length(v);
    if (!(d > r)) {
        cos_half = -1.f;
        half = kPi;
        return false;
    }
    axis = v / d;
    half = std::asin(std::min(1.f, r / d));
    cos_half = std::cos(half);
    return true;
}

// ---- building ---------------------------------------------------------------------------------

EdgeHierarchy::LeafInput EdgeHierarchy::leaf_input(const Scene& scene, const Edge& e) {
    LeafInput in;
    const Mesh& m = scene.meshes[size_t(e.mesh)];
    in.p0 = m.vertex(e.v0);
    in.p1 = m.vertex(e.v1);
    if (e.flat) in.p0 = in.p1 = (in.p0 + in.p1) * 0.5f;  // an empty leaf (Edge::flat): never sampled
    in.always = e.kind != EdgeKind::Smooth;
    // An edge between faces that are black seen from behind (a one-sided material, no
    // emission from the back): from a point behind both, either side of it looks black
    // (or both sides see what hides it), so it adds nothing there.
    in.crease = e.kind == EdgeKind::Crease;
    in.seam = in.crease && e.seam;
    in.dark_behind = e.kind != EdgeKind::Boundary && scene.dark_behind(m);
    in.emissive = m.is_emitter();
    in.n0 = in.n1 = Vec3f(0.f);
    if (!in.always || in.crease) {
        // The faces' unit normals, as the scene keeps them (unit_face_normal(f), the face
        // normal itself where its length is 0: one read for each face).
        const Vec3f a = m.triangle_data[e.f0].ng, b = m.triangle_data[e.f1].ng;
        // A face of zero area has no side: its edge is treated as a discontinuity.
        if (length(a) > 0.f && length(b) > 0.f) {
            in.n0 = a;
            in.n1 = b;
        } else {
            in.always = true;
            in.dark_behind = false;
            in.crease = false;
            in.seam = false;
        }
    }
    return in;
}

// What the build needs of the edges `ids` (indices into scene.edges()), in their order.
struct EdgeHierarchy::Input {
    std::vector<LeafInput> leaf;
    const std::vector<int32_t>* ids;
    int32_t id(size_t k) const { return (*ids)[k]; }

    Input(const Scene& scene, const std::vector<int32_t>& edges) : ids(&edges) {
        const std::vector<Edge>& all = scene.edges();
        const size_t n = edges.size();
        leaf.resize(n);
        over_chunks(int64_t(n), kParallelRange, [&](int64_t b, int64_t e) {
            for (size_t i = size_t(b); i < size_t(e); ++i) leaf[i] = leaf_input(scene, all[size_t(edges[i])]);
        });
    }
};

void EdgeHierarchy::ConeInput::resize(size_t n) {
    for (std::vector<float>& c : v) c.resize(n);
}

void EdgeHierarchy::ConeInput::set(size_t k, const LeafInput& in) {
    const Vec3f* from[3] = {&in.n0, &in.n1, &in.p0};
    for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) v[3 * a + c][k] = (*from[a])[c];
}

void EdgeHierarchy::set_leaf(const LeafInput& in, int32_t edge, Node& node) {
    node.lo = min(in.p0, in.p1);
    node.hi = max(in.p0, in.p1);
    node.length = length(in.p1 - in.p0);
    node.edge = edge;
    node.count = 1;
    node.always = in.always;
    node.center = (node.lo + node.hi) * 0.5f;
    node.radius = length(node.hi - node.lo) * 0.5f;
    node.leaf.a = in.p0;
    node.leaf.b = in.p1;
    node.leaf.n0 = in.n0;
    node.leaf.n1 = in.n1;
    node.dark_behind = in.dark_behind;
    node.emissive = in.emissive;
    node.crease = in.crease;
    node.seam = in.seam;
    node.cone_cos = -1.f;
    node.dihedral = 0.f;
    const Vec3f s = in.n0 + in.n1;
    if ((!node.always || node.crease) && length(s) > 1e-6f) {
        // The cone's axis (the normals' mean) is not kept: a leaf tests its two faces exactly.
        node.cone_cos = std::clamp(dot(normalize(s), in.n0), -1.f, 1.f);
        node.dihedral = 2.f * std::acos(node.cone_cos);
    }
}

// The subtree over items [begin, end) has its root at `index` and its other 2 (end - begin) - 2
// nodes from `next` on: the root's two children side by side (the descents score both), then
// the left child's other nodes, then the right one's; so both halves can be built at once, and
// children come after their parents. The items end up in the order of the leaves (order_),
// each node's from node.first on.
void EdgeHierarchy::build_range(const Input& in, std::vector<int32_t>& items, int begin, int end, int32_t index,
                                int32_t parent, int32_t next) {
    Node& node = nodes_[size_t(index)];
    node.parent = parent;
    node.first = begin;
    if (end - begin == 1) {
        const size_t i = size_t(items[size_t(begin)]);
        set_leaf(in.leaf[i], in.id(i), node);
        cone_in_.set(size_t(begin), in.leaf[i]);  // its place in the leaves' order
        leaf_of_[size_t(node.edge)] = index;
        return;
    }
    // Median split of the centroids along the longest axis of their box.
    Vec3f lo(1e30f), hi(-1e30f);
    for (int k = begin; k < end; ++k) {
        const LeafInput& e = in.leaf[size_t(items[size_t(k)])];
        const Vec3f c = (e.p0 + e.p1) * 0.5f;
        lo = min(lo, c);
        hi = max(hi, c);
    }
    const Vec3f ext = hi - lo;
    const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    const int mid = (begin + end) / 2;
    std::nth_element(items.begin() + begin, items.begin() + mid, items.begin() + end, [&](int32_t a, int32_t b) {
        const LeafInput &ea = in.leaf[size_t(a)], &eb = in.leaf[size_t(b)];
        return (ea.p0[axis] + ea.p1[axis]) < (eb.p0[axis] + eb.p1[axis]);
    });
    const int32_t l = next, r = next + 1;
    node.left = l;
    const int32_t next_l = next + 2, next_r = next + 2 * (mid - begin);
    if (end - begin > kParallelRange)
        tbb::parallel_invoke([&] { build_range(in, items, begin, mid, l, index, next_l); },
                             [&] { build_range(in, items, mid, end, r, index, next_r); });
    else {
        build_range(in, items, begin, mid, l, index, next_l);
        build_range(in, items, mid, end, r, index, next_r);
    }
    finish_inner(index);
    // The children are done: items [begin, end) are in the leaves' order, and so are their
    // cones' inputs.
    if (has_cone(node)) fit_cone(node);
}

// A tight normal cone and the range of the plane equations at the centre, over the faces of the
// node's (smooth) edges, from their inputs in the leaves' order (cone_in_, from node.first on):
// O(n) per node, O(n log n) in all. The axis is the direction of the sum of the normals, which
// finish_inner() adds up from the children's; the least cosine to the axis and the planes' range
// four edges at a time (each lane's products and sums as the scalar dot products make them; a
// least or greatest value is the same whatever the order it is found in).
void EdgeHierarchy::fit_cone(Node& n) const {
    const size_t first = size_t(n.first), end = first + size_t(n.count);
    const float *n0x = cone_in_.v[0].data(), *n0y = cone_in_.v[1].data(), *n0z = cone_in_.v[2].data();
    const float *n1x = cone_in_.v[3].data(), *n1y = cone_in_.v[4].data(), *n1z = cone_in_.v[5].data();
    const float *px = cone_in_.v[6].data(), *py = cone_in_.v[7].data(), *pz = cone_in_.v[8].data();
    const Vec3f sum = n.cone.normals;
    n.cone_cos = -1.f;
    n.cone = Cone();
    n.cone.normals = sum;
    const bool axis = length(sum) > 1e-6f;
    n.cone.axis = axis ? normalize(sum) : Vec3f(0.f, 0.f, 1.f);
    const Vec3f ax = n.cone.axis, c = n.center;
    // The normals' least cosine to the axis and the planes' range, in one sweep.
    auto dot3 = [](auto x0, auto y0, auto z0, auto x1, auto y1, auto z1) { return x0 * x1 + y0 * y1 + z0 * z1; };
    F4 lo4(1.f), plo4(1e30f), phi4(-1e30f);
    size_t i = first;
    for (; i + 4 <= end; i += 4) {
        const F4 ax0 = F4::loadu(n0x + i), ay0 = F4::loadu(n0y + i), az0 = F4::loadu(n0z + i);
        const F4 ax1 = F4::loadu(n1x + i), ay1 = F4::loadu(n1y + i), az1 = F4::loadu(n1z + i);
        if (axis)
            lo4 = min_std(lo4, min_std(dot3(F4(ax.x), F4(ax.y), F4(ax.z), ax0, ay0, az0),
                                       dot3(F4(ax.x), F4(ax.y), F4(ax.z), ax1, ay1, az1)));
        const F4 tx = F4(c.x) - F4::loadu(px + i), ty = F4(c.y) - F4::loadu(py + i), tz = F4(c.z) - F4::loadu(pz + i);
        const F4 a = dot3(ax0, ay0, az0, tx, ty, tz), b = dot3(ax1, ay1, az1, tx, ty, tz);
        plo4 = min_std(plo4, min_std(a, b));
        phi4 = max_std(phi4, max_std(a, b));
    }
    alignas(16) float l[4], pl[4], ph[4];
    lo4.store(l);
    plo4.store(pl);
    phi4.store(ph);
    float lo = std::min(std::min(l[0], l[1]), std::min(l[2], l[3]));
    float plo = std::min(std::min(pl[0], pl[1]), std::min(pl[2], pl[3]));
    float phi = std::max(std::max(ph[0], ph[1]), std::max(ph[2], ph[3]));
    for (; i < end; ++i) {
        if (axis)
            lo = std::min(lo, std::min(dot3(ax.x, ax.y, ax.z, n0x[i], n0y[i], n0z[i]),
                                       dot3(ax.x, ax.y, ax.z, n1x[i], n1y[i], n1z[i])));
        const float tx = c.x - px[i], ty = c.y - py[i], tz = c.z - pz[i];
        const float a = dot3(n0x[i], n0y[i], n0z[i], tx, ty, tz), b = dot3(n1x[i], n1y[i], n1z[i], tx, ty, tz);
        plo = std::min(plo, std::min(a, b));
        phi = std::max(phi, std::max(a, b));
    }
    if (axis) {
        // A little slack for rounding.
        n.cone_cos = std::max(-1.f, lo - 1e-5f);
        n.cone.sin = sine(n.cone_cos);
    }
    const float slack = 1e-5f * (n.radius + length(n.center));
    n.cone.plane_lo = plo - slack;
    n.cone.plane_hi = phi + slack;
}

void EdgeHierarchy::finish_inner(int32_t index) {
    Node& n = nodes_[size_t(index)];
    const Node &a = nodes_[size_t(n.left)], &b = nodes_[size_t(n.right())];
    n.lo = min(a.lo, b.lo);
    n.hi = max(a.hi, b.hi);
    n.center = (n.lo + n.hi) * 0.5f;
    n.radius = length(n.hi - n.lo) * 0.5f;
    n.length = a.length + b.length;
    n.count = a.count + b.count;
    n.always = a.always || b.always;
    n.dark_behind = a.dark_behind && b.dark_behind;
    n.emissive = a.emissive || b.emissive;
    n.crease = a.crease && b.crease;
    n.seam = a.seam || b.seam;
    n.dihedral = n.length > 0.f ? (a.dihedral * a.length + b.dihedral * b.length) / n.length : 0.f;
    n.cone_cos = -1.f;
    // (Summed in a tree, not edge after edge: a chain of additions, each waiting for the last,
    // was a fifth of a refit at a million edges.)
    auto normals = [](const Node& c) { return c.left < 0 ? c.leaf.n0 + c.leaf.n1 : c.cone.normals; };
    const Vec3f sum = normals(a) + normals(b);
    n.cone = Cone();
    n.cone.normals = sum;
}

void EdgeHierarchy::build_kinds(const Input& in, std::vector<int32_t>& items, int begin, int split, int end,
                                int32_t index, int32_t parent, int32_t next) {
    if (split == begin || split == end) {
        build_range(in, items, begin, end, index, parent, next);
        return;
    }
    Node& node = nodes_[size_t(index)];
    node.parent = parent;
    node.first = begin;
    node.mixed = true;  // holds discontinuities: never culled
    node.left = next;
    build_range(in, items, begin, split, next, index, next + 2);
    build_range(in, items, split, end, next + 1, index, next + 2 * (split - begin));
    finish_inner(index);
}

void EdgeHierarchy::build(const Scene& scene, const std::vector<int32_t>& edges, size_t group) {
    const auto start = std::chrono::steady_clock::now();
    const Input in(scene, edges);
    build(scene, in, group);
    build_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void EdgeHierarchy::build(const Scene& scene, const Input& in, size_t group) {
    nodes_.clear();
    key_.clear();  // (the caller's name for the edges, if any, is given again after)
    const std::vector<Edge>& all = scene.edges();
    leaf_of_.assign(all.size(), -1);
    const std::vector<int32_t>& edges = *in.ids;
    const size_t n = edges.size();
    ids_ = edges;
    group_ = group;
    kept_edges_.resize(n);
    for (size_t i = 0; i < n; ++i) kept_edges_[i] = all[size_t(edges[i])];
    // The group's edges, then the others; in each, the discontinuities from everywhere first,
    // then the smooth edges.
    std::vector<int32_t>& items = order_;
    items.clear();
    items.reserve(n);
    const bool everything = n > 0 && group >= n;
    if (everything) group = 0;  // no subtree of their own: the root is theirs
    int splits[2] = {0, 0};
    for (int g = 0; g < 2; ++g) {
        const size_t lo = g == 0 ? 0 : group, hi = g == 0 ? group : n;
        for (size_t i = lo; i < hi; ++i)
            if (in.leaf[i].always) items.push_back(int32_t(i));
        splits[g] = int(items.size());
        for (size_t i = lo; i < hi; ++i)
            if (!in.leaf[i].always) items.push_back(int32_t(i));
    }
    group_root_ = group > 0 ? 1 : (everything ? 0 : -1);
    cone_in_.resize(n);
    if (n > 0) {
        nodes_.resize(2 * n - 1);
        if (group == 0) {
            build_kinds(in, items, 0, splits[1], int(n), 0, -1, 1);
        } else {
            // The group's subtree and the others' under one root.
            const int g = int(group);
            Node& root = nodes_[0];
            root.left = 1;  // the group's subtree at 1 (group_root_), the others' at 2
            root.mixed = true;
            root.first = 0;
            build_kinds(in, items, 0, splits[0], g, 1, 0, 3);
            build_kinds(in, items, g, splits[1], int(n), 2, 0, 2 * g + 1);
            finish_inner(0);
        }
    }
    built_ = true;
}

std::vector<uint8_t> EdgeHierarchy::mesh_flags(const Scene& scene) {
    std::vector<uint8_t> out(scene.meshes.size());
    for (size_t i = 0; i < out.size(); ++i) {
        const Mesh& m = scene.meshes[i];
        out[i] = uint8_t((m.is_emitter() ? 1 : 0) | (scene.dark_behind(m) ? 2 : 0));
    }
    return out;
}

EdgeHierarchy::Update EdgeHierarchy::update(const Scene& scene, const std::vector<int32_t>& edges, size_t group) {
    const auto start = std::chrono::steady_clock::now();
    auto done = [&](Update what) {
        scene_ = &scene;
        version_ = scene.geometry_version();
        mesh_flags_ = mesh_flags(scene);
        ++(what == Update::Built ? stats_.builds : what == Update::Refit ? stats_.refits : stats_.reuses);
        build_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        return what;
    };
    // The scene's geometry as the leaves have it (the other views of a call, or a call that
    // changed materials, lights or the camera only): the flags at most (O(meshes) to check).
    if (holds(scene, edges, group)) {
        if (mesh_flags(scene) != mesh_flags_) refresh_flags(Input(scene, edges));
        return done(Update::Reused);
    }
    const std::vector<Edge>& all = scene.edges();
    const size_t n = edges.size();
    // The same edges (the same ends, faces and kinds) in the same groups: the same tree.
    // (Each check over the edges in chunks, in parallel where there are many: a million edges
    // took tens of milliseconds a step one by one.)
    struct Found {
        bool same = true, moved = false, flags = false;
        Found operator+(const Found& o) const { return {same && o.same, moved || o.moved, flags || o.flags}; }
    };
    auto over = [&](size_t count, auto&& check) {
        auto chunk = [&](const tbb::blocked_range<size_t>& r, Found f) {
            for (size_t i = r.begin(); i < r.end() && f.same; ++i) check(i, f);
            return f;
        };
        if (n <= size_t(kParallelRange)) return chunk(tbb::blocked_range<size_t>(0, count), Found());
        return tbb::parallel_reduce(tbb::blocked_range<size_t>(0, count, 16384), Found(), chunk, std::plus<Found>());
    };
    bool same = built_ && group == group_ && edges == ids_ && leaf_of_.size() == all.size();
    if (same)
        same = over(n, [&](size_t i, Found& f) {
                   const Edge &e = all[size_t(edges[i])], &k = kept_edges_[i];
                   f.same = e.mesh == k.mesh && e.v0 == k.v0 && e.v1 == k.v1 && e.f0 == k.f0 && e.f1 == k.f1 &&
                            e.kind == k.kind;
               }).same;
    // The same edges: each leaf set from its edge as the scene has it now, with its cone's input
    // (at its place in the leaves' order, leaf.first), in one sweep that finds which changed:
    // their ends or faces (a refit), only the flags the materials and emission decide (those
    // flags alone), or which tree (discontinuity or smooth) they belong in (a face became or
    // stopped being degenerate: a rebuild, which sets every node anew). The sweep goes through
    // the nodes in memory order, skipping the inner ones: a third less time at a million edges
    // than going from edge to leaf, whose nodes lie scattered.
    bool moved = false, flags = false;
    if (same) {
        const Found f = over(nodes_.size(), [&](size_t index, Found& f) {
            Node& leaf = nodes_[index];
            if (leaf.left >= 0) return;
            const int32_t id = leaf.edge;
            const LeafInput in = leaf_input(scene, all[size_t(id)]);
            f.same = leaf.always == in.always && leaf.crease == in.crease && leaf.seam == in.seam;
            if (!f.same) return;
            f.moved = f.moved || !(bitwise_equal(leaf.leaf.a, in.p0) && bitwise_equal(leaf.leaf.b, in.p1) &&
                                   bitwise_equal(leaf.leaf.n0, in.n0) && bitwise_equal(leaf.leaf.n1, in.n1));
            f.flags = f.flags || leaf.dark_behind != in.dark_behind || leaf.emissive != in.emissive;
            const size_t k = size_t(leaf.first);
            set_leaf(in, id, leaf);
            cone_in_.set(k, in);
        });
        same = f.same;
        moved = f.moved;
        flags = f.flags;
    }
    if (!same) {
        build(scene, Input(scene, edges), group);
        return done(Update::Built);
    }
    if (moved) {
        refit(0);
        return done(Update::Refit);
    }
    if (flags) refresh_inner_flags();
    return done(Update::Reused);
}

// The inner nodes of the subtree at `index` from their children's (set), bottom-up, and the
// normal cones of those that have one, as the build makes them; large subtrees' halves in
// parallel.
void EdgeHierarchy::refit(int32_t index) {
    Node& node = nodes_[size_t(index)];
    if (node.left < 0) return;
    if (node.count > kParallelRange)
        tbb::parallel_invoke([&] { refit(node.left); }, [&] { refit(node.right()); });
    else {
        refit(node.left);
        refit(node.right());
    }
    finish_inner(index);
    if (has_cone(node)) fit_cone(node);
}

void EdgeHierarchy::refresh_flags(const Input& in) {
    for (size_t i = 0; i < in.ids->size(); ++i) {
        Node& leaf = nodes_[size_t(leaf_of_[size_t(in.id(i))])];
        leaf.dark_behind = in.leaf[i].dark_behind;
        leaf.emissive = in.leaf[i].emissive;
    }
    refresh_inner_flags();
}

void EdgeHierarchy::refresh_inner_flags() {
    for (size_t k = nodes_.size(); k-- > 0;) {
        Node& node = nodes_[k];
        if (node.left < 0) continue;
        const Node &a = nodes_[size_t(node.left)], &b = nodes_[size_t(node.right())];
        node.dark_behind = a.dark_behind && b.dark_behind;
        node.emissive = a.emissive || b.emissive;
    }
}

int32_t EdgeHierarchy::check_bounds(const Scene& scene, float tol) const {
    const std::vector<Edge>& all = scene.edges();
    for (size_t k = 0; k < nodes_.size(); ++k) {
        const Node& node = nodes_[k];
        if (node.left >= 0) {  // the children: side by side after it, its edges split between them
            if (size_t(node.left) <= k || size_t(node.right()) >= nodes_.size()) return int32_t(k);
            const Node &l = nodes_[size_t(node.left)], &r = nodes_[size_t(node.right())];
            if (l.parent != int32_t(k) || r.parent != int32_t(k) || l.count + r.count != node.count ||
                l.first != node.first || r.first != node.first + l.count)
                return int32_t(k);
        }
        const float scale = tol * (length(node.hi - node.lo) + length(node.center) + 1e-6f);
        double total = 0.0;
        for (int32_t j = node.first; j < node.first + node.count; ++j) {
            const int32_t id = ids_[size_t(order_[size_t(j)])];
            const Node& leaf = nodes_[size_t(leaf_of_[size_t(id)])];
            if (size_t(id) >= all.size()) return int32_t(k);
            // The edge as the scene has it now (not as the leaf kept it).
            const Edge& e = all[size_t(id)];
            const Mesh& m = scene.meshes[size_t(e.mesh)];
            Vec3f a = m.vertex(e.v0), b = m.vertex(e.v1);
            if (e.flat) a = b = (a + b) * 0.5f;  // an empty leaf
            total += length(b - a);
            for (const Vec3f& x : {a, b}) {
                for (int c = 0; c < 3; ++c)
                    if (x[c] < node.lo[c] - scale || x[c] > node.hi[c] + scale) return int32_t(k);
                if (length(x - node.center) > node.radius + scale) return int32_t(k);
            }
            if (node.cone_cos > -1.f && !node.mixed && length(leaf.leaf.n0) > 0.f) {
                const Vec3f n0 = m.unit_face_normal(e.f0), n1 = m.unit_face_normal(e.f1);
                // A leaf keeps no axis: its cone's is its faces' normals' mean.
                const Vec3f axis = node.left >= 0 ? node.cone.axis : normalize(node.leaf.n0 + node.leaf.n1);
                for (const Vec3f& nf : {n0, n1})
                    if (dot(axis, nf) < node.cone_cos - tol) return int32_t(k);
                if (node.left >= 0) {
                    const float pa = dot(n0, node.center - a), pb = dot(n1, node.center - a);
                    if (std::min(pa, pb) < node.cone.plane_lo - scale || std::max(pa, pb) > node.cone.plane_hi + scale)
                        return int32_t(k);
                }
            }
        }
        if (std::abs(total - double(node.length)) > double(tol) * (total + 1e-6)) return int32_t(k);
    }
    return -1;
}

int32_t EdgeHierarchy::first_difference(const EdgeHierarchy& other) const {
    auto same = [](const auto& a, const auto& b) { return std::memcmp(&a, &b, sizeof(a)) == 0; };
    for (size_t k = 0; k < nodes_.size(); ++k) {
        if (k >= other.nodes_.size()) return int32_t(k);
        const Node &a = nodes_[k], &b = other.nodes_[k];
        bool equal = same(a.lo, b.lo) && same(a.hi, b.hi) && same(a.center, b.center) && same(a.radius, b.radius) &&
                     same(a.length, b.length) && a.count == b.count && a.left == b.left && same(a.cone_cos, b.cone_cos) &&
                     same(a.dihedral, b.dihedral) && a.always == b.always && a.crease == b.crease &&
                     a.dark_behind == b.dark_behind && a.emissive == b.emissive && a.edge == b.edge &&
                     a.parent == b.parent && a.first == b.first && a.seam == b.seam && a.mixed == b.mixed;
        if (equal && a.left < 0) equal = same(a.leaf.a, b.leaf.a) && same(a.leaf.b, b.leaf.b) && same(a.leaf.n0, b.leaf.n0) &&
                                         same(a.leaf.n1, b.leaf.n1);
        else if (equal && !a.mixed && (!a.always || a.crease))  // fit_cone's
            equal = same(a.cone.axis, b.cone.axis) && same(a.cone.sin, b.cone.sin) && same(a.cone.plane_lo, b.cone.plane_lo) &&
                    same(a.cone.plane_hi, b.cone.plane_hi);
        if (!equal) return int32_t(k);
    }
    return nodes_.size() == other.nodes_.size() ? -1 : int32_t(nodes_.size());
}

// ---- importance -------------------------------------------------------------------------------

// Written into `out` rather than returned: a returned Coarse came back packed in registers
// through a store of its flags and a wider load of them, a store-forwarding stall measured at
// about a fifth of this function's time.
void EdgeHierarchy::coarse(const Query& q, const Node& n, Coarse& out) const {
    out = Coarse();
    if (!(n.length > 0.f)) return;  // empty leaves only (Edge::flat): nothing to sample
    const bool leaf = n.left < 0;
    // A leaf's arc and Lights part (ArcPart::compute), kept for the point sampler where the
    // query keeps them (Query::arcs).
    auto leaf_part = [&](ArcPart& arc) {
        const bool part = arc.compute(q.p, n.leaf.a, n.leaf.b, *q.cone, q.lights);
        // (Only with a part: without one the leaf scores zero for strategy Lights, which then
        // cannot pick the edge, and the point sampler takes no part.)
        if (q.arcs && part) q.arcs->keep(n.edge, n.leaf.a, n.leaf.b, arc);
        return part;
    };
    // A smooth edge or a crease is a silhouette where p is in front of exactly one of its faces.
    // Elsewhere a crease's faces meet at a shading jump, about as large as the angle between
    // them, and a smooth edge's at the steps where the mesh shadows itself along it (the light
    // between the faces' planes reaches one face and not the other, while the smooth normals
    // give both a weight): in proportion to that angle, over pi as in the camera's pass.
    // Nothing there where both faces are dark from behind, or at a last bounce, which sees
    // only emission (that jumps along an emitter's seams only).
    float weight = 1.f;
    if (leaf && (n.crease || (!n.always && n.cone_cos > -1.f))) {
        const Vec3f d = q.p - n.leaf.a;
        const bool front0 = dot(d, n.leaf.n0) > 0.f, front1 = dot(d, n.leaf.n1) > 0.f;
        if (front0 == front1) {
            if ((!front0 && n.dark_behind) || (q.direct_only && !(n.emissive && n.seam))) return;
            weight = n.always ? crease_weight(n.dihedral, n.seam) : n.dihedral / kPi;
            if (!(weight > 0.f)) return;
        }
    }
    const Vec3f v = n.center - q.p;
    // Nothing above the tangent plane (the BSDF's support, n on the side of wo): no light
    // through the node's edges reaches p (edges in the plane itself are seen at grazing angles,
    // where the cosine vanishes).
    const Vec3f half = (n.hi - n.lo) * 0.5f, ln = q.lobe.n;
    if (dot(ln, v) + std::abs(ln.x) * half.x + std::abs(ln.y) * half.y + std::abs(ln.z) * half.z <= 0.f) return;
    if (leaf) {  // the segment itself: both ends below, or within 1e-5 rad above, the plane
        const Vec3f ea = n.leaf.a - q.p, eb = n.leaf.b - q.p;
        if (dot(ln, ea) <= 1e-5f * length(ea) && dot(ln, eb) <= 1e-5f * length(eb)) return;
    }
    const float dc2 = length_squared(v), r2 = n.radius * n.radius;
    const Vec3f below = max(n.lo - q.p, Vec3f(0.f)), above = max(q.p - n.hi, Vec3f(0.f));
    // Distance to the box, no less than half the sphere's radius (the bound of 1/distance^2
    // would be infinite for boxes that hold p), and positive (a zero radius: one point). No
    // floor in the scene's units: one (1e-12) once scored every node of a scene 1e-6 units
    // across alike.
    const float d2 = std::max(std::max(length_squared(below + above), 0.25f * r2), std::numeric_limits<float>::min());
    const float d = std::sqrt(dc2);
    const Vec3f dir = d > 0.f ? v / d : Vec3f(0.f, 0.f, 1.f);  // (any direction at the centre: d 0)
    // Silhouettes possible? The signed distance of p to a face's plane is
    //   n_f . (p - x_f) = n_f . (p - c) + n_f . (c - x_f),
    // the first term within d [cos(phi + theta), cos(phi - theta)] (phi: the angle between the
    // normal cone's axis and p - c, theta: the cone's half angle), the second within the node's
    // plane range. A smooth edge is a silhouette where its faces' distances have opposite signs:
    // none if the range is all positive or all negative. Otherwise the share of silhouettes:
    // the two faces of an edge differ by about d x dihedral, so about that over the range's
    // width (no less than a tenth: an estimate, not a bound, kept from starving a node whose
    // silhouettes happen to carry the contribution). The range holds wherever p is, inside the
    // node's sphere too, and so do its two exact tests (nothing where p is behind every face of
    // edges dark from behind; nothing but silhouettes at a last bounce): their leaves would all
    // score zero, so a node they reject scores zero even where p is inside it.
    float fraction = 1.f;
    bool silhouettes_only = false;
    if (!leaf && (!n.always || n.crease) && n.cone_cos > -1.f) {
        const float cp = -dot(n.cone.axis, dir), sp = sine(cp);
        const float ct = n.cone_cos, st = n.cone.sin;
        const float lowest = ct < -cp ? -1.f : cp * ct - sp * st, highest = cp > ct ? 1.f : cp * ct + sp * st;
        const float lo = n.cone.plane_lo + d * lowest, hi = n.cone.plane_hi + d * highest;
        if (n.dark_behind && !(hi > 0.f)) return;  // creases, p behind every face
        // Edges count where the range straddles 0 (silhouettes) and elsewhere too (shading jumps,
        // self-shadowing steps), except at a last bounce unless there are seams of an emitter:
        // then only as silhouettes.
        silhouettes_only = q.direct_only && !(n.emissive && n.seam);
        const bool straddles = lo < 0.f && hi > 0.f;
        if (silhouettes_only) {
            if (!straddles) return;
            fraction = std::clamp(d * n.dihedral / (hi - lo), 0.1f, 1.f);
        } else {
            const float silhouettes = straddles ? std::clamp(d * n.dihedral / (hi - lo), 0.f, 1.f) : 0.f;
            fraction = silhouettes + (1.f - silhouettes) * (n.always ? crease_weight(n.dihedral, n.seam) : n.dihedral / kPi);
        }
    }
    if (!(dc2 > r2)) {
        // p inside the bounding sphere: every direction; the lobe's peak (not the silhouettes'
        // share, an estimate for nodes seen from outside). (importance() scores such a node by
        // its children instead, a few levels down: their bounds are tighter.)
        // Strategy Lights: nothing where the point sampler has no part of the edge to take, or
        // where the box lies outside every light triangle's wedge.
        out.value[0] = n.length * (q.lobe.diffuse + q.lobe.specular) / d2;
        if (q.cone) {
            ArcPart arc;
            const bool none = leaf ? !(leaf_part(arc) && arc.t1 > arc.t0) : q.lights && q.lights->outside(n.lo, n.hi);
            out.value[1] = none ? 0.f : out.value[0];
        }
        out.inside = !leaf;
        return;
    }
    const float sin_b = n.radius / d, cos_b = sine(sin_b);
    // The lobe over the node's directions: for a leaf, along its edge's own arc (closed form);
    // for a node, over the cone around its sphere.
    double leaf_h = 0.0;
    if (leaf) {
        // The edge's term is about the lobe's integral over the arc it subtends, over the
        // distance h to its line (the rate at which the arc sweeps as the edge moves).
        const double integral = q.lobe.integral(q.p, n.leaf.a, n.leaf.b, &leaf_h);
        out.value[0] = weight * float(integral / std::max(leaf_h, 1e-3 * double(n.length)));
    } else {
        // The largest cosine between a lobe axis and the node's directions; for silhouettes,
        // also no more than that to the band of directions a silhouette can have: a direction w
        // along which p sees a silhouette is perpendicular to some normal between the edge's two
        // faces', so within the cone's half angle theta of the great circle perpendicular to its
        // axis (for theta below pi / 2).
        const bool band = silhouettes_only && n.cone_cos > 0.f;
        auto largest = [&](const Vec3f& axis) {
            float c = cos_minus(dot(axis, dir), cos_b, sin_b);
            if (band) {
                const float x = std::abs(dot(axis, n.cone.axis));
                if (x > n.cone.sin) c = std::min(c, sine(x) * n.cone_cos + x * n.cone.sin);
            }
            return c;
        };
        const float cn = largest(q.lobe.n);
        if (!(cn > 0.f)) return;
        float bound = q.lobe.diffuse * cn;
        if (q.lobe.specular > 0.f) {
            // Silhouettes are curves: one crosses the node's directions along a chord of about
            // twice its angular radius, over which the lobe averages at most its width over
            // the chord's length times its largest value (an estimate, as a leaf's value is the
            // lobe's integral along its edge; without it, nodes wider than the lobe would all
            // score the lobe's peak).
            const float s = 1.f + q.lobe.sharpness * (1.f - largest(q.lobe.r));
            const float chord = std::min(1.f, q.lobe.width / (2.f * std::max(sin_b, 1e-6f)));
            bound += q.lobe.specular * chord / (s * s);
        }
        out.value[0] = n.length * fraction * bound / d2;
    }
    if (!(out.value[0] > 0.f) || !std::isfinite(out.value[0])) {
        out.value[0] = 0.f;
        return;
    }
    // Towards the lights: apart when the angle between the axes exceeds beta + the cone's.
    // Otherwise the share of the node inside the cone: the overlap of the two angular
    // intervals along the line of their centres over the smaller one, times the ratio of their
    // sizes when the node is the larger (silhouettes are curves: the ratio, not its square); no
    // less than a tenth (an estimate, not a bound).
    if (q.cone) {
        const BoundsCone& c = *q.cone;
        const float cos_g = dot(dir, c.axis);
        const bool wraps = c.cos_half <= -cos_b;  // beta + the cone's half angle >= pi
        if (leaf) {
            // A leaf: the same integral over the part of its arc the point sampler takes
            // (EdgeArc::lights_part: inside the cone, near a light triangle), zero where that is
            // empty (or where the cones are apart).
            ArcPart arc;
            if ((wraps || cos_g >= cos_b * c.cos_half - sin_b * sine(c.cos_half)) && !(q.lights && q.lights->outside(n.lo, n.hi)) &&
                leaf_part(arc)) {
                const float t0 = arc.t0, t1 = arc.t1;
                if (t1 > t0) {
                    const Vec3f e = n.leaf.b - n.leaf.a;
                    const double part =
                        t0 <= 0.f && t1 >= 1.f ? -1.0 : q.lobe.integral(q.p, n.leaf.a + e * t0, n.leaf.a + e * t1);
                    out.value[1] = part < 0.0 ? out.value[0]
                                              : weight * float(part / std::max(leaf_h, 1e-3 * double(n.length)));
                    if (!std::isfinite(out.value[1])) out.value[1] = 0.f;
                }
            }
        } else if (wraps) {
            out.value[1] = out.value[0];
            if (q.lights && q.lights->outside(n.lo, n.hi)) out.value[1] = 0.f;
        } else if (cos_g >= cos_b * c.cos_half - sin_b * sine(c.cos_half)) {
            const float beta = std::asin(sin_b), gamma = std::acos(std::clamp(cos_g, -1.f, 1.f));
            const float small = std::min(beta, c.half);
            float share = small > 0.f ? std::clamp((beta + c.half - gamma) / (2.f * small), 0.f, 1.f) : 1.f;
            if (beta > c.half) share *= c.half / beta;
            share = std::max(share, 0.1f);
            out.value[1] = out.value[0] * share;
            // A narrow cone meets few of a large node's edges, and which of them are
            // silhouettes inside it the node's own bounds cannot tell: its children's can.
            out.narrow = c.cos_half > kNarrowCone && beta > c.half;
            // None of them where the box lies outside every light triangle's widened wedge.
            if (q.lights && q.lights->outside(n.lo, n.hi)) {
                out.value[1] = 0.f;
                out.narrow = false;
            }
        }
    }
}

// The memo's entry of a node scored by its own bounds needs no more work where neither the
// refinement of a node whose sphere holds p nor that of a narrow light cone applies; a small
// subtree's entry (its leaves' sum) keeps both flags false. Then no node is read at all.
inline void EdgeHierarchy::importance(const Query& q, int32_t index, float out[2], int refine, int light_refine) const {
    bool found = false;
    Coarse* const kept = q.memo ? q.memo->lookup(index, found) : nullptr;
    if (found && !(kept->inside && refine > 0) && !(kept->narrow && light_refine > 0)) {
        out[0] = kept->value[0];
        out[1] = kept->value[1];
        return;
    }
    importance_of(q, index, kept, found, out, refine, light_refine);
}

void EdgeHierarchy::importance_of(const Query& q, int32_t index, Coarse* kept, bool found, float out[2], int refine,
                                  int light_refine) const {
    const Node& n = nodes_[size_t(index)];
    if (!(n.length > 0.f)) {  // empty leaves only (Edge::flat): never descended into
        out[0] = out[1] = 0.f;
        if (kept) {  // claimed by importance(): a later hit reads it
            kept->value[0] = kept->value[1] = 0.f;
            kept->inside = kept->narrow = false;
        }
        return;
    }
    if (n.left >= 0 && n.count <= kExactLeaves) {
        // A small subtree: the sum of its leaves' own values (kept in the memo in place of the
        // node's own bounds, which are never needed).
        if (found) {
            out[0] = kept->value[0];
            out[1] = kept->value[1];
            return;
        }
        float a[2], b[2];
        leaves_sum(q, n.left, a);
        leaves_sum(q, n.right(), b);
        out[0] = a[0] + b[0];
        out[1] = a[1] + b[1];
        if (kept) {
            kept->value[0] = out[0];
            kept->value[1] = out[1];
            kept->inside = kept->narrow = false;
        }
        return;
    }
    Coarse scratch;
    const Coarse* c = kept;
    if (!kept) {
        coarse(q, n, scratch);
        c = &scratch;
    } else if (!found) {
        coarse(q, n, *kept);
    }
    if (c->inside && refine > 0) {
        // p inside the bounding sphere: the children's bounds are tighter (a few levels down).
        float a[2], b[2];
        importance(q, n.left, a, refine - 1, light_refine);
        importance(q, n.right(), b, refine - 1, light_refine);
        out[0] = a[0] + b[0];
        out[1] = a[1] + b[1];
        return;
    }
    out[0] = c->value[0];
    out[1] = c->value[1];
    if (c->narrow && light_refine > 0) {
        // The node's share of a narrow light cone, by its children (summed, a few levels down):
        // descents then rarely end where nothing contributes.
        float a[2], b[2];
        importance(q, n.left, a, 0, light_refine - 1);
        importance(q, n.right(), b, 0, light_refine - 1);
        out[1] = a[1] + b[1];
    }
}

// importance(q, index, out, 0, 0) for a node of a small subtree, without its general case:
// a leaf is scored by its own bounds (never inside nor narrow), a node by its children's sum.
void EdgeHierarchy::leaves_sum(const Query& q, int32_t index, float out[2]) const {
    bool found = false;
    Coarse* const kept = q.memo ? q.memo->lookup(index, found) : nullptr;
    if (found) {
        out[0] = kept->value[0];
        out[1] = kept->value[1];
        return;
    }
    const Node& n = nodes_[size_t(index)];
    Coarse scratch;
    Coarse& c = kept ? *kept : scratch;
    if (n.left < 0) {
        coarse(q, n, c);  // zero for an empty leaf
    } else {
        c = Coarse();
        if (n.length > 0.f) {  // else only empty leaves: never descended into
            float a[2], b[2];
            leaves_sum(q, n.left, a);
            leaves_sum(q, n.right(), b);
            c.value[0] = a[0] + b[0];
            c.value[1] = a[1] + b[1];
        }
    }
    out[0] = c.value[0];
    out[1] = c.value[1];
}

EdgeHierarchy::Coarse* EdgeHierarchy::Memo::insert(int32_t node) {
    if (used_ * 4 >= kSize * 3) return nullptr;  // full enough: computed without keeping
    for (uint32_t h = slot(node);; h = (h + 1) & (kSize - 1))
        if (entries_[h].stamp != stamp_) {
            entries_[h].stamp = stamp_;
            entries_[h].node = node;
            ++used_;
            return &entries_[h].value;
        }
}

const EdgeHierarchy::Coarse* EdgeHierarchy::Memo::find(int32_t node) const {
    for (uint32_t h = slot(node);; h = (h + 1) & (kSize - 1)) {
        const Entry& e = entries_[h];
        if (e.stamp != stamp_) return nullptr;
        if (e.node == node) return &e.value;
    }
}

void EdgeHierarchy::Memo::reset() {
    used_ = 0;
    if (++stamp_ == 0) {  // wrapped: no entry may look current
        for (Entry& e : entries_) e.stamp = 0;
        stamp_ = 1;
    }
}

// ---- sampling ---------------------------------------------------------------------------------

inline bool EdgeHierarchy::splits(const Query& q, const Node& n, const float il[2], const float ir[2], const float whole[2],
                           int k, int used) const {
    if (used >= kMaxSplits || !(il[k] > 0.f) || !(ir[k] > 0.f)) return false;
    // p inside both boxes: the bounds (no better than the lobe's peak) cannot tell them apart.
    const Node &l = nodes_[size_t(n.left)], &r = nodes_[size_t(n.right())];
    auto inside = [&](const Node& c) {
        return q.p.x >= c.lo.x && q.p.x <= c.hi.x && q.p.y >= c.lo.y && q.p.y <= c.hi.y && q.p.z >= c.lo.z &&
               q.p.z <= c.hi.z;
    };
    if (inside(l) && inside(r)) return true;
    // A narrow light cone: the few edges that cast the shadow are worth more than one look.
    if (k == Lights && q.cone && q.cone->cos_half > kNarrowCone) return true;
    // Both children comparable and large: choosing one throws away half of what matters.
    const float lo = std::min(il[k], ir[k]), hi = std::max(il[k], ir[k]);
    return lo >= kComparable * hi && il[k] + ir[k] >= kLarge * whole[k];
}

int EdgeHierarchy::sample(const Query& q, Strategy s, float u, Choice out[kMaxChoices], int32_t start) const {
    if (nodes_.empty() || start < 0 || size_t(start) >= nodes_.size() || (s == Lights && !q.cone)) return 0;
    float root[2];
    importance(q, start, root);
    if (!(root[s] > 0.f)) return 0;
    // Pending descents: the node, its u, the expected counts so far and the splits made so far
    // (under both strategies: the other strategy's count follows its own splitting rule).
    struct Item {
        int32_t at;
        float u;
        float prob[2];
        int used[2];
    };
    Item stack[kMaxChoices + 1];
    int top = 0, count = 0;
    stack[top++] = Item{start, u, {root[0] > 0.f ? 1.f : 0.f, root[1] > 0.f ? 1.f : 0.f}, {0, 0}};
    while (top > 0) {
        Item it = stack[--top];
        bool alive = true;
        while (nodes_[size_t(it.at)].left >= 0) {
            const Node& n = nodes_[size_t(it.at)];
            float il[2], ir[2];
            importance(q, n.left, il);
            importance(q, n.right(), ir);
            const float sum = il[s] + ir[s];
            if (!(sum > 0.f)) {
                alive = false;
                break;
            }
            bool split[2];
            for (int k = 0; k < 2; ++k) split[k] = splits(q, n, il, ir, root, k, it.used[k]);
            if (split[s]) {
                // Both children, the same u in each (each descent is right on its own).
                Item other = it;
                other.at = n.right();
                for (int k = 0; k < 2; ++k) {
                    if (split[k]) continue;
                    const float tot = il[k] + ir[k];
                    it.prob[k] *= tot > 0.f ? il[k] / tot : 0.f;
                    other.prob[k] *= tot > 0.f ? ir[k] / tot : 0.f;
                }
                for (int k = 0; k < 2; ++k) it.used[k] += split[k], other.used[k] += split[k];
                it.at = n.left;
                stack[top++] = other;
                continue;
            }
            const float pl = il[s] / sum;
            const bool left = it.u < pl;
            it.u = left ? it.u / pl : (it.u - pl) / (1.f - pl);
            it.u = std::min(std::max(it.u, 0.f), 0.99999994f);
            for (int k = 0; k < 2; ++k) {
                if (split[k]) {
                    ++it.used[k];
                    continue;
                }
                const float tot = il[k] + ir[k];
                it.prob[k] *= tot > 0.f ? (left ? il[k] : ir[k]) / tot : 0.f;
            }
            it.at = left ? n.left : n.right();
        }
        if (!alive || !(it.prob[s] > 0.f)) continue;
        Choice& c = out[count++];
        c.edge = nodes_[size_t(it.at)].edge;
        c.prob[0] = it.prob[0];
        c.prob[1] = it.prob[1];
    }
    return count;
}

EdgeHierarchy::Choice EdgeHierarchy::pdf(const Query& q, int32_t edge, int32_t start) const {
    Choice c;
    c.edge = edge;
    if (size_t(edge) >= leaf_of_.size() || leaf_of_[size_t(edge)] < 0 || start < 0) return c;
    // The path from `start` down (the splits depend on those made above); none if the edge is
    // not under it.
    int32_t path[128];
    int depth = 0;
    int32_t at = leaf_of_[size_t(edge)];
    for (; at >= 0 && depth < 128; at = nodes_[size_t(at)].parent) {
        path[depth++] = at;
        if (at == start) break;
    }
    if (at != start) return c;
    float root[2];
    importance(q, start, root);
    c.prob[0] = root[0] > 0.f ? 1.f : 0.f;
    c.prob[1] = root[1] > 0.f ? 1.f : 0.f;
    int used[2] = {0, 0};
    for (int i = depth - 1; i > 0; --i) {
        const Node& n = nodes_[size_t(path[i])];
        const int32_t next = path[i - 1];
        float il[2], ir[2];
        importance(q, n.left, il);
        importance(q, n.right(), ir);
        for (int k = 0; k < 2; ++k) {
            const float mine = next == n.left ? il[k] : ir[k];
            if (splits(q, n, il, ir, root, k, used[k])) {
                ++used[k];
                if (!(mine > 0.f)) c.prob[k] = 0.f;
                continue;
            }
            const float tot = il[k] + ir[k];
            c.prob[k] *= tot > 0.f ? mine / tot : 0.f;
        }
    }
    return c;
}

// ---- the point on the edge --------------------------------------------------------------------

void EdgePointSampler::Table::build(const Vec3f& a, const Vec3f& b, const LobeBound& lobe, float lo_, float hi_) {
    lo = lo_;
    hi = hi_;
    // (cos, sin) of the bins' ends by rotation, one step at a time (padded with zeros to whole
    // groups of four).
    const float step = (hi - lo) / float(kBins), cs = std::cos(step), ss = std::sin(step);
    float c = std::cos(lo), sn = std::sin(lo);
    constexpr int kPadded = (kBins + 1 + 3) / 4 * 4;
    float cv[kPadded] = {}, sv[kPadded] = {}, gv[kPadded];
    for (int k = 0; k <= kBins; ++k) {
        cv[k] = c;
        sv[k] = sn;
        const float next_c = c * cs - sn * ss;
        sn = sn * cs + c * ss;
        c = next_c;
    }
    // The lobe bound there: LobeBound::eval's arithmetic in the same order, four ends at a time
    // where the compiler has vector types (each lane rounds as the scalar code), without
    // branches (the padding gives zeros).
    const float kd = lobe.diffuse, ks = lobe.specular, sharp = lobe.sharpness;
    const float ax = a.x, ay = a.y, az = a.z, bx = b.x, by = b.y, bz = b.z;
    const float nx = lobe.n.x, ny = lobe.n.y, nz = lobe.n.z, rx = lobe.r.x, ry = lobe.r.y, rz = lobe.r.z;
    const bool glossy = ks > 0.f;
#if defined(__GNUC__)
    typedef float F4 __attribute__((vector_size(16)));
    for (int k = 0; k < kPadded; k += 4) {
        F4 cc, sk;
        std::memcpy(&cc, cv + k, sizeof(F4));
        std::memcpy(&sk, sv + k, sizeof(F4));
        const F4 wx = ax * cc + bx * sk, wy = ay * cc + by * sk, wz = az * cc + bz * sk;
        const F4 cn = nx * wx + ny * wy + nz * wz;
        F4 v = kd * cn;
        if (glossy) {
            const F4 q = 1.f + sharp * (1.f - (rx * wx + ry * wy + rz * wz));
            v = v + ks / (q * q);
        }
        const F4 zero = {0.f, 0.f, 0.f, 0.f};
        const F4 out = cn > 0.f ? v : zero;
        std::memcpy(gv + k, &out, sizeof(F4));
    }
#else
    for (int k = 0; k < kPadded; ++k) {
        const float wx = ax * cv[k] + bx * sv[k], wy = ay * cv[k] + by * sv[k], wz = az * cv[k] + bz * sv[k];
        const float cn = nx * wx + ny * wy + nz * wz;
        float v = kd * cn;
        if (glossy) {
            const float q = 1.f + sharp * (1.f - (rx * wx + ry * wy + rz * wz));
            v += ks / (q * q);
        }
        gv[k] = cn > 0.f ? v : 0.f;
    }
#endif
    std::memcpy(g, gv, sizeof(g));
    // The bins' trapezoids (independent: vector lanes), then their running sum in order.
    float area[kBins + 1];
    for (int k = 1; k <= kBins; ++k) area[k] = 0.5f * (gv[k - 1] + gv[k]) * step;
    cdf[0] = 0.f;
    for (int k = 1; k <= kBins; ++k) cdf[k] = cdf[k - 1] + area[k];
    total = cdf[kBins];
    if (!(total > 0.f) || !std::isfinite(total)) total = 0.f;
}

float EdgePointSampler::Table::invert(float u) const {
    // The bin, then x in [0, 1] inside it with
    //   g0 x + (g1 - g0) x^2 / 2 = c,
    // by Newton's method kept inside a shrinking bracket (bisection when a step leaves it).
    const float target = u * total, step = (hi - lo) / float(kBins);
    int k = 0;
    while (k < kBins - 1 && cdf[k + 1] <= target) ++k;
    const float g0 = g[k], g1 = g[k + 1], c = (target - cdf[k]) / step;
    float a = 0.f, b = 1.f, x = g0 + g1 > 0.f ? std::clamp(2.f * c / (g0 + g1), 0.f, 1.f) : 0.5f;
    for (int it = 0; it < 20; ++it) {
        const float F = g0 * x + 0.5f * (g1 - g0) * x * x - c, dF = g0 + (g1 - g0) * x;
        if (F > 0.f) b = x;
        else a = x;
        float next = dF > 0.f ? x - F / dF : 0.5f * (a + b);
        if (!(next > a && next < b)) next = 0.5f * (a + b);
        const bool done = std::abs(next - x) < 1e-7f;
        x = next;
        if (done) break;
    }
    return lo + (float(k) + x) * step;
}

float EdgePointSampler::Table::value(float phi) const {
    const float step = (hi - lo) / float(kBins), f = (phi - lo) / step;
    const int k = std::clamp(int(f), 0, kBins - 1);
    const float x = std::clamp(f - float(k), 0.f, 1.f);
    return g[k] + (g[k + 1] - g[k]) * x;
}

void LightTriangles::set(const Vec3f& p_, const Vec3f (*corners)[3], int count_, float margin_) {
    count = std::min(count_, kMax);
    margin = margin_;
    p = p_;
    for (int i = 0; i < count; ++i) {
        const Vec3f d[3] = {corners[i][0] - p_, corners[i][1] - p_, corners[i][2] - p_};
        // The sign of det(d0, d1, d2) turns each side's plane to face the opposite corner (the
        // same sign for all three). Where p lies in (or within 1e-5 rad of) the triangle's plane
        // that sign is not to be trusted: no bound from this triangle.
        const float det = dot(cross(d[0], d[1]), d[2]);
        const float scale = length(d[0]) * length(d[1]) * length(d[2]);
        const bool bounded = std::abs(det) > 1e-5f * scale && std::isfinite(det);
        for (int k = 0; k < 3; ++k) {
            const Vec3f c = cross(d[k], d[(k + 1) % 3]);
            const float l = length(c);
            n[i][k] = bounded && l > 0.f ? c * ((det > 0.f ? 1.f : -1.f) / l) : Vec3f(0.f);
            abs_n[i][k] = Vec3f(std::abs(n[i][k].x), std::abs(n[i][k].y), std::abs(n[i][k].z));
        }
        for (int k = 0; k < 4; ++k) {
            const Vec3f &nk = n[i][k % 3], &ak = abs_n[i][k % 3];
            planes[i].x[k] = nk.x;
            planes[i].y[k] = nk.y;
            planes[i].z[k] = nk.z;
            planes[i].ax[k] = ak.x;
            planes[i].ay[k] = ak.y;
            planes[i].az[k] = ak.z;
        }
    }
}

bool LightTriangles::outside(const Vec3f& lo, const Vec3f& hi) const {
    if (count <= 0) return false;
    // Over the box, n . (x - p) is at most n . (c - p) + |n| . half, and |x - p| at most the
    // sum of |c - p| and |half| in the 1-norm (no square roots; the margin is small). A plane
    // leaves the box out where the first plus the margin times the second is below zero, by
    // more than the rounding of these sums (and of the leaves' clips, computed in float from the
    // same planes).
    const Vec3f c = (lo + hi) * 0.5f - p, half = (hi - lo) * 0.5f;
    const float far = std::abs(c.x) + std::abs(c.y) + std::abs(c.z) + half.x + half.y + half.z;
    const float reach = (margin + 1e-5f) * far;
    // Each triangle's three planes at once (Planes; lane 3 repeats lane 0), in the order of
    // dot(n, c) + dot(abs_n, half) + reach: the same values as one plane at a time.
#if defined(__SSE2__)
    const __m128 cx = _mm_set1_ps(c.x), cy = _mm_set1_ps(c.y), cz = _mm_set1_ps(c.z);
    const __m128 hx = _mm_set1_ps(half.x), hy = _mm_set1_ps(half.y), hz = _mm_set1_ps(half.z);
    const __m128 r = _mm_set1_ps(reach), zero = _mm_setzero_ps();
    for (int i = 0; i < count; ++i) {
        const Planes& t = planes[i];
        const __m128 nc = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_load_ps(t.x), cx), _mm_mul_ps(_mm_load_ps(t.y), cy)),
                                     _mm_mul_ps(_mm_load_ps(t.z), cz));
        const __m128 ah = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_load_ps(t.ax), hx), _mm_mul_ps(_mm_load_ps(t.ay), hy)),
                                     _mm_mul_ps(_mm_load_ps(t.az), hz));
        if (_mm_movemask_ps(_mm_cmplt_ps(_mm_add_ps(_mm_add_ps(nc, ah), r), zero)) == 0) return false;
    }
#else
    for (int i = 0; i < count; ++i) {
        bool out = false;
        for (int k = 0; k < 3 && !out; ++k) out = dot(n[i][k], c) + dot(abs_n[i][k], half) + reach < 0.f;
        if (!out) return false;
    }
#endif
    return true;
}

namespace {
// Keeps of [lo, hi] (shorter than pi) the angles phi with A cos(phi) + B sin(phi) >= -m, or the
// hull of them where they are two pieces; false when none are left.
bool keep_above(float A, float B, float m, float& lo, float& hi) {
    const float R = std::sqrt(A * A + B * B);
    if (!(R > m)) return hi > lo;  // every angle
    // R cos(phi - psi) >= -m: phi within h of psi, h in (pi/2, pi]; the arc left out,
    // (psi + h, psi + 2 pi - h), is shorter than pi, so at most one turn of it meets [lo, hi].
    const float psi = std::atan2(B, A), h = std::acos(std::max(-1.f, -m / R));
    for (int k = -2; k <= 1; ++k) {
        const float e0 = psi + h + 2.f * kPi * float(k), e1 = psi - h + 2.f * kPi * float(k + 1);
        if (e1 <= lo || e0 >= hi) continue;       // misses it
        if (e0 <= lo && e1 >= hi) return false;   // covers it
        if (e0 <= lo) lo = e1;                    // cuts its lower end
        else if (e1 >= hi) hi = e0;               // its upper end
        // else inside it: two pieces, their hull kept
    }
    return hi > lo;
}
}  // namespace

bool EdgeArc::set(const Vec3f& p, const Vec3f& v0, const Vec3f& v1) {
    const Vec3f e = v1 - v0;
    len = length(e);
    if (!(len > 0.f) || !std::isfinite(len)) return false;
    b = e / len;
    s_foot = dot(p - v0, b);
    const Vec3f hv = v0 + b * s_foot - p;
    h = length(hv);
    if (!(h > 1e-7f * (len + length(v0 - p)))) return false;  // p on the edge's line
    a = hv / h;
    phi0 = std::atan(-s_foot / h);
    phi1 = std::atan((len - s_foot) / h);
    return phi1 - phi0 > 1e-7f;
}

bool EdgeArc::lights_part(const BoundsCone& cone, const LightTriangles* lights, float& lo_out, float& hi_out) const {
    // The part inside the light cone: w(phi) . axis = R cos(phi - psi) >= cos_half.
    float c0 = 0.f, c1 = 0.f;
    if (cone.cos_half <= 0.f) {  // a hemisphere or more: the whole edge
        c0 = phi0;
        c1 = phi1;
    } else {
        const float A = dot(a, cone.axis), B = dot(b, cone.axis), R = std::sqrt(A * A + B * B);
        if (R > cone.cos_half) {
            const float psi = std::atan2(B, A), half = std::acos(std::min(1.f, cone.cos_half / R));
            float lo = psi - half, hi = psi + half;
            if (hi < phi0) lo += 2.f * kPi, hi += 2.f * kPi;
            if (lo > phi1) lo -= 2.f * kPi, hi -= 2.f * kPi;
            c0 = std::max(lo, phi0);
            c1 = std::min(hi, phi1);
        }
    }
    // Of that part, where the directions pass within the margin of a light triangle: the hull
    // over the triangles of each one's part (each a superset of where the directions meet it,
    // widened by the margin; see LightTriangles).
    if (lights && lights->count > 0 && c1 > c0) {
        // A plane that keeps both ends of [c0, c1] keeps all of it (what it leaves out is an
        // arc shorter than pi: inside the interval, the hull of the two pieces is the whole),
        // and so does a triangle all of whose planes do: then the hull over the triangles is
        // the whole too. Tested on the ends' directions, before any angle is solved for.
        const Vec3f w0 = a * std::cos(c0) + b * std::sin(c0), w1 = a * std::cos(c1) + b * std::sin(c1);
        const float m = lights->margin;
        float lo = c1, hi = c0;
        for (int i = 0; i < lights->count; ++i) {
            float l = c0, u = c1;
            bool left = true, whole = true;
            for (int k = 0; k < 3 && left; ++k) {
                const Vec3f& nk = lights->n[i][k];
                if (whole && dot(nk, w0) >= -m && dot(nk, w1) >= -m) continue;
                left = keep_above(dot(nk, a), dot(nk, b), m, l, u);
                whole = whole && l == c0 && u == c1;
            }
            if (!left) continue;
            lo = std::min(lo, l);
            hi = std::max(hi, u);
            if (whole) break;
        }
        c0 = lo;
        c1 = hi;
    }
    if (!(c1 > c0)) {
        lo_out = hi_out = 0.f;
        return false;
    }
    lo_out = c0;
    hi_out = c1;
    return true;
}

bool ArcPart::compute(const Vec3f& p, const Vec3f& v0, const Vec3f& v1, const BoundsCone& cone,
                      const LightTriangles* lights) {
    arc_ok = arc.set(p, v0, v1);
    part = arc_ok && arc.lights_part(cone, lights, lo, hi);
    if (part) {
        t0 = arc.param(lo);
        t1 = arc.param(hi);
    }
    return part;
}

bool EdgePointSampler::setup(const Vec3f& p, const Vec3f& v0, const Vec3f& v1, const LobeBound& lobe,
                             const BoundsCone* cone, const LightTriangles* lights) {
    ArcPart known;
    if (cone) known.compute(p, v0, v1, *cone, lights);
    else known.arc_ok = known.arc.set(p, v0, v1);
    return setup(known, lobe, cone);
}

bool EdgePointSampler::setup(const ArcPart& known, const LobeBound& lobe, const BoundsCone* cone) {
    if (!known.arc_ok) return false;
    arc_ = known.arc;
    // The lobe bound along the edge, in angle, and its integral.
    all_.build(arc_.a, arc_.b, lobe, arc_.phi0, arc_.phi1);
    // The part strategy Lights takes (EdgeArc::lights_part), and its ends in t (both the
    // sample and the density need them).
    cone0_ = cone1_ = t0_ = t1_ = 0.f;
    lights_uniform_ = 1.f;
    lights_pending_ = false;
    if (cone && known.part) {
        cone0_ = known.lo;
        cone1_ = known.hi;
        t0_ = known.t0;
        t1_ = known.t1;
        // A glossy lobe may be narrower than the cone: the lobe bound over the part inside it
        // (build_lights()).
        if (lobe.specular > 0.f) {
            lobe_ = lobe;
            lights_pending_ = true;
        }
    }
    return true;
}

void EdgePointSampler::build_lights() const {
    if (!lights_pending_) return;
    lights_pending_ = false;
    lights_.build(arc_.a, arc_.b, lobe_, cone0_, cone1_);
    if (lights_.total > 0.f) lights_uniform_ = kLightsUniform;
}

float EdgePointSampler::angle(float t) const { return arc_.angle(t); }
float EdgePointSampler::param(float phi) const { return arc_.param(phi); }
float EdgePointSampler::dphi_dt(float t) const {
    const float along = t * arc_.len - arc_.s_foot;
    return arc_.len * arc_.h / (arc_.h * arc_.h + along * along);
}

bool EdgePointSampler::sample(EdgeHierarchy::Strategy s, float u, float& t) const {
    if (s == EdgeHierarchy::Lights) {
        if (!(cone1_ > cone0_)) return false;
        const float t0 = t0_, t1 = t1_;
        if (!(t1 > t0)) return false;
        build_lights();
        if (u < lights_uniform_) {
            t = t0 + u / lights_uniform_ * (t1 - t0);
            return true;
        }
        t = std::clamp(param(lights_.invert((u - lights_uniform_) / (1.f - lights_uniform_))), t0, t1);
        return true;
    }
    if (u < kUniform || all_.total <= 0.f) {
        t = u < kUniform ? u / kUniform : (u - kUniform) / (1.f - kUniform);
        return true;
    }
    // The piecewise-linear density in angle.
    t = param(all_.invert((u - kUniform) / (1.f - kUniform)));
    return true;
}

float EdgePointSampler::lights_pdf(float t, float phi) const {
    build_lights();
    const float t0 = t0_, t1 = t1_;
    if (!(lights_uniform_ < 1.f)) return 1.f / (t1 - t0);
    return lights_uniform_ / (t1 - t0) + (1.f - lights_uniform_) * lights_.value(phi) / lights_.total * dphi_dt(t);
}

float EdgePointSampler::pdf(EdgeHierarchy::Strategy s, float t) const {
    if (!(t >= 0.f && t <= 1.f)) return 0.f;
    if (s == EdgeHierarchy::Lights) {
        if (!(cone1_ > cone0_)) return 0.f;
        if (!(t1_ > t0_ && t >= t0_ && t <= t1_)) return 0.f;
        return lights_pdf(t, angle(t));
    }
    if (all_.total <= 0.f) return 1.f;
    return kUniform + (1.f - kUniform) * all_.value(angle(t)) / all_.total * dphi_dt(t);
}

void EdgePointSampler::pdfs(float t, bool lights, float& all, float& lights_out) const {
    all = lights_out = 0.f;
    if (!(t >= 0.f && t <= 1.f)) return;
    // The angle where a density needs it, once.
    const bool in_part = lights && cone1_ > cone0_ && t1_ > t0_ && t >= t0_ && t <= t1_;
    const bool lobe_all = all_.total > 0.f;
    const float phi = lobe_all || (in_part && (lights_pending_ || lights_uniform_ < 1.f)) ? angle(t) : 0.f;
    all = lobe_all ? kUniform + (1.f - kUniform) * all_.value(phi) / all_.total * dphi_dt(t) : 1.f;
    if (in_part) lights_out = lights_pdf(t, phi);
}

bool EdgeHierarchy::current_for(const Scene& scene, const std::vector<uint8_t>& key) const {
    return !key.empty() && key == key_ && holds(scene, ids_, group_);
}

bool EdgeHierarchy::holds(const Scene& scene, const std::vector<int32_t>& edges, size_t group) const {
    return built_ && scene_ == &scene && version_ == scene.geometry_version() && group == group_ &&
           (&edges == &ids_ || edges == ids_);
}

bool EdgeHierarchy::unchanged_for(const Scene& scene, const std::vector<int32_t>& edges, size_t group) const {
    return holds(scene, edges, group) && mesh_flags(scene) == mesh_flags_;
}

// The scene's kept hierarchies (Scene::KeptHierarchies): the one for these edges, or else the
// one used least recently, brought up to date.
std::shared_ptr<const EdgeHierarchy> Scene::kept_hierarchy(const std::function<bool(const EdgeHierarchy&)>& fits,
                                                           const std::vector<int32_t>* edges, size_t group) const {
    KeptHierarchies& h = *hierarchies_;
    size_t pick = 0;
    for (size_t k = 0; k < KeptHierarchies::kKept; ++k)
        if (h.used[k] < h.used[pick]) pick = k;
    for (size_t k = 0; k < KeptHierarchies::kKept; ++k)
        if (h.kept[k] && fits(*h.kept[k])) pick = k;
    h.used[pick] = ++h.calls;
    std::shared_ptr<EdgeHierarchy>& kept = h.kept[pick];
    if (kept && kept.use_count() > 1) {
        // A pass in another thread still reads it: shared as it is where nothing would change
        // (many threads rendering one scene), else copied before it is changed.
        if (kept->unchanged_for(*this, edges ? *edges : kept->edges(), edges ? group : kept->group())) {
            ++hierarchy_stats_.reuses;
            return kept;
        }
        kept = std::make_shared<EdgeHierarchy>(*kept);
    }
    if (!kept) kept = std::make_shared<EdgeHierarchy>();
    switch (edges ? kept->update(*this, *edges, group) : kept->update(*this, kept->edges(), kept->group())) {
        case EdgeHierarchy::Update::Built: ++hierarchy_stats_.builds; break;
        case EdgeHierarchy::Update::Refit: ++hierarchy_stats_.refits; break;
        case EdgeHierarchy::Update::Reused: ++hierarchy_stats_.reuses; break;
    }
    return kept;
}

std::shared_ptr<const EdgeHierarchy> Scene::edge_hierarchy(const std::vector<int32_t>& edges, size_t group) const {
    std::lock_guard<std::mutex> lock(hierarchies_->mutex);
    // The one built for these arguments, or else the one used least recently.
    return kept_hierarchy([&](const EdgeHierarchy& t) { return t.built_for(edges, group); }, &edges, group);
}

std::shared_ptr<const EdgeHierarchy> Scene::edge_hierarchy(
    const std::vector<uint8_t>& key, const std::function<void(std::vector<int32_t>&, size_t&)>& list) const {
    KeptHierarchies& h = *hierarchies_;
    std::lock_guard<std::mutex> lock(h.mutex);
    auto current = [&](const EdgeHierarchy& t) { return t.current_for(*this, key); };
    bool any = false;
    for (size_t k = 0; k < KeptHierarchies::kKept; ++k) any = any || (h.kept[k] && current(*h.kept[k]));
    std::shared_ptr<const EdgeHierarchy> tree;
    if (any) {
        // Its own edges and group: update() finds them its own and reuses it.
        tree = kept_hierarchy(current, nullptr, 0);
    } else {
        std::vector<int32_t> edges;
        size_t group = 0;
        list(edges, group);
        tree = kept_hierarchy([&](const EdgeHierarchy& t) { return t.built_for(edges, group); }, &edges, group);
    }
    // (The one kept is the one returned: the same tree, or its copy.)
    for (size_t k = 0; k < KeptHierarchies::kKept; ++k)
        if (h.kept[k] == tree) h.kept[k]->set_key(key);
    return tree;
}

}  // namespace edgepath
