#include "edges/hierarchy.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include "scene/scene.h"

namespace edgepath {

namespace {

constexpr float kHalfPi = 1.57079632679f;

float angle_between(const Vec3f& a, const Vec3f& b) { return std::acos(std::clamp(dot(a, b), -1.f, 1.f)); }

}  // namespace

int32_t EdgeHierarchy::build_node(std::vector<int32_t>& items, int begin, int end, int32_t parent,
                                  const std::vector<Vec3f>& p0, const std::vector<Vec3f>& p1,
                                  const std::vector<Vec3f>& n0, const std::vector<Vec3f>& n1,
                                  const std::vector<uint8_t>& always, const std::vector<int32_t>& ids) {
    const int32_t index = int32_t(nodes_.size());
    nodes_.emplace_back();
    nodes_[size_t(index)].parent = parent;
    if (end - begin == 1) {
        const int32_t i = items[size_t(begin)];
        Node& n = nodes_[size_t(index)];
        n.lo = min(p0[size_t(i)], p1[size_t(i)]);
        n.hi = max(p0[size_t(i)], p1[size_t(i)]);
        n.length = length(p1[size_t(i)] - p0[size_t(i)]);
        n.edge = ids[size_t(i)];
        n.always = always[size_t(i)] != 0;
        const Vec3f s = n0[size_t(i)] + n1[size_t(i)];
        if (n.always || !(length(s) > 1e-6f)) {
            n.cone_axis = Vec3f(0.f, 0.f, 1.f);
            n.cone_cos = -1.f;
        } else {
            n.cone_axis = normalize(s);
            n.cone_cos = dot(n.cone_axis, n0[size_t(i)]);
        }
        leaf_of_[size_t(n.edge)] = index;
        return index;
    }
    // Median split of the centroids along the box's longest axis.
    Vec3f lo(1e30f), hi(-1e30f);
    for (int k = begin; k < end; ++k) {
        const Vec3f c = (p0[size_t(items[size_t(k)])] + p1[size_t(items[size_t(k)])]) * 0.5f;
        lo = min(lo, c);
        hi = max(hi, c);
    }
    const Vec3f ext = hi - lo;
    const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    const int mid = (begin + end) / 2;
    std::nth_element(items.begin() + begin, items.begin() + mid, items.begin() + end, [&](int32_t a, int32_t b) {
        return (p0[size_t(a)][axis] + p1[size_t(a)][axis]) < (p0[size_t(b)][axis] + p1[size_t(b)][axis]);
    });
    const int32_t l = build_node(items, begin, mid, index, p0, p1, n0, n1, always, ids);
    const int32_t r = build_node(items, mid, end, index, p0, p1, n0, n1, always, ids);
    Node& n = nodes_[size_t(index)];
    const Node &a = nodes_[size_t(l)], &b = nodes_[size_t(r)];
    n.left = l;
    n.right = r;
    n.lo = min(a.lo, b.lo);
    n.hi = max(a.hi, b.hi);
    n.length = a.length + b.length;
    n.always = a.always || b.always;
    // The union of the two normal cones (conservative).
    if (a.cone_cos <= -1.f || b.cone_cos <= -1.f) {
        n.cone_axis = Vec3f(0.f, 0.f, 1.f);
        n.cone_cos = -1.f;
    } else {
        const Vec3f s = a.cone_axis + b.cone_axis;
        if (!(length(s) > 1e-6f)) {
            n.cone_cos = -1.f;
            n.cone_axis = Vec3f(0.f, 0.f, 1.f);
        } else {
            n.cone_axis = normalize(s);
            const float half = std::max(angle_between(n.cone_axis, a.cone_axis) + std::acos(a.cone_cos),
                                        angle_between(n.cone_axis, b.cone_axis) + std::acos(b.cone_cos));
            n.cone_cos = half >= kPi ? -1.f : std::cos(half);
        }
    }
    return index;
}

void EdgeHierarchy::build(const Scene& scene, const std::vector<int32_t>& edges) {
    const auto start = std::chrono::steady_clock::now();
    nodes_.clear();
    const std::vector<Edge>& all = scene.edges();
    leaf_of_.assign(all.size(), -1);
    const size_t n = edges.size();
    std::vector<Vec3f> p0(n), p1(n), n0(n), n1(n);
    std::vector<uint8_t> always(n);
    std::vector<int32_t> items(n);
    for (size_t i = 0; i < n; ++i) {
        const Edge& e = all[size_t(edges[i])];
        const Mesh& m = scene.meshes[size_t(e.mesh)];
        p0[i] = m.vertex(e.v0);
        p1[i] = m.vertex(e.v1);
        always[i] = e.kind != EdgeKind::Smooth;
        if (!always[i]) {
            n0[i] = normalize(m.face_normal(e.f0));
            n1[i] = normalize(m.face_normal(e.f1));
        }
        items[i] = int32_t(i);
    }
    if (n > 0) {
        nodes_.reserve(2 * n);
        build_node(items, 0, int(n), -1, p0, p1, n0, n1, always, edges);
    }
    build_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

float EdgeHierarchy::importance(const Query& q, const Node& n) const {
    // The box's bounding sphere seen from p: direction `dir`, angular radius beta.
    const Vec3f c = (n.lo + n.hi) * 0.5f;
    const float r = length(n.hi - n.lo) * 0.5f, d = length(c - q.p);
    if (!(d > r)) {
        // The point is inside the node's bounding sphere: only the length tells nodes apart.
        return n.length / std::max(1e-12f, r * r);
    }
    const Vec3f dir = (c - q.p) / d;
    const float sin_beta = r / d, cos_beta = std::sqrt(std::max(0.f, 1.f - sin_beta * sin_beta));
    auto sine = [](float cosine) { return std::sqrt(std::max(0.f, 1.f - cosine * cosine)); };
    // Silhouettes possible? Directions from the box to p lie within beta of -dir; faces with
    // normals within theta of the cone axis all face p (or all face away) when the angle b
    // between the axis and -dir satisfies b + theta + beta < pi/2 (or b - theta - beta > pi/2),
    // i.e. when theta + beta < pi/2 and |cos b| > sin(theta + beta).
    if (!n.always && n.cone_cos > -1.f) {
        const float cos_t = n.cone_cos, sin_t = sine(cos_t);
        const float cos_s = cos_t * cos_beta - sin_t * sin_beta, sin_s = sin_t * cos_beta + cos_t * sin_beta;
        if (cos_s > 0.f && sin_s >= 0.f && std::abs(dot(n.cone_axis, dir)) > sin_s) return 0.f;
    }
    // Only directions towards the lights? Apart when their angle exceeds beta + the cone's.
    if (q.cone && q.cone->cos_half > -1.f) {
        const float cos_c = q.cone->cos_half, sin_c = sine(cos_c);
        if (dot(dir, q.cone->axis) < cos_beta * cos_c - sin_beta * sin_c) return 0.f;
    }
    // A bound of the cosine at the point over the box's directions (the BSDF's support): the
    // cosine of max(0, a - beta), a the angle between the normal and dir (or pi - a, two-sided).
    float cos_a = dot(q.n, dir);
    if (q.two_sided) cos_a = std::abs(cos_a);
    float bound = 1.f;
    if (cos_a < cos_beta) {  // a > beta
        bound = cos_a * cos_beta + sine(cos_a) * sin_beta;
        if (bound <= 0.f) return 0.f;
    }
    // Distance to the box.
    const Vec3f below = max(n.lo - q.p, Vec3f(0.f)), above = max(q.p - n.hi, Vec3f(0.f));
    const float d2 = std::max(length_squared(below + above), 1e-12f);
    return n.length * bound / d2;
}

bool EdgeHierarchy::sample(const Query& q, float u, int32_t& edge, float& prob) const {
    if (nodes_.empty()) return false;
    int32_t at = 0;
    prob = 1.f;
    if (importance(q, nodes_[0]) <= 0.f) return false;
    while (nodes_[size_t(at)].left >= 0) {
        const Node& n = nodes_[size_t(at)];
        const float il = importance(q, nodes_[size_t(n.left)]), ir = importance(q, nodes_[size_t(n.right)]);
        if (!(il + ir > 0.f)) return false;
        const float pl = il / (il + ir);
        if (u < pl) {
            u = std::min(u / pl, 0.99999994f);
            prob *= pl;
            at = n.left;
        } else {
            u = std::min((u - pl) / (1.f - pl), 0.99999994f);
            prob *= 1.f - pl;
            at = n.right;
        }
    }
    edge = nodes_[size_t(at)].edge;
    return prob > 0.f;
}

float EdgeHierarchy::pdf(const Query& q, int32_t edge) const {
    if (size_t(edge) >= leaf_of_.size() || leaf_of_[size_t(edge)] < 0) return 0.f;
    if (importance(q, nodes_[0]) <= 0.f) return 0.f;
    float prob = 1.f;
    for (int32_t at = leaf_of_[size_t(edge)]; nodes_[size_t(at)].parent >= 0;) {
        const int32_t up = nodes_[size_t(at)].parent;
        const Node& n = nodes_[size_t(up)];
        const float il = importance(q, nodes_[size_t(n.left)]), ir = importance(q, nodes_[size_t(n.right)]);
        const float mine = at == n.left ? il : ir;
        if (!(mine > 0.f)) return 0.f;
        prob *= mine / (il + ir);
        at = up;
    }
    return prob;
}

}  // namespace edgepath
