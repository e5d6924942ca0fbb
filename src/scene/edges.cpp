#include "scene/edges.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <limits>

#include "scene/chunks.h"
#include "scene/desc.h"
#include "scene/geometry.h"

namespace edgepath {

namespace {

struct PositionKey {
    uint32_t bits[3];
    bool operator==(const PositionKey& o) const {
        return bits[0] == o.bits[0] && bits[1] == o.bits[1] && bits[2] == o.bits[2];
    }
};

struct PositionHash {
    size_t operator()(const PositionKey& k) const {
        uint64_t h = 0x9E3779B97F4A7C15ull;
        for (uint32_t b : k.bits) h = (h ^ b) * 0xBF58476D1CE4E5B9ull;
        return size_t(h ^ (h >> 31));
    }
};

PositionKey key_of(const float* p) {
    PositionKey k;
    for (int i = 0; i < 3; ++i) {
        float v = p[i] == 0.f ? 0.f : p[i];  // -0 and +0 are one position
        std::memcpy(&k.bits[i], &v, sizeof v);
    }
    return k;
}

struct HalfEdge {
    int64_t lo, hi;  // welded vertex ids, lo < hi
    int64_t face;
    int32_t a, b;    // the face's own vertex indices, in the face's order
};

// Faces closer than this angle (radians) to one plane, facing the same way, are taken for one
// plane. A plane given by float corners is flat to about 1e-6 of its faces' size; which side of
// such a pair an eye is on is then rounding, not geometry. The bunny's chin had an outline on two
// faces 4.9e-4 rad apart (dropped while the bound was 1e-6 of the cosine, 1.4e-3 rad).
constexpr double kCoplanarAngle = 1e-5;

bool nearly_coplanar(const MeshDesc& m, int64_t f, int64_t g) {
    auto normal = [&](int64_t face) {
        const int32_t* t = m.indices + 3 * face;
        const Vec3d p0(Vec3f::load(m.vertices + 3 * int64_t(t[0])));
        return cross(Vec3d(Vec3f::load(m.vertices + 3 * int64_t(t[1]))) - p0,
                     Vec3d(Vec3f::load(m.vertices + 3 * int64_t(t[2]))) - p0);
    };
    const Vec3d a = normal(f), b = normal(g);
    const double c = dot(a, b);
    return c > 0.0 && length(cross(a, b)) <= kCoplanarAngle * c;
}

// The shading normal a face uses at one of its vertices (vertex index v of face f).
Vec3f shading_normal(const MeshDesc& m, int64_t f, int32_t v) {
    const int32_t* t = m.indices + 3 * f;
    const int32_t* n = m.normal_indices ? m.normal_indices + 3 * f : t;
    for (int k = 0; k < 3; ++k)
        if (t[k] == v) return Vec3f::load(m.normals + 3 * int64_t(n[k]));
    return Vec3f(0.f);
}

// The uv a face uses at one of its vertices (vertex index v of face f).
Vec2f face_uv(const MeshDesc& m, int64_t f, int32_t v) {
    const int32_t* t = m.indices + 3 * f;
    const int32_t* u = m.uv_indices ? m.uv_indices + 3 * f : t;
    for (int k = 0; k < 3; ++k)
        if (t[k] == v) return Vec2f(m.uvs[2 * int64_t(u[k])], m.uvs[2 * int64_t(u[k]) + 1]);
    return Vec2f(0.f, 0.f);
}

// The welded vertex ids: the vertices at one position share one, numbered in the order of their
// first occurrence (an open-addressing table of the first vertex at each position).
std::vector<int64_t> weld_positions(const MeshDesc& m) {
    const size_t n = size_t(m.num_vertices);
    std::vector<int64_t> weld(n);
    size_t capacity = 16;
    while (capacity < 2 * n) capacity <<= 1;
    std::vector<int64_t> first(capacity, -1);
    const PositionHash hash;
    int64_t ids = 0;
    for (size_t v = 0; v < n; ++v) {
        const PositionKey key = key_of(m.vertices + 3 * v);
        for (size_t h = hash(key) & (capacity - 1);; h = (h + 1) & (capacity - 1)) {
            if (first[h] < 0) {
                first[h] = int64_t(v);
                weld[v] = ids++;
                break;
            }
            if (key_of(m.vertices + 3 * first[h]) == key) {
                weld[v] = weld[size_t(first[h])];
                break;
            }
        }
    }
    return weld;
}

}  // namespace

std::vector<uint8_t> degenerate_faces(const MeshDesc& m) {
    std::vector<uint8_t> out(size_t(m.num_triangles));
    for (int64_t f = 0; f < m.num_triangles; ++f) {
        const int32_t* t = m.indices + 3 * f;
        out[size_t(f)] = is_degenerate_triangle(Vec3f::load(m.vertices + 3 * int64_t(t[0])),
                                                Vec3f::load(m.vertices + 3 * int64_t(t[1])),
                                                Vec3f::load(m.vertices + 3 * int64_t(t[2])));
    }
    return out;
}

namespace {

// build_mesh_edges from the welding and the degenerate faces; with `flattenable`, also appends
// for each edge whether it is flat where its faces are nearly coplanar.
void pair_faces(const MeshDesc& m, int32_t mesh_index, const std::vector<int64_t>& weld,
                const std::vector<uint8_t>& degenerate, std::vector<Edge>& out, bool keep_flat,
                std::vector<uint8_t>* flattenable) {
    std::vector<HalfEdge> half;
    half.reserve(size_t(m.num_triangles) * 3);
    for (int64_t f = 0; f < m.num_triangles; ++f) {
        const int32_t* t = m.indices + 3 * f;
        if (degenerate[size_t(f)]) continue;
        for (int k = 0; k < 3; ++k) {
            int32_t a = t[k], b = t[(k + 1) % 3];
            int64_t wa = weld[size_t(a)], wb = weld[size_t(b)];
            if (wa == wb) continue;  // degenerate edge
            half.push_back({std::min(wa, wb), std::max(wa, wb), f, a, b});
        }
    }
    std::sort(half.begin(), half.end(), [](const HalfEdge& x, const HalfEdge& y) {
        return x.lo != y.lo ? x.lo < y.lo : (x.hi != y.hi ? x.hi < y.hi : x.face < y.face);
    });
    for (size_t i = 0; i < half.size();) {
        size_t j = i + 1;
        while (j < half.size() && half[j].lo == half[i].lo && half[j].hi == half[i].hi) ++j;
        const size_t count = j - i;
        if (count == 2) {
            const HalfEdge &h0 = half[i], &h1 = half[i + 1];
            bool shading_jump = m.normals == nullptr;
            if (!shading_jump) {
                // Split normals along the edge: a shading discontinuity.
                for (int32_t v : {h0.a, h0.b}) {
                    // the same position in the other face
                    int32_t w = weld[size_t(v)] == weld[size_t(h1.a)] ? h1.a : h1.b;
                    if (length_squared(shading_normal(m, h0.face, v) - shading_normal(m, h1.face, w)) > 1e-12f)
                        shading_jump = true;
                }
            }
            // uvs that differ across the edge (a seam, a pole's fan): textures may jump there.
            bool value_jump = false, uv_jump = false;
            if (m.uvs) {
                for (int32_t v : {h0.a, h0.b}) {
                    int32_t w = weld[size_t(v)] == weld[size_t(h1.a)] ? h1.a : h1.b;
                    const Vec2f a = face_uv(m, h0.face, v), b = face_uv(m, h1.face, w);
                    if (a.x != b.x || a.y != b.y) value_jump = uv_jump = true;
                }
            }
            const bool normal_jump = shading_jump && m.normals != nullptr;
            // Vertex colours that differ across the edge (welded positions, different colours):
            // the diffuse reflectance jumps there, as at a uv seam.
            bool colour_jump = false;
            if (m.colors)
                for (int32_t v : {h0.a, h0.b}) {
                    int32_t w = weld[size_t(v)] == weld[size_t(h1.a)] ? h1.a : h1.b;
                    for (int c = 0; c < 3; ++c)
                        if (m.colors[3 * int64_t(v) + c] != m.colors[3 * int64_t(w) + c])
                            value_jump = colour_jump = true;
                }
            shading_jump = shading_jump || value_jump;
            // Two faces at an angle fold where the eye lies between their planes (a scan's nearly
            // flat neighbours seen edge-on at its outline): only faces within kCoplanarAngle of
            // one plane, the rounding of a plane's float corners, drop their edge.
            const bool can_be_flat = !value_jump && !(shading_jump && m.normals != nullptr);
            const bool flat = can_be_flat && nearly_coplanar(m, h0.face, h1.face);
            if (!flat || keep_flat) {
                Edge e;
                e.mesh = mesh_index;
                e.v0 = h0.a;
                e.v1 = h0.b;
                e.f0 = h0.face;
                e.f1 = h1.face;
                e.kind = shading_jump ? EdgeKind::Crease : EdgeKind::Smooth;
                e.seam = value_jump || (shading_jump && m.normals != nullptr);
                e.uv_only = uv_jump && !colour_jump && !normal_jump && m.normals != nullptr;
                e.flat = flat;
                out.push_back(e);
                if (flattenable) flattenable->push_back(can_be_flat);
            }
        } else {
            // A boundary (one face), or an edge shared by more than two faces: each face's side
            // is a boundary of its own; sampling them all is conservative (where nothing jumps,
            // the two sides agree and the sample adds zero).
            for (size_t k = i; k < j; ++k) {
                Edge e;
                e.mesh = mesh_index;
                e.v0 = half[k].a;
                e.v1 = half[k].b;
                e.f0 = half[k].face;
                e.kind = EdgeKind::Boundary;
                out.push_back(e);
                if (flattenable) flattenable->push_back(0);
            }
        }
        i = j;
    }
}

}  // namespace

void build_mesh_edges(const MeshDesc& m, int32_t mesh_index, std::vector<Edge>& out, bool keep_flat) {
    pair_faces(m, mesh_index, weld_positions(m), degenerate_faces(m), out, keep_flat, nullptr);
}

void MeshEdgeList::build(const MeshDesc& m, const std::vector<uint8_t>& degenerate, int32_t mesh_index,
                         std::vector<Edge>& out) {
    weld_ = weld_positions(m);
    degenerate_ = degenerate;
    flattenable_.clear();
    begin_ = out.size();
    pair_faces(m, mesh_index, weld_, degenerate_, out, true, &flattenable_);
    count_ = out.size() - begin_;
}

bool MeshEdgeList::refresh(const MeshDesc& m, const std::vector<uint8_t>& degenerate, std::vector<Edge>& all) const {
    if (begin_ + count_ > all.size() || degenerate != degenerate_ || weld_positions(m) != weld_) return false;
    // The same pairs of faces: only where they lie changed (each edge on its own, in parallel
    // over chunks where there are many).
    over_chunks(int64_t(count_), 16384, [&](int64_t b, int64_t e) {
        for (size_t k = size_t(b); k < size_t(e); ++k) {
            Edge& edge = all[begin_ + k];
            edge.flat = flattenable_[k] && nearly_coplanar(m, edge.f0, edge.f1);
        }
    });
    return true;
}

bool mesh_solids(const MeshDesc& mesh, int32_t mesh_index, const std::vector<Edge>& edges, std::vector<Solid>& solids,
                 std::vector<int32_t>& solid_of_face) {
    const float* v = mesh.vertices;
    auto same = [&](int32_t a, int32_t b) {
        return v[3 * a] == v[3 * b] && v[3 * a + 1] == v[3 * b + 1] && v[3 * a + 2] == v[3 * b + 2];
    };
    for (const Edge& e : edges) {
        if (e.mesh != mesh_index) continue;
        if (e.kind == EdgeKind::Boundary || e.f1 < 0) return false;
        // Each face's direction along the edge (+1: from v0's position to v1's).
        int dir[2] = {0, 0};
        for (int k = 0; k < 2; ++k) {
            const int32_t* t = mesh.indices + 3 * (k == 0 ? e.f0 : e.f1);
            for (int c = 0; c < 3; ++c) {
                const int32_t a = t[c], b = t[(c + 1) % 3];
                if (same(a, e.v0) && same(b, e.v1)) dir[k] = 1;
                if (same(a, e.v1) && same(b, e.v0)) dir[k] = -1;
            }
        }
        if (dir[0] == 0 || dir[0] != -dir[1]) return false;
    }
    // The parts: vertices joined by position, then by faces.
    const size_t n = size_t(mesh.num_vertices);
    std::vector<int32_t> parent(n), order(n);
    for (size_t i = 0; i < n; ++i) parent[i] = order[i] = int32_t(i);
    auto root = [&](int32_t i) {
        while (parent[size_t(i)] != i) i = parent[size_t(i)] = parent[size_t(parent[size_t(i)])];
        return i;
    };
    auto join = [&](int32_t a, int32_t b) {
        a = root(a), b = root(b);
        if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
    };
    auto position = [&](int32_t i) { return std::array<float, 3>{v[3 * i], v[3 * i + 1], v[3 * i + 2]}; };
    std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) { return position(a) < position(b); });
    for (size_t k = 1; k < n; ++k)
        if (same(order[k], order[k - 1])) join(order[k], order[k - 1]);
    const std::vector<uint8_t> degenerate = degenerate_faces(mesh);
    for (int64_t f = 0; f < mesh.num_triangles; ++f) {
        if (degenerate[size_t(f)]) continue;
        const int32_t* t = mesh.indices + 3 * f;
        join(t[0], t[1]), join(t[0], t[2]);
    }
    const size_t base = solids.size();
    std::vector<int32_t> part_solid(n, -1);
    std::vector<double> volume;
    solid_of_face.assign(size_t(mesh.num_triangles), -1);
    for (int64_t f = 0; f < mesh.num_triangles; ++f) {
        if (degenerate[size_t(f)]) continue;
        const int32_t* t = mesh.indices + 3 * f;
        int32_t& id = part_solid[size_t(root(t[0]))];
        if (id < 0) {
            id = int32_t(solids.size());
            Solid sd;
            sd.lo = Vec3d(std::numeric_limits<double>::infinity());
            sd.hi = -sd.lo;
            solids.push_back(sd);
            volume.push_back(0.0);
        }
        solid_of_face[size_t(f)] = id;
        Solid& sd = solids[size_t(id)];
        Vec3d p[3];
        for (int c = 0; c < 3; ++c) {
            p[c] = Vec3d(double(v[3 * t[c]]), double(v[3 * t[c] + 1]), double(v[3 * t[c] + 2]));
            sd.lo = min(sd.lo, p[c]), sd.hi = max(sd.hi, p[c]);
        }
        volume[size_t(id) - base] += dot(p[0], cross(p[1], p[2]));
    }
    for (size_t k = 0; k < volume.size(); ++k) solids[base + k].side = volume[k] > 0.0 ? -1 : volume[k] < 0.0 ? 1 : 0;
    return true;
}

}  // namespace edgepath
