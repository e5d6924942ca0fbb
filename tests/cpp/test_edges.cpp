// Edge extraction: welding by position, kinds of edges, what is dropped.
#include <gtest/gtest.h>

#include <map>
#include <string>
#include <vector>

#include "scene/edges.h"
#include "support/shapes.h"

namespace edgepath {
namespace {

std::map<EdgeKind, int> count_kinds(const std::vector<Edge>& edges) {
    std::map<EdgeKind, int> c;
    for (const Edge& e : edges) c[e.kind]++;
    return c;
}

std::vector<Edge> edges_of(const MeshData& m) {
    std::vector<Edge> out;
    build_mesh_edges(m.desc(0), 0, out);
    return out;
}

TEST(Edges, BoxWithDuplicatedCornersHasTwelveCreases) {
    // 6 separate quads (24 vertices): welding by position joins them into a closed box; the 6
    // face diagonals are flat and dropped.
    MeshData box = make_box(Vec3f(0, 0, 0), Vec3f(1, 2, 3));
    ASSERT_EQ(box.num_vertices(), 24);
    auto edges = edges_of(box);
    auto c = count_kinds(edges);
    EXPECT_EQ(edges.size(), 12u);
    EXPECT_EQ(c[EdgeKind::Crease], 12);
    for (const Edge& e : edges) {
        EXPECT_GE(e.f1, 0);
        EXPECT_NE(e.f0, e.f1);
    }
}

TEST(Edges, QuadHasFourBoundariesAndNoDiagonal) {
    MeshData quad = make_quad(Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0));
    auto edges = edges_of(quad);
    EXPECT_EQ(edges.size(), 4u);
    EXPECT_EQ(count_kinds(edges)[EdgeKind::Boundary], 4);
}

TEST(Edges, SmoothSphereWithSeamIsClosed) {
    // The uv seam duplicates a column of vertices, the poles a row each: no false boundary, no
    // crease (the normals agree along the seam), every edge a smooth-surface edge.
    MeshData sphere = make_sphere(Vec3f(0, 0, 0), 1.f, 8, 12);
    auto edges = edges_of(sphere);
    auto c = count_kinds(edges);
    EXPECT_EQ(c[EdgeKind::Boundary], 0);
    EXPECT_EQ(c[EdgeKind::Crease], 0);
    // Closed: 86 distinct positions, 168 faces, so E = V + F - 2 = 252 edges; the 72 diagonals
    // of the planar quads of the 6 non-polar bands are flat (up to the rounding of their float
    // corners) and dropped.
    EXPECT_EQ(int(edges.size()), 252 - 72);
}

TEST(Edges, NearlyCoplanarFacesKeepTheirEdge) {
    // Two faces 1e-4 rad apart fold where the eye lies between their planes (a scan's nearly flat
    // neighbours seen edge-on at its outline): their edge is kept; two faces of one plane are not.
    for (float lift : {0.f, 1e-4f}) {
        MeshData m;
        m.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, lift};
        m.indices = {0, 1, 2, 2, 1, 3};
        auto edges = edges_of(m);
        EXPECT_EQ(int(edges.size()), lift == 0.f ? 4 : 5) << lift;
        if (lift != 0.f) {
            auto vertex = [&](int32_t v) { return Vec3f::load(m.vertices.data() + 3 * v); };
            auto normal = [&](int64_t f) {
                const int32_t* t = m.indices.data() + 3 * f;
                return normalize(cross(vertex(t[1]) - vertex(t[0]), vertex(t[2]) - vertex(t[0])));
            };
            // Above the first face's plane and below the second's, z = lift (x + y - 1).
            const Vec3f eye(0.9f, 0.9f, 4e-5f);
            int folds = 0;
            for (const Edge& e : edges)
                if (e.kind != EdgeKind::Boundary)
                    folds += is_silhouette(eye, vertex(e.v0), normal(e.f0), normal(e.f1), e.kind);
            EXPECT_EQ(folds, 1);
        }
    }
}

TEST(Edges, KeepFlatKeepsTheListWhateverTheLift) {
    // A scene whose vertices move keeps the edges between nearly coplanar faces, marked flat, so
    // that its edge list does not change when a move turns an edge flat or back: the same edges,
    // in the same order, whether the corner is lifted (a fold) or not (one plane).
    std::vector<std::vector<Edge>> lists;
    for (float lift : {0.f, 1e-7f, 1e-4f}) {
        MeshData m;
        m.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, lift};
        m.indices = {0, 1, 2, 2, 1, 3};
        std::vector<Edge> dropped, kept;
        build_mesh_edges(m.desc(0), 0, dropped);
        build_mesh_edges(m.desc(0), 0, kept, true);
        const bool fold = lift > 1e-5f;
        EXPECT_EQ(int(dropped.size()), fold ? 5 : 4) << lift;
        ASSERT_EQ(kept.size(), 5u) << lift;
        int flat = 0;
        for (const Edge& e : kept) flat += e.flat;
        EXPECT_EQ(flat, fold ? 0 : 1) << lift;
        for (const Edge& e : dropped) EXPECT_FALSE(e.flat);
        lists.push_back(kept);
    }
    for (const std::vector<Edge>& list : lists)
        for (size_t i = 0; i < list.size(); ++i) {
            const Edge &a = list[i], &b = lists[0][i];
            EXPECT_TRUE(a.mesh == b.mesh && a.v0 == b.v0 && a.v1 == b.v1 && a.f0 == b.f0 && a.f1 == b.f1 &&
                        a.kind == b.kind && a.seam == b.seam)
                << "edge " << i;
        }
    // A quad with continuous uvs: its diagonal is flat (with a uv seam it would be a crease).
    MeshData quad = make_quad(Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0));
    std::vector<Edge> out;
    build_mesh_edges(quad.desc(0), 0, out, true);
    int flat = 0;
    for (const Edge& e : out) flat += e.flat;
    EXPECT_EQ(flat, 1);  // the diagonal of the one plane
}

// Two edge lists the same, field by field.
void expect_same_edges(const std::vector<Edge>& got, const std::vector<Edge>& want, const std::string& what) {
    ASSERT_EQ(got.size(), want.size()) << what;
    for (size_t i = 0; i < got.size(); ++i) {
        const Edge &a = got[i], &b = want[i];
        EXPECT_TRUE(a.mesh == b.mesh && a.v0 == b.v0 && a.v1 == b.v1 && a.f0 == b.f0 && a.f1 == b.f1 &&
                    a.kind == b.kind && a.seam == b.seam && a.flat == b.flat)
            << what << ": edge " << i;
    }
}

TEST(Edges, KeptListEqualsAFreshBuildAfterEveryKindOfMove) {
    // A mesh's part of an edge list kept across moves (a scene whose vertices move) is refreshed
    // to what build_mesh_edges with keep_flat gives, bit for bit, where a move keeps the welding
    // and the degenerate faces (the flat marks recomputed), and refuses (built anew) where it does
    // not. A small sphere whose faces own their corners (welded by position, flat shaded), and a
    // folded quad whose diagonal turns flat and back.
    const MeshData sphere = make_sphere(Vec3f(0, 0, 0), 1.f, 6, 8);
    MeshData m;
    for (int32_t i : sphere.indices) {
        m.vertices.insert(m.vertices.end(), sphere.vertices.begin() + 3 * i, sphere.vertices.begin() + 3 * i + 3);
        m.indices.push_back(int32_t(m.indices.size()));
    }
    MeshData quad;
    quad.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 1e-3f};
    quad.indices = {0, 1, 2, 2, 1, 3};
    MeshEdgeList list, quad_list;
    std::vector<Edge> all, quad_all;
    // `l`'s part of `in` (after an edge of another mesh) brought up to date: refreshed where
    // `kept`, else built anew; then compared with a fresh build.
    auto check = [](MeshEdgeList& l, std::vector<Edge>& in, const MeshData& mesh, bool kept, const std::string& what) {
        std::vector<Edge> fresh;
        build_mesh_edges(mesh.desc(0), 3, fresh, true);
        const std::vector<Edge> before = in;
        const std::vector<uint8_t> degenerate = degenerate_faces(mesh.desc(0));
        const bool refreshed = !in.empty() && l.refresh(mesh.desc(0), degenerate, in);
        EXPECT_EQ(refreshed, kept) << what;
        if (!refreshed) {
            if (!in.empty()) expect_same_edges(in, before, what + ": refused, nothing changed");
            in.assign(1, Edge());
            l.build(mesh.desc(0), degenerate, 3, in);
        }
        EXPECT_EQ(in.front().mesh, -1) << what;  // the other mesh's edge left alone
        expect_same_edges(std::vector<Edge>(in.begin() + 1, in.end()), fresh, what);
        return fresh;
    };
    check(list, all, m, false, "the first list");
    check(list, all, m, true, "nothing moved");
    for (float& x : m.vertices) x *= 1.f + 1e-4f;
    check(list, all, m, true, "every vertex moved");
    // One corner's copy moved off the others: its faces no longer share their edges there.
    const float x0 = m.vertices[0];
    m.vertices[0] += 1e-3f;
    check(list, all, m, false, "a welded position split");
    m.vertices[0] = x0;
    check(list, all, m, false, "welded again");
    // Face 10's third corner (every copy of its position) onto the midpoint of the other two:
    // a degenerate face, its neighbours' edges with it boundaries.
    const int32_t* t = m.indices.data() + 30;
    const Vec3f p0 = Vec3f::load(&m.vertices[3 * size_t(t[0])]), p1 = Vec3f::load(&m.vertices[3 * size_t(t[1])]);
    const Vec3f p2 = Vec3f::load(&m.vertices[3 * size_t(t[2])]), mid = (p0 + p1) * 0.5f;
    int moved = 0;
    for (size_t v = 0; v < m.vertices.size(); v += 3)
        if (m.vertices[v] == p2.x && m.vertices[v + 1] == p2.y && m.vertices[v + 2] == p2.z) {
            m.vertices[v] = mid.x, m.vertices[v + 1] = mid.y, m.vertices[v + 2] = mid.z;
            ++moved;
        }
    EXPECT_GE(moved, 3);
    const std::vector<Edge> degenerate = check(list, all, m, false, "a degenerate face");
    EXPECT_GT(count_kinds(degenerate)[EdgeKind::Boundary], 0);
    for (float& x : m.vertices) x *= 1.f - 1e-4f;
    check(list, all, m, true, "moved again");
    // The quad's diagonal: a fold, flat, a fold again; the kept list serves each time.
    const std::vector<Edge> fold = check(quad_list, quad_all, quad, false, "a fold");
    quad.vertices[11] = 0.f;
    const std::vector<Edge> flat = check(quad_list, quad_all, quad, true, "flat");
    quad.vertices[11] = 1e-3f;
    check(quad_list, quad_all, quad, true, "a fold again");
    int flats[2] = {0, 0};
    for (const Edge& e : fold) flats[0] += e.flat;
    for (const Edge& e : flat) flats[1] += e.flat;
    EXPECT_EQ(flats[0], 0);
    EXPECT_EQ(flats[1], 1);
}

TEST(Edges, UvSeamInsideAFlatQuadIsKept) {
    // Two coplanar triangles: their shared diagonal is dropped while the uvs agree along it, and
    // kept as a crease (textures may jump there) when each face has its own uvs for it.
    MeshData quad = make_quad(Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0));
    ASSERT_EQ(quad.num_triangles(), 2);
    auto with_uvs = [&](const std::vector<float>& uvs, const std::vector<int32_t>& uv_indices) {
        MeshDesc d = quad.desc(0);
        d.uvs = uvs.data();
        d.num_uvs = int64_t(uvs.size() / 2);
        d.uv_indices = uv_indices.data();
        std::vector<Edge> out;
        build_mesh_edges(d, 0, out);
        for (const Edge& e : out) EXPECT_EQ(e.seam, e.kind == EdgeKind::Crease);  // the uvs jump
        return count_kinds(out);
    };
    // One uv per vertex (continuous) against the second face's corners shifted in u (a seam).
    std::vector<float> uvs = {0, 0, 1, 0, 1, 1, 0, 1, 0.5f, 0, 0.5f, 1, 0.5f, 0.5f, 0.25f, 0.75f};
    std::vector<int32_t> same(quad.indices.begin(), quad.indices.end()), seam = same;
    for (int k = 3; k < 6; ++k) seam[size_t(k)] = 4 + k - 3;
    auto a = with_uvs(uvs, same), b = with_uvs(uvs, seam);
    EXPECT_EQ(a[EdgeKind::Boundary], 4);
    EXPECT_EQ(a[EdgeKind::Crease], 0);
    EXPECT_EQ(b[EdgeKind::Boundary], 4);
    EXPECT_EQ(b[EdgeKind::Crease], 1);
}

TEST(Edges, AUvSeamOfASmoothMeshIsMarkedUvOnly) {
    // The quad's two faces with one shading normal: a seam of uvs alone is uv_only; with
    // vertex colours that differ across it too, or without shading normals, it is not.
    MeshData quad = make_quad(Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0));
    std::vector<float> uvs = {0, 0, 1, 0, 1, 1, 0, 1, 0.5f, 0, 0.5f, 1, 0.5f, 0.5f, 0.25f, 0.75f};
    std::vector<int32_t> seam(quad.indices.begin(), quad.indices.end());
    for (int k = 3; k < 6; ++k) seam[size_t(k)] = 4 + k - 3;
    const std::vector<float> normals = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
    // The colours of vertex 2 (the diagonal's end the second face reaches through its own
    // corner) told apart by duplicating it.
    auto seams = [&](bool with_normals, bool colours_jump) {
        MeshData m = quad;
        std::vector<int32_t> indices = m.indices;
        std::vector<float> colours(size_t(m.num_vertices()) * 3, 0.5f);
        if (colours_jump) {
            m.vertices.insert(m.vertices.end(), {m.vertices[6], m.vertices[7], m.vertices[8]});
            colours.insert(colours.end(), {0.9f, 0.1f, 0.1f});
            for (int k = 3; k < 6; ++k)
                if (indices[size_t(k)] == 2) indices[size_t(k)] = int32_t(m.num_vertices() - 1);
        }
        std::vector<float> n = normals;
        if (colours_jump) n.insert(n.end(), {0, 0, 1});
        MeshDesc d = m.desc(0);
        d.indices = indices.data();
        d.uvs = uvs.data();
        d.num_uvs = int64_t(uvs.size() / 2);
        d.uv_indices = seam.data();
        if (with_normals) {
            d.normals = n.data();
            d.num_normals = int64_t(n.size() / 3);
            d.normal_indices = indices.data();
        }
        d.colors = colours.data();
        std::vector<Edge> out;
        build_mesh_edges(d, 0, out);
        std::vector<int> kinds;
        for (const Edge& e : out)
            if (e.kind == EdgeKind::Crease) kinds.push_back(e.uv_only ? 1 : 0);
        return kinds;
    };
    EXPECT_EQ(seams(true, false), std::vector<int>{1});
    EXPECT_EQ(seams(true, true), std::vector<int>{0});
    EXPECT_EQ(seams(false, false), std::vector<int>{0});
}

// A mesh's faces with their winding turned.
MeshData turned(MeshData m) {
    for (size_t k = 0; k < m.indices.size(); k += 3) std::swap(m.indices[k + 1], m.indices[k + 2]);
    return m;
}

std::vector<Solid> solids_of(const MeshData& m, bool& closed, std::vector<int32_t>& of_face) {
    std::vector<Solid> solids;
    const MeshDesc d = m.desc(0);
    std::vector<Edge> edges;
    build_mesh_edges(d, 0, edges);
    closed = mesh_solids(d, 0, edges, solids, of_face);
    return solids;
}

TEST(Edges, ClosedMeshesBoundSolidsOnTheSideOfPositiveVolume) {
    bool closed = false;
    std::vector<int32_t> of;
    // A box whose faces turn outwards: its solid behind them, its box the box.
    const MeshData box = make_box(Vec3f(-1, 0, 2), Vec3f(1, 3, 5));
    std::vector<Solid> s = solids_of(box, closed, of);
    ASSERT_TRUE(closed);
    ASSERT_EQ(s.size(), 1u);
    EXPECT_EQ(s[0].side, -1);
    EXPECT_EQ(s[0].lo.x, -1.0);
    EXPECT_EQ(s[0].lo.y, 0.0);
    EXPECT_EQ(s[0].lo.z, 2.0);
    EXPECT_EQ(s[0].hi.x, 1.0);
    EXPECT_EQ(s[0].hi.y, 3.0);
    EXPECT_EQ(s[0].hi.z, 5.0);
    EXPECT_EQ(of, std::vector<int32_t>(size_t(box.num_triangles()), 0));
    // Turned inside out: in front of them.
    s = solids_of(turned(box), closed, of);
    ASSERT_TRUE(closed);
    EXPECT_EQ(s[0].side, 1);
    // A smooth sphere (welded poles, no seam), and a sphere with a box in one mesh: a solid
    // each, the faces of each part on their own.
    const MeshData sphere = make_sphere(Vec3f(0, 0, 0), 1.f, 8, 12);
    s = solids_of(sphere, closed, of);
    ASSERT_TRUE(closed);
    ASSERT_EQ(s.size(), 1u);
    EXPECT_EQ(s[0].side, -1);
    MeshData both = make_box(Vec3f(3, 0, 0), Vec3f(4, 1, 1));
    MeshData inner = turned(make_box(Vec3f(3.25f, 0.25f, 0.25f), Vec3f(3.75f, 0.75f, 0.75f)));
    both.append(inner);  // a hollow box: its inner faces turn inwards, towards the hollow
    s = solids_of(both, closed, of);
    ASSERT_TRUE(closed);
    ASSERT_EQ(s.size(), 2u);
    EXPECT_EQ(s[0].side, -1);  // the outer faces: the solid behind them
    EXPECT_EQ(s[1].side, 1);   // the hollow's faces: its part's volume is negative
    EXPECT_EQ(s[1].lo.x, 3.25);
    for (int64_t f = 0; f < both.num_triangles(); ++f) EXPECT_EQ(of[size_t(f)], f < 12 ? 0 : 1);
}

TEST(Edges, OpenOrInconsistentMeshesBoundNoSolid) {
    bool closed = true;
    std::vector<int32_t> of;
    MeshData open = make_box(Vec3f(0, 0, 0), Vec3f(1, 1, 1));
    open.indices.resize(open.indices.size() - 6);  // the +y face gone
    EXPECT_TRUE(solids_of(open, closed, of).empty());
    EXPECT_FALSE(closed);
    MeshData flipped = make_box(Vec3f(0, 0, 0), Vec3f(1, 1, 1));
    std::swap(flipped.indices[1], flipped.indices[2]);  // one face wound against the others
    EXPECT_TRUE(solids_of(flipped, closed, of).empty());
    EXPECT_FALSE(closed);
}

TEST(Edges, WeldedAndUnweldedMeshesGiveTheSameEdges) {
    // A folded strip, once with shared vertices and once with every face owning its vertices.
    const std::vector<float> p = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0.5f, 0, 2, 0};
    const std::vector<int32_t> tris = {0, 1, 2, 1, 3, 2, 2, 3, 4};
    MeshData shared, split;
    shared.vertices = p;
    shared.indices = tris;
    for (int32_t i : tris) {
        split.vertices.insert(split.vertices.end(), p.begin() + 3 * i, p.begin() + 3 * i + 3);
        split.indices.push_back(int32_t(split.indices.size()));
    }
    auto a = count_kinds(edges_of(shared)), b = count_kinds(edges_of(split));
    EXPECT_EQ(a, b);
    EXPECT_EQ(a[EdgeKind::Boundary], 5);
    EXPECT_EQ(a[EdgeKind::Crease], 2);  // both inner edges fold (flat shading)
    // Flat shading jumps by the faces' angle only: no seam.
    for (const Edge& e : edges_of(split)) EXPECT_FALSE(e.seam);
}

TEST(Edges, SplitNormalsMakeACreaseEvenWhenCoplanar) {
    MeshData quad = make_quad(Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0));
    // Smooth normals, equal along the diagonal: the diagonal is dropped.
    quad.normals.assign(12, 0.f);
    for (int v = 0; v < 4; ++v) quad.normals[3 * v + 2] = 1.f;
    EXPECT_EQ(edges_of(quad).size(), 4u);
    // Separate vertices per face with different normals along the diagonal: a crease.
    MeshData split;
    for (int f = 0; f < 2; ++f)
        for (int k = 0; k < 3; ++k) {
            int32_t v = quad.indices[3 * f + k];
            split.vertices.insert(split.vertices.end(), quad.vertices.begin() + 3 * v, quad.vertices.begin() + 3 * v + 3);
            split.normals.insert(split.normals.end(), {f == 0 ? 0.3f : -0.3f, 0.f, 0.95f});
            split.indices.push_back(3 * f + k);
        }
    auto c = count_kinds(edges_of(split));
    EXPECT_EQ(c[EdgeKind::Boundary], 4);
    EXPECT_EQ(c[EdgeKind::Crease], 1);
    for (const Edge& e : edges_of(split)) EXPECT_EQ(e.seam, e.kind == EdgeKind::Crease);  // a modelled crease
}

TEST(Edges, EdgeSharedByThreeFacesIsKeptForEachFace) {
    MeshData fan;
    fan.vertices = {0, 0, 0, 0, 1, 0, 1, 0, 0, -1, 0, 0.2f, 0, 0, 1};
    fan.indices = {0, 1, 2, 1, 0, 3, 0, 1, 4};  // three fins on the edge (0, 1)
    auto edges = edges_of(fan);
    int on_shared = 0;
    for (const Edge& e : edges)
        if ((e.v0 == 0 && e.v1 == 1) || (e.v0 == 1 && e.v1 == 0)) {
            ++on_shared;
            EXPECT_EQ(e.kind, EdgeKind::Boundary);
        }
    EXPECT_EQ(on_shared, 3);
    EXPECT_EQ(edges.size(), 3u + 6u);
}

TEST(Edges, DegenerateEdgesAreSkipped) {
    MeshData m;
    m.vertices = {0, 0, 0, 1, 0, 0, 1, 0, 0, 0, 1, 0};  // vertices 1 and 2 coincide
    m.indices = {0, 1, 3, 1, 2, 3};
    for (const Edge& e : edges_of(m)) {
        const bool degenerate = (e.v0 == 1 && e.v1 == 2) || (e.v0 == 2 && e.v1 == 1);
        EXPECT_FALSE(degenerate);
    }
}

TEST(Edges, SilhouettePredicate) {
    const Vec3f e0(0, 0, 0), n0(0, 0, 1), n1(1, 0, 0);  // a convex corner
    EXPECT_TRUE(is_silhouette(Vec3f(-1, 0, 1), e0, n0, n1, EdgeKind::Smooth));   // sees only face 0
    EXPECT_FALSE(is_silhouette(Vec3f(1, 0, 1), e0, n0, n1, EdgeKind::Smooth));   // sees both
    EXPECT_FALSE(is_silhouette(Vec3f(-1, 0, -1), e0, n0, n1, EdgeKind::Smooth)); // sees neither
    EXPECT_TRUE(is_silhouette(Vec3f(1, 0, 1), e0, n0, n1, EdgeKind::Boundary));
}

}  // namespace
}  // namespace edgepath
