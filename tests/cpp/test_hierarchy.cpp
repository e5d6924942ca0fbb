// The edge hierarchy and the point sampler on an edge: sample() and pdf() agree with the
// empirical frequencies, densities integrate to one, awkward geometry gives finite results.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <tuple>
#include <vector>

#include "edgepath.h"
#include "edges/hierarchy.h"
#include "moved_scene.h"
#include "sampling/rng.h"
#include "scene/scene.h"
#include "support/shapes.h"

namespace edgepath {
namespace {

// A small camera and one matte material (its values kept alive by the owner).
struct MatteScene {
    std::vector<float> kd = {0.5f, 0.5f, 0.5f}, ks = {0, 0, 0}, rough = {0.5f};
    SceneDesc desc() {
        SceneDesc d;
        d.camera.width = d.camera.height = 8;
        d.camera.position[2] = -5;
        MaterialDesc m;
        m.diffuse = {kd.data(), 1, 1, 3};
        m.specular = {ks.data(), 1, 1, 3};
        m.roughness = {rough.data(), 1, 1, 1};
        d.materials.push_back(m);
        return d;
    }
};

struct HierarchyScene {
    MeshData sphere = make_sphere(Vec3f(0, 1, 0), 0.5f, 8, 16), box = make_box(Vec3f(1.5f, 0.2f, 0), Vec3f(0.4f, 0.4f, 0.4f)),
             quad = make_quad(Vec3f(-2, 0, -2), Vec3f(4, 0, 0), Vec3f(0, 0, 4));
    MatteScene matte;
    std::shared_ptr<const Scene> scene;
    HierarchyScene() { scene = build_scene(desc()); }
    // The description of the sphere, the box and the quad (matte).
    SceneDesc desc() {
        SceneDesc d = matte.desc();
        d.meshes = {sphere.desc(0), box.desc(0), quad.desc(0)};
        return d;
    }
};

// A hierarchy over every edge of `scene`.
EdgeHierarchy hierarchy_of_all(const Scene& scene) {
    std::vector<int32_t> ids(scene.edges().size());
    for (size_t i = 0; i < ids.size(); ++i) ids[i] = int32_t(i);
    EdgeHierarchy h;
    h.build(scene, ids);
    return h;
}

BoundsCone cone_towards(const Vec3f& p, const Vec3f& c, float r) {
    BoundsCone cone;
    EXPECT_TRUE(cone.towards(p, c, r));
    return cone;
}

// Both strategies, diffuse and glossy lobes: every expected count sample() reports is pdf()'s,
// a descent gives each edge at most once and at most kMaxChoices edges, the expected counts sum
// to the mean number of edges per descent, and the empirical frequencies match them.
TEST(EdgeHierarchy, PdfMatchesEmpiricalFrequency) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    const EdgeHierarchy h = hierarchy_of_all(scene);
    const size_t edges = scene.edges().size();
    const Vec3f p(0.3f, 0.01f, 0.4f);
    // A wide cone and a narrow one (cos half angle above 0.95: the light strategy splits), both
    // around the direction to the sphere's lower pole, where 16 of its edges meet (strategy
    // Lights scores a leaf by the part of its edge inside the cone: the cone must hold edges).
    const BoundsCone wide = cone_towards(p, Vec3f(-0.99f, 2.11f, -1.31f), 0.3f),
                     narrow = cone_towards(p, Vec3f(-0.99f, 2.11f, -1.31f), 0.05f);
    ASSERT_GT(narrow.cos_half, 0.95f);
    int split_seen = 0;
    for (int variant = 0; variant < 4; ++variant) {
        const bool glossy = variant & 1;
        EdgeHierarchy::Query q;
        q.p = p;
        q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(-1, 1, 0)), glossy ? 0.1f : 0.5f, glossy ? 0.5f : 0.f,
                                 0.1f);
        q.cone = variant & 2 ? &narrow : &wide;
        // One query throughout: its nodes' bounds kept across the calls (as a render keeps them
        // across a vertex's descents; MemoGivesTheSameSamples checks that this changes nothing).
        EdgeHierarchy::Memo memo;
        q.memo = &memo;
        for (int s = 0; s < 2; ++s) {
            const auto strategy = EdgeHierarchy::Strategy(s);
            double sum = 0;
            for (size_t e = 0; e < edges; ++e) sum += h.pdf(q, int32_t(e)).prob[s];
            EXPECT_GT(sum, 0.1) << "strategy " << s;
            EXPECT_LE(sum, EdgeHierarchy::kMaxChoices + 1e-4) << "strategy " << s;
            const int n = 50000;
            std::map<int32_t, int> counts;
            long picked = 0;
            Rng rng(7, 1);
            for (int i = 0; i < n; ++i) {
                EdgeHierarchy::Choice c[EdgeHierarchy::kMaxChoices];
                const int m = h.sample(q, strategy, rng.next_float(), c);
                ASSERT_GE(m, 0);
                ASSERT_LE(m, EdgeHierarchy::kMaxChoices);
                if (m > 1) ++split_seen;
                for (int j = 0; j < m; ++j) {
                    for (int k = 0; k < j; ++k) ASSERT_NE(c[j].edge, c[k].edge);
                    const EdgeHierarchy::Choice ref = h.pdf(q, c[j].edge);
                    EXPECT_NEAR(c[j].prob[0], ref.prob[0], 1e-5f * ref.prob[0] + 1e-12f);
                    EXPECT_NEAR(c[j].prob[1], ref.prob[1], 1e-5f * ref.prob[1] + 1e-12f);
                    EXPECT_LE(ref.prob[s], 1.f + 1e-5f);
                    counts[c[j].edge]++;
                }
                picked += m;
            }
            // At most kMaxChoices a descent: the variance of the total is at most n kMaxChoices^2 / 4.
            EXPECT_NEAR(double(picked), n * sum, 5 * std::sqrt(double(n)) * EdgeHierarchy::kMaxChoices / 2 + 1);
            for (const auto& [e, c] : counts) {
                const double pe = h.pdf(q, e).prob[s], sigma = std::sqrt(n * pe * (1 - pe)) + 1;
                EXPECT_NEAR(c, n * pe, 5 * sigma) << "edge " << e << " strategy " << s << " variant " << variant;
            }
            // Whatever the light strategy picks, the strategy over all edges can pick too (it is
            // the one that covers every edge in the multiple importance sampling).
            if (s == 1) {
                for (const auto& [e, c] : counts) EXPECT_GT(h.pdf(q, e).prob[0], 0.f) << "edge " << e;
            }
        }
    }
    EXPECT_GT(split_seen, 0);  // the splitting descents were exercised
}

// Every density is a ratio of lengths: the same scene at 2^-30 or 2^-33 units (its vertices
// scaled by a power of two, so exactly) gives every edge the same expected counts from the same
// point, both strategies, to 1e-3 (they differ by up to 8e-5, rounding). A floor of 1e-12 on
// the squared distance to a node once scored every node of a scene a micron across alike: here
// most counts came out 1e-6 to 1e-9 of their value; in a render, gradients were 30% off.
TEST(EdgeHierarchy, DensitiesDoNotDependOnTheScenesScale) {
    auto densities = [](float s) {
        MeshData sphere = make_sphere(Vec3f(0, 1, 0) * s, 0.5f * s, 8, 16),
                 box = make_box(Vec3f(1.5f, 0.2f, 0) * s, Vec3f(0.4f, 0.4f, 0.4f) * s),
                 quad = make_quad(Vec3f(-2, 0, -2) * s, Vec3f(4, 0, 0) * s, Vec3f(0, 0, 4) * s);
        MatteScene matte;
        SceneDesc d = matte.desc();
        d.meshes = {sphere.desc(0), box.desc(0), quad.desc(0)};
        const auto scene = build_scene(d);
        const EdgeHierarchy h = hierarchy_of_all(*scene);
        const Vec3f p = Vec3f(0.3f, 0.01f, 0.4f) * s;
        const BoundsCone cone = cone_towards(p, Vec3f(-0.99f, 2.11f, -1.31f) * s, 0.3f * s);
        EdgeHierarchy::Query q;
        q.p = p;
        q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(-1, 1, 0)), 0.5f, 0.2f, 0.1f);
        q.cone = &cone;
        std::vector<float> out;
        for (size_t e = 0; e < scene->edges().size(); ++e) {
            const EdgeHierarchy::Choice c = h.pdf(q, int32_t(e));
            out.push_back(c.prob[0]);
            out.push_back(c.prob[1]);
        }
        return out;
    };
    const std::vector<float> ref = densities(1.f);
    float total = 0.f;
    for (float x : ref) total += x;
    ASSERT_GT(total, 0.1f);
    for (float s : {std::ldexp(1.f, -30), std::ldexp(1.f, -33)}) {
        const std::vector<float> got = densities(s);
        ASSERT_EQ(got.size(), ref.size());
        for (size_t i = 0; i < ref.size(); ++i)
            EXPECT_NEAR(got[i], ref[i], 1e-3f * ref[i] + 1e-9f) << "scale " << s << " edge " << i / 2 << " strategy " << i % 2;
    }
}

// A vertex's last bounce sees only emission, so a crease adds nothing where the point is in
// front of both its faces, unless it is a seam of an emitter (a textured emission may jump
// there): such creases are never picked then (and still are otherwise), while silhouettes, and
// an emitter's seams, still are. The emitting box once without uvs (flat shading: its creases
// jump by their angle only) and once with each face's own uvs (every crease a seam).
TEST(EdgeHierarchy, LastBounceSkipsCreasesThatCannotChangeEmission) {
    for (const bool seams : {false, true}) {
        MeshData dark = make_box(Vec3f(-1.f, 1.f, -0.5f), Vec3f(-0.2f, 1.8f, 0.5f)), bright;
        if (seams) {
            const Vec3f lo(0.4f, 1.f, -0.5f), s = Vec3f(1.2f, 1.8f, 0.5f) - lo;
            const Vec3f ex(s.x, 0, 0), ey(0, s.y, 0), ez(0, 0, s.z);
            for (const auto& [corner, e1, e2] : {std::tuple{lo, ey, ex}, std::tuple{lo + ez, ex, ey}, std::tuple{lo, ez, ey},
                                                std::tuple{lo + ex, ey, ez}, std::tuple{lo, ex, ez}, std::tuple{lo + ey, ez, ex}})
                bright.append(make_quad(corner, e1, e2));
        } else {
            bright = make_box(Vec3f(0.4f, 1.f, -0.5f), Vec3f(1.2f, 1.8f, 0.5f));
        }
        std::vector<float> glow = {1.f, 1.f, 1.f};
        MatteScene matte;
        SceneDesc d = matte.desc();
        d.meshes = {dark.desc(0), bright.desc(0)};
        d.meshes[1].emission = {glow.data(), 1, 1, 3};
        const std::shared_ptr<const Scene> scene = build_scene(d);
        const EdgeHierarchy h = hierarchy_of_all(*scene);
        EdgeHierarchy::Query q;
        q.p = Vec3f(0.1f, 0.2f, -1.2f);  // below both boxes and in front of them
        q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(0, 1, -1)), 0.5f, 0.f, 0.5f);
        int culled = 0, kept_dark = 0, kept_bright = 0, kept_seams = 0;
        for (size_t i = 0; i < scene->edges().size(); ++i) {
            const Edge& e = scene->edges()[i];
            ASSERT_EQ(e.kind, EdgeKind::Crease);
            ASSERT_EQ(e.seam, seams && e.mesh == 1) << "edge " << i;
            const Mesh& mesh = scene->meshes[size_t(e.mesh)];
            const Vec3f x = mesh.vertex(e.v0);
            const bool front0 = dot(q.p - x, mesh.face_normal(e.f0)) > 0.f, front1 = dot(q.p - x, mesh.face_normal(e.f1)) > 0.f;
            q.direct_only = false;
            const float every = h.pdf(q, int32_t(i)).prob[0];
            q.direct_only = true;
            const float last = h.pdf(q, int32_t(i)).prob[0];
            // Behind both faces (one-sided, no emission from the back): never, in either mode.
            if (!front0 && !front1) {
                EXPECT_EQ(every, 0.f) << "edge " << i;
                EXPECT_EQ(last, 0.f) << "edge " << i;
                continue;
            }
            EXPECT_GT(every, 0.f) << "edge " << i;
            if (front0 && front1 && !e.seam) {
                EXPECT_EQ(last, 0.f) << "edge " << i;
                ++culled;
            } else {
                EXPECT_GT(last, 0.f) << "edge " << i;
                (e.mesh == 0 ? kept_dark : kept_bright)++;
                kept_seams += front0 && front1;
            }
        }
        EXPECT_GT(culled, 0);
        EXPECT_GT(kept_dark, 0);  // the dark box's silhouette
        EXPECT_GT(kept_bright, 0);
        EXPECT_EQ(kept_seams > 0, seams);  // the emitter's seams where no silhouette
        // sample() agrees: it never picks a culled crease, and its counts are pdf()'s.
        q.direct_only = true;
        Rng rng(5, 2);
        for (int i = 0; i < 2000; ++i) {
            EdgeHierarchy::Choice c[EdgeHierarchy::kMaxChoices];
            const int n = h.sample(q, EdgeHierarchy::All, rng.next_float(), c);
            ASSERT_GT(n, 0);
            for (int j = 0; j < n; ++j) {
                const float want = h.pdf(q, c[j].edge).prob[0];
                EXPECT_GT(want, 0.f);
                EXPECT_NEAR(c[j].prob[0], want, 1e-5f * want);
            }
        }
    }
}

// What culls a node (its normal cone and planes, the band of directions its silhouettes can
// have, the lobe's horizon, creases at a last bounce) never culls an edge that can contribute:
// from points all around a smooth sphere, a box and a floor, with diffuse, glossy and sharp
// lobes, every silhouette (and boundary edge) with an end clearly above the point's horizon
// has a nonzero probability.
TEST(EdgeHierarchy, EveryEdgeThatCanContributeCanBePicked) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    const EdgeHierarchy h = hierarchy_of_all(scene);
    Rng rng(11, 4);
    int checked = 0;
    for (int i = 0; i < 240; ++i) {
        EdgeHierarchy::Query q;
        q.p = Vec3f(4.f * rng.next_float() - 2.f, 0.01f + 2.5f * rng.next_float(), 4.f * rng.next_float() - 2.f);
        const Vec3f n = normalize(Vec3f(rng.next_float() - 0.5f, 1.f, rng.next_float() - 0.5f));
        const Vec3f wo = normalize(n + Vec3f(rng.next_float() - 0.5f, 0.f, rng.next_float() - 0.5f) * 1.5f);
        const int kind = i % 3;
        q.lobe = LobeBound::make(n, wo, kind == 1 ? 0.f : 0.5f, kind == 0 ? 0.f : 0.8f, kind == 2 ? 0.02f : 0.2f);
        q.direct_only = (i / 3) % 2 == 1;
        for (size_t e = 0; e < scene.edges().size(); ++e) {
            const Edge& edge = scene.edges()[e];
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const Vec3f v0 = m.vertex(edge.v0), v1 = m.vertex(edge.v1);
            const bool above = dot(v0 - q.p, n) > 0.05f * length(v0 - q.p) || dot(v1 - q.p, n) > 0.05f * length(v1 - q.p);
            if (!above || length(v1 - v0) == 0.f) continue;
            bool silhouette = edge.kind == EdgeKind::Boundary;
            if (edge.kind != EdgeKind::Boundary) {
                const Vec3f n0 = m.face_normal(edge.f0), n1 = m.face_normal(edge.f1);
                if (length(n0) == 0.f || length(n1) == 0.f) continue;
                silhouette = is_silhouette(q.p, v0, normalize(n0), normalize(n1), EdgeKind::Smooth);
            }
            if (!silhouette) continue;
            EXPECT_GT(h.pdf(q, int32_t(e)).prob[0], 0.f) << "query " << i << " edge " << e;
            ++checked;
        }
    }
    EXPECT_GT(checked, 2000);  // about 2400
}

// A group of edges under a subtree of their own (the wanted meshes' edges, in a render): from
// the group's root, sample() picks only its edges, pdf() gives zero to the others and matches
// the empirical frequencies; from the root, the other edges can still be picked.
TEST(EdgeHierarchy, GroupSubtreeSamplesOnlyItsEdges) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    std::vector<int32_t> ids;  // the box's edges (mesh 1) first, then the others
    for (int pass = 0; pass < 2; ++pass)
        for (size_t i = 0; i < scene.edges().size(); ++i)
            if ((scene.edges()[i].mesh == 1) == (pass == 0)) ids.push_back(int32_t(i));
    size_t group = 0;
    while (group < ids.size() && scene.edges()[size_t(ids[group])].mesh == 1) ++group;
    ASSERT_GT(group, 0u);
    EdgeHierarchy h;
    h.build(scene, ids, group);
    const int32_t start = h.group_root();
    ASSERT_GT(start, 0);
    EdgeHierarchy::Query q;
    q.p = Vec3f(0.3f, 0.01f, 0.4f);
    q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(-1, 1, 0)), 0.3f, 0.5f, 0.2f);
    double sum = 0.0, sum_root = 0.0, others = 0.0;
    for (size_t e = 0; e < scene.edges().size(); ++e) {
        const float p = h.pdf(q, int32_t(e), start).prob[0];
        const float from_root = h.pdf(q, int32_t(e)).prob[0];
        if (scene.edges()[e].mesh != 1) {
            EXPECT_EQ(p, 0.f) << "edge " << e;
            others += from_root;
        }
        sum += p;
        sum_root += from_root;
    }
    // (A descent may end where no leaf can contribute: the expected counts sum to less than 1.)
    EXPECT_GT(sum, 0.5);
    EXPECT_LE(sum, EdgeHierarchy::kMaxChoices + 1e-4);
    EXPECT_GT(sum_root, 0.5);
    EXPECT_GT(others, 0.05);
    const int n = 40000;
    std::map<int32_t, int> counts;
    Rng rng(9, 3);
    for (int i = 0; i < n; ++i) {
        EdgeHierarchy::Choice c[EdgeHierarchy::kMaxChoices];
        const int m = h.sample(q, EdgeHierarchy::All, rng.next_float(), c, start);
        for (int j = 0; j < m; ++j) {
            ASSERT_EQ(scene.edges()[size_t(c[j].edge)].mesh, 1);
            EXPECT_NEAR(c[j].prob[0], h.pdf(q, c[j].edge, start).prob[0], 1e-5f);
            counts[c[j].edge]++;
        }
    }
    for (const auto& [e, c] : counts) {
        const double pe = h.pdf(q, e, start).prob[0], sigma = std::sqrt(n * pe * (1 - pe)) + 1;
        EXPECT_NEAR(c, n * pe, 5 * sigma) << "edge " << e;
    }
    // No group: none, or all of them (the root).
    EdgeHierarchy none, all;
    none.build(scene, ids, 0);
    all.build(scene, ids, ids.size());
    EXPECT_EQ(none.group_root(), -1);
    EXPECT_EQ(all.group_root(), 0);
}

// Draws `rounds` samples of `h` for `plain` and for `kept` (the same query with a memo), the
// strategies alternating, with the same random numbers, and expects the same choices bit for
// bit (and, with `with_pdf`, the same pdf() of each chosen edge); returns how many it compared.
int expect_same_samples(const EdgeHierarchy& h, const EdgeHierarchy::Query& plain, const EdgeHierarchy::Query& kept,
                        Rng& rng, int rounds, bool with_pdf) {
    int compared = 0;
    for (int k = 0; k < rounds; ++k) {
        const auto strategy = EdgeHierarchy::Strategy(k % 2);
        const float u = rng.next_float();
        EdgeHierarchy::Choice a[EdgeHierarchy::kMaxChoices], b[EdgeHierarchy::kMaxChoices];
        const int na = h.sample(plain, strategy, u, a), nb = h.sample(kept, strategy, u, b);
        EXPECT_EQ(na, nb);
        for (int j = 0; j < std::min(na, nb); ++j) {
            EXPECT_EQ(a[j].edge, b[j].edge);
            EXPECT_EQ(a[j].prob[0], b[j].prob[0]);
            EXPECT_EQ(a[j].prob[1], b[j].prob[1]);
            if (with_pdf && a[j].edge == b[j].edge) {
                const EdgeHierarchy::Choice pa = h.pdf(plain, a[j].edge), pb = h.pdf(kept, a[j].edge);
                EXPECT_EQ(pa.prob[0], pb.prob[0]);
                EXPECT_EQ(pa.prob[1], pb.prob[1]);
            }
            ++compared;
        }
    }
    return compared;
}

// The memo of node bounds changes nothing: with and without it (and with one memo kept across
// both strategies and many descents, as a render keeps it per vertex), sample() picks the same
// edges with the same expected counts, bit for bit.
TEST(EdgeHierarchy, MemoGivesTheSameSamples) {
    HierarchyScene hs;
    const EdgeHierarchy h = hierarchy_of_all(*hs.scene);
    Rng rng(11, 2);
    EdgeHierarchy::Memo memo;
    int compared = 0;
    for (int i = 0; i < 400; ++i) {
        const Vec3f p(rng.next_float() * 4.f - 2.f, rng.next_float() * 0.5f, rng.next_float() * 4.f - 2.f);
        const BoundsCone cone = cone_towards(p, Vec3f(0.5f, 3.f, 0.6f), 0.02f + 0.3f * rng.next_float());
        EdgeHierarchy::Query plain;
        plain.p = p;
        plain.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1, 0.3f)), 0.3f,
                                     i % 2 ? 0.6f : 0.f, 0.05f + 0.3f * rng.next_float());
        plain.cone = &cone;
        EdgeHierarchy::Query kept = plain;
        kept.memo = &memo;
        memo.reset();
        compared += expect_same_samples(h, plain, kept, rng, 6, false);
    }
    EXPECT_GT(compared, 1000);
}

// A glossy lobe concentrates the probability on the edges near the mirror direction: from a
// point on a (virtual) floor, the mirror direction grazes the top of the sphere's outline (its
// silhouette), with the box 30 degrees off. The share of the sphere's edges follows the
// leaves' own values (the lobe's integral along each silhouette, over the distance to it; the
// smooth edges that are not silhouettes by the angle between their faces over pi, for the
// steps where the sphere shadows itself, where p sees their faces' fronts).
TEST(EdgeHierarchy, GlossyLobeFavoursMirrorDirection) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    std::vector<int32_t> ids;  // the sphere's and the box's edges (no floor around the point)
    for (size_t i = 0; i < scene.edges().size(); ++i)
        if (scene.edges()[i].mesh != 2) ids.push_back(int32_t(i));
    EdgeHierarchy h;
    h.build(scene, ids);
    const Vec3f p(-1.5f, 0.01f, 0.f), c(0, 1, 0);
    // The direction to the sphere's centre, turned up by the outline's angular radius.
    const Vec3f to_c = normalize(c - p), up = normalize(Vec3f(0, 1, 0) - to_c * to_c.y);
    const float beta = std::asin(0.5f / length(c - p));
    const Vec3f towards = to_c * std::cos(beta) + up * std::sin(beta);
    const Vec3f wo = normalize(Vec3f(-towards.x, towards.y, -towards.z));
    EdgeHierarchy::Query queries[2];  // diffuse, glossy
    for (EdgeHierarchy::Query& q : queries) q.p = p;
    queries[0].lobe = LobeBound::make(Vec3f(0, 1, 0), wo, 0.5f, 0.f, 0.1f);
    queries[1].lobe = LobeBound::make(Vec3f(0, 1, 0), wo, 0.f, 0.5f, 0.1f);
    double share[2], leaf_share[2];
    for (int k = 0; k < 2; ++k) {
        const EdgeHierarchy::Query& q = queries[k];
        double on_sphere = 0, total = 0, leaf_sphere = 0, leaf_total = 0;
        for (int32_t e : ids) {
            const Edge& edge = scene.edges()[size_t(e)];
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            const float pe = h.pdf(q, e).prob[0];
            total += pe;
            // A leaf's value: a silhouette's (or a crease's: its faces meet at right angles)
            // lobe integral over the distance to its line.
            const Vec3f v0 = m.vertex(edge.v0), v1 = m.vertex(edge.v1);
            const Vec3f n0 = normalize(m.face_normal(edge.f0)), n1 = normalize(m.face_normal(edge.f1));
            double weight = 1.0;
            if (edge.kind == EdgeKind::Smooth && !is_silhouette(p, v0, n0, n1, EdgeKind::Smooth))
                weight = dot(p - v0, n0) > 0.f || scene.materials[size_t(m.material)].two_sided
                             ? std::acos(std::clamp(double(dot(n0, n1)), -1.0, 1.0)) / kPi
                             : 0.0;
            double dist = 0.0;
            const double leaf = weight > 0.0 ? weight * q.lobe.integral(p, v0, v1, &dist) / dist : 0.0;
            leaf_total += leaf;
            if (edge.mesh == 0) {
                on_sphere += pe;
                leaf_sphere += leaf;
            }
        }
        share[k] = on_sphere / total;
        leaf_share[k] = leaf_sphere / leaf_total;
        EXPECT_NEAR(share[k], leaf_share[k], 0.05) << (k ? "glossy" : "diffuse");
    }
    std::printf("sphere's share: diffuse %.3f (leaves %.3f), glossy %.3f (leaves %.3f)\n", share[0], leaf_share[0],
                share[1], leaf_share[1]);
    // The box loses at least a third of its share.
    EXPECT_LT(1 - share[1], 0.67 * (1 - share[0]));
}

// The glossy share that sets the light strategy's probability (edges/secondary.cpp): 1 with the
// mirror direction inside the light cone; outside it, the lobe's own value at the cone's nearest
// direction over its peak (the angle from the mirror direction less the cone's half angle), so
// it falls as the lobe turns away; 0 without a glossy part.
TEST(LobeBound, GlossyShareIsTheLobeAtTheConesNearestDirection) {
    const Vec3f n(0, 1, 0), wo = normalize(Vec3f(-1, 2, 0)), p(0, 0, 0);
    const LobeBound glossy = LobeBound::make(n, wo, 0.f, 0.8f, 0.08f), matte = LobeBound::make(n, wo, 0.5f, 0.f, 0.08f);
    const Vec3f r = glossy.r;
    EXPECT_NEAR(length(r), 1.f, 1e-5f);
    // A cone around the mirror direction, and one whose border it just touches.
    EXPECT_FLOAT_EQ(glossy.glossy_share(cone_towards(p, r * 5.f, 0.3f)), 1.f);
    EXPECT_EQ(matte.glossy_share(cone_towards(p, r * 5.f, 0.3f)), 0.f);
    // Cones turned away from r about z by growing angles: the share equals the lobe's value at the
    // direction turned by (angle - half angle), over its value at r (diffuse 0: glossy alone).
    float last = 2.f;
    for (float angle : {0.05f, 0.1f, 0.2f, 0.4f, 0.8f}) {
        const float c = std::cos(angle), s = std::sin(angle);
        const Vec3f axis(c * r.x - s * r.y, s * r.x + c * r.y, r.z);
        const BoundsCone cone = cone_towards(p, axis * 4.f, 0.2f);
        const float beyond = std::max(0.f, angle - cone.half), cb = std::cos(beyond), sb = std::sin(beyond);
        const Vec3f nearest(cb * r.x - sb * r.y, sb * r.x + cb * r.y, r.z);
        const float share = glossy.glossy_share(cone);
        EXPECT_NEAR(share, glossy.eval(nearest) / glossy.eval(r), 1e-3f) << "angle " << angle;
        EXPECT_LE(share, last);
        if (beyond > 0.f) {
            EXPECT_LT(share, 1.f);
        }
        last = share;
    }
    EXPECT_LT(last, 0.01f);  // 0.8 rad away (0.75 beyond the cone): far outside a lobe of alpha 0.08
    // Every direction (p inside the lights' sphere): the whole lobe.
    EXPECT_FLOAT_EQ(glossy.glossy_share(BoundsCone()), 1.f);
}

// The point sampler: each strategy's density integrates to one over the edge (the light strategy
// over the part inside the cone, and is zero elsewhere); samples follow it (the empirical
// cumulative distribution matches the integral of pdf(), i.e. the inverse CDF is right).
TEST(EdgePointSampler, DensityIntegratesToOneAndInverseMatches) {
    const Vec3f p(0.2f, 0.f, 0.1f), v0(-1.f, 0.5f, -0.3f), v1(2.f, 0.8f, 0.4f);
    const BoundsCone cone = cone_towards(p, Vec3f(0.3f, 1.f, 0.1f), 0.4f);
    const LobeBound lobes[2] = {LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(1, 1, 0)), 0.5f, 0.f, 0.5f),
                                LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(-0.2f, 1, 0)), 0.1f, 0.8f, 0.1f)};
    for (const LobeBound& lobe : lobes) {
        EdgePointSampler ps;
        ASSERT_TRUE(ps.setup(p, v0, v1, lobe, &cone));
        for (int s = 0; s < 2; ++s) {
            const auto strategy = EdgeHierarchy::Strategy(s);
            // Midpoint rule on a fine grid, with the running integral at the checkpoints.
            const int grid = 200000, checks = 20;
            std::vector<double> cdf(checks + 1, 0.0);
            double integral = 0;
            for (int i = 0; i < grid; ++i) {
                const float t = (float(i) + 0.5f) / float(grid);
                const float d = ps.pdf(strategy, t);
                ASSERT_TRUE(std::isfinite(d) && d >= 0.f);
                integral += double(d) / grid;
                if ((i + 1) % (grid / checks) == 0) cdf[size_t((i + 1) / (grid / checks))] = integral;
            }
            EXPECT_NEAR(integral, 1.0, 2e-3) << "strategy " << s;
            const int n = 100000;
            std::vector<int> below(checks + 1, 0);
            Rng rng(3, uint64_t(s));
            for (int i = 0; i < n; ++i) {
                float t;
                ASSERT_TRUE(ps.sample(strategy, rng.next_float(), t));
                ASSERT_TRUE(t >= 0.f && t <= 1.f);
                EXPECT_GT(ps.pdf(strategy, t), 0.f);
                for (int c = 1; c <= checks; ++c) below[size_t(c)] += t <= float(c) / checks;
            }
            for (int c = 1; c < checks; ++c) {
                const double f = double(below[size_t(c)]) / n,
                             sigma = std::sqrt(std::max(0.0, cdf[size_t(c)] * (1 - cdf[size_t(c)])) / n);
                EXPECT_NEAR(f, cdf[size_t(c)], 5 * sigma + 2e-3) << "strategy " << s << " at t = " << float(c) / checks;
            }
        }
    }
    // A cone that misses the edge: the light strategy cannot sample it, its density is zero.
    EdgePointSampler ps;
    const BoundsCone away = cone_towards(p, Vec3f(0.2f, -3.f, 0.1f), 0.1f);
    ASSERT_TRUE(ps.setup(p, v0, v1, lobes[0], &away));
    float t;
    EXPECT_FALSE(ps.sample(EdgeHierarchy::Lights, 0.5f, t));
    EXPECT_EQ(ps.pdf(EdgeHierarchy::Lights, 0.5f), 0.f);
}

// The density of `ps` under strategy s at the midpoints of `grid` equal bins of [0, 1], each
// finite and non-negative; `integral`: their mean (the density's integral by the midpoint rule).
std::vector<float> tabulate_density(const EdgePointSampler& ps, EdgeHierarchy::Strategy s, int grid, double& integral) {
    std::vector<float> d(static_cast<size_t>(grid));
    integral = 0;
    for (int i = 0; i < grid; ++i) {
        d[size_t(i)] = ps.pdf(s, (float(i) + 0.5f) / float(grid));
        EXPECT_TRUE(std::isfinite(d[size_t(i)]) && d[size_t(i)] >= 0.f) << "bin " << i;
        integral += double(d[size_t(i)]) / grid;
    }
    return d;
}

// The samples of `ps` under strategy s (200k, stream `seed`) against its density d, tabulated
// at the midpoints of a uniform grid over [0, 1] and positive on [t0, t1] only: every sample in
// [t0, t1] where the density is positive, and their histogram over it (20 bins) matching the
// density's integral over each bin.
void expect_samples_follow_density(const EdgePointSampler& ps, EdgeHierarchy::Strategy s, const std::vector<float>& d,
                                   float t0, float t1, uint64_t seed) {
    const int bins = 20, samples = 200000, grid = int(d.size());
    std::vector<double> want(bins, 0.0);
    for (int i = 0; i < grid; ++i) {
        const float t = (float(i) + 0.5f) / float(grid);
        if (d[size_t(i)] > 0.f) want[size_t(std::min(bins - 1, int((t - t0) / (t1 - t0) * bins)))] += double(d[size_t(i)]) / grid;
    }
    std::vector<int> got(bins, 0);
    Rng rng(seed, 0);
    for (int i = 0; i < samples; ++i) {
        float t;
        ASSERT_TRUE(ps.sample(s, rng.next_float(), t));
        ASSERT_TRUE(t >= t0 - 1e-5f && t <= t1 + 1e-5f) << t;
        EXPECT_GT(ps.pdf(s, t), 0.f);
        ++got[size_t(std::clamp(int((t - t0) / (t1 - t0) * bins), 0, bins - 1))];
    }
    for (int b = 0; b < bins; ++b) {
        const double f = double(got[size_t(b)]) / samples, sigma = std::sqrt(want[size_t(b)] * (1 - want[size_t(b)]) / samples);
        EXPECT_NEAR(f, want[size_t(b)], 5 * sigma + 1e-3) << "bin " << b;
    }
}

// Strategy Lights with a glossy lobe narrower than the light cone: the density over the part of
// the edge inside the cone mixes uniform by length with the lobe bound there. It integrates to
// one, is zero outside that part, follows the lobe (far from uniform), and the samples'
// histogram over that part matches its integral bin by bin.
TEST(EdgePointSampler, LightStrategyFollowsANarrowLobeInsideTheCone) {
    const Vec3f p(0.2f, 0.f, 0.1f), v0(-1.f, 1.f, -0.3f), v1(2.f, 1.f, 0.4f);
    const BoundsCone cone = cone_towards(p, Vec3f(0.3f, 1.f, 0.1f), 0.3f);
    // The mirror direction towards the middle of the part of the edge inside the cone.
    const Vec3f n(0, 1, 0), towards = normalize(Vec3f(0.35f, 1.f, 0.12f) - p);
    const Vec3f wo = n * (2.f * dot(n, towards)) - towards;
    for (float alpha : {0.02f, 0.08f}) {
        const LobeBound lobe = LobeBound::make(n, wo, 0.05f, 0.8f, alpha);
        EdgePointSampler ps;
        ASSERT_TRUE(ps.setup(p, v0, v1, lobe, &cone));
        const auto L = EdgeHierarchy::Lights;
        // The support: where the density is positive, on a fine grid.
        const int grid = 400000;
        float t0 = 2.f, t1 = -1.f, lo = 1e30f, hi = 0.f;
        double integral = 0;
        const std::vector<float> d = tabulate_density(ps, L, grid, integral);
        for (int i = 0; i < grid; ++i) {
            const float t = (float(i) + 0.5f) / float(grid);
            if (d[size_t(i)] > 0.f) {
                t0 = std::min(t0, t);
                t1 = std::max(t1, t);
                lo = std::min(lo, d[size_t(i)]);
                hi = std::max(hi, d[size_t(i)]);
            }
        }
        ASSERT_LT(t0, t1);
        EXPECT_GT(t0, 0.01f);  // the cone holds a part of the edge, not all of it
        EXPECT_LT(t1, 0.99f);
        EXPECT_NEAR(integral, 1.0, 2e-3) << "alpha " << alpha;
        EXPECT_GT(hi, (alpha < 0.05f ? 4.f : 1.5f) * lo) << "alpha " << alpha;  // not uniform
        {
            SCOPED_TRACE(alpha);
            expect_samples_follow_density(ps, L, d, t0, t1, 11);
        }
    }
}

// Whether the ray from p along w (unit) meets triangle (a, b, c), from either face.
bool meets(const Vec3f& p, const Vec3f& w, const Vec3f& a, const Vec3f& b, const Vec3f& c) {
    const Vec3f e1 = b - a, e2 = c - a, s = cross(w, e2);
    const float det = dot(e1, s);
    if (std::abs(det) < 1e-12f) return false;
    const Vec3f o = p - a;
    const float u = dot(o, s) / det;
    const Vec3f q = cross(o, e1);
    const float v = dot(w, q) / det, d = dot(e2, q) / det;
    return u >= 0.f && v >= 0.f && u + v <= 1.f && d > 0.f;
}

// Strategy Lights kept to the light triangles (LightTriangles): a square light (two triangles)
// whose bounding cone's circle reaches well past its corner. An edge whose plane through p
// cuts the square near that corner: the part sampled lies strictly inside the cone's part,
// the density integrates to one over it and is zero outside it, the samples' histogram
// matches it, and every direction within the margin of a light triangle (either face) has a
// positive density. A light behind p: nothing to sample; p in a light's plane: the cone's part.
TEST(EdgePointSampler, LightStrategyKeepsToTheLightTriangles) {
    const float margin = 4e-4f;
    const Vec3f p(0.f, 0.f, 0.f);
    const Vec3f sq[4] = {Vec3f(-0.15f, 3, -0.15f), Vec3f(0.15f, 3, -0.15f), Vec3f(0.15f, 3, 0.15f), Vec3f(-0.15f, 3, 0.15f)};
    const Vec3f tris[2][3] = {{sq[0], sq[2], sq[1]}, {sq[0], sq[3], sq[2]}};
    BoundsCone cone = cone_towards(p, Vec3f(0, 3, 0), 0.15f * std::sqrt(2.f));
    cone.half += margin;
    cone.cos_half = std::cos(cone.half);
    LightTriangles lights;
    lights.set(p, tris, 2, margin);
    // The plane through p and the edge meets the lights' plane on x + z = 0.2.
    const Vec3f v0(-1.f, 1.5f, 1.1f), v1(1.f, 1.5f, -0.9f);
    for (float ks : {0.f, 0.8f}) {
        const Vec3f n(0, 1, 0), wo = normalize(Vec3f(-0.1f, 1.f, -0.1f));
        const LobeBound lobe = LobeBound::make(n, wo, 0.5f, ks, 0.1f);
        EdgePointSampler coned, kept;
        ASSERT_TRUE(coned.setup(p, v0, v1, lobe, &cone));
        ASSERT_TRUE(kept.setup(p, v0, v1, lobe, &cone, &lights));
        const auto L = EdgeHierarchy::Lights;
        const int grid = 400000;
        float c0 = 2.f, c1 = -1.f, k0 = 2.f, k1 = -1.f;
        double integral = 0;
        const std::vector<float> d = tabulate_density(kept, L, grid, integral);
        for (int i = 0; i < grid; ++i) {
            const float t = (float(i) + 0.5f) / float(grid);
            if (coned.pdf(L, t) > 0.f) c0 = std::min(c0, t), c1 = std::max(c1, t);
            if (d[size_t(i)] > 0.f) k0 = std::min(k0, t), k1 = std::max(k1, t);
        }
        ASSERT_LT(k0, k1);
        EXPECT_GE(k0, c0);
        EXPECT_LE(k1, c1);
        EXPECT_LT(k1 - k0, 0.6f * (c1 - c0)) << "cone part [" << c0 << ", " << c1 << "], kept [" << k0 << ", " << k1 << "]";
        EXPECT_NEAR(integral, 1.0, 2e-3) << "ks " << ks;
        // Every direction within the margin of a light triangle (three moved copies of each
        // direction, across the edge's plane and along it) lies where the density is positive;
        // and some directions inside the cone meet no light.
        const Vec3f across = normalize(cross(v0 - p, v1 - p)), along = normalize(v1 - v0);
        int hits = 0;
        for (int i = 0; i < grid; i += 4) {
            const float t = (float(i) + 0.5f) / float(grid);
            const Vec3f w = normalize(v0 + (v1 - v0) * t - p);
            for (const Vec3f& m : {Vec3f(0.f), across * (0.95f * margin), across * (-0.95f * margin), along * (0.95f * margin)}) {
                const Vec3f wm = normalize(w + m);
                if (!meets(p, wm, tris[0][0], tris[0][1], tris[0][2]) && !meets(p, wm, tris[1][0], tris[1][1], tris[1][2]))
                    continue;
                ++hits;
                ASSERT_GT(d[size_t(i)], 0.f) << "t " << t;
            }
        }
        EXPECT_GT(hits, 1000);
        {
            SCOPED_TRACE(ks);
            expect_samples_follow_density(kept, L, d, k0, k1, 17);
        }
        // Strategy All is not changed.
        for (float t : {0.1f, 0.5f, 0.55f, 0.9f}) EXPECT_EQ(kept.pdf(EdgeHierarchy::All, t), coned.pdf(EdgeHierarchy::All, t));
    }
    const LobeBound diffuse = LobeBound::make(Vec3f(0, 1, 0), Vec3f(0, 1, 0), 0.5f, 0.f, 0.5f);
    // A plane through p and the edge that passes beside the square, inside the cone's circle
    // (z = 0.18 in the lights' plane; the square ends at 0.15, the circle at 0.21): nothing to
    // sample.
    {
        EdgePointSampler coned, kept;
        const Vec3f a0(-1.f, 1.5f, 0.09f), a1(1.f, 1.5f, 0.09f);
        ASSERT_TRUE(coned.setup(p, a0, a1, diffuse, &cone));
        ASSERT_TRUE(kept.setup(p, a0, a1, diffuse, &cone, &lights));
        float t;
        EXPECT_TRUE(coned.sample(EdgeHierarchy::Lights, 0.5f, t));  // the cone's circle reaches it
        EXPECT_FALSE(kept.sample(EdgeHierarchy::Lights, 0.5f, t));
        for (int i = 0; i < 1000; ++i) EXPECT_EQ(kept.pdf(EdgeHierarchy::Lights, (float(i) + 0.5f) / 1000.f), 0.f);
    }
    // The same square behind p (at y = -3): its planes bound the directions towards it only.
    {
        Vec3f behind[2][3];
        for (int i = 0; i < 2; ++i)
            for (int k = 0; k < 3; ++k) behind[i][k] = Vec3f(tris[i][k].x, -3.f, tris[i][k].z);
        LightTriangles back;
        back.set(p, behind, 2, margin);
        EdgePointSampler ps;
        ASSERT_TRUE(ps.setup(p, v0, v1, diffuse, &cone, &back));  // the cone (wrongly) up: no part left
        float t;
        EXPECT_FALSE(ps.sample(EdgeHierarchy::Lights, 0.5f, t));
    }
    // p in the lights' plane (a square at y = 0 beside p): no bound from it, the cone's part.
    {
        Vec3f level[2][3];
        for (int i = 0; i < 2; ++i)
            for (int k = 0; k < 3; ++k) level[i][k] = Vec3f(tris[i][k].x, 0.f, tris[i][k].z + 3.f);
        LightTriangles flat;
        flat.set(p, level, 2, margin);
        const BoundsCone side = cone_towards(p, Vec3f(0, 0, 3), 0.25f);
        const Vec3f a0(-1.f, 0.1f, 1.5f), a1(1.f, -0.1f, 1.5f);
        EdgePointSampler coned, kept;
        ASSERT_TRUE(coned.setup(p, a0, a1, diffuse, &side));
        ASSERT_TRUE(kept.setup(p, a0, a1, diffuse, &side, &flat));
        for (int i = 0; i < 100; ++i) {
            const float t = (float(i) + 0.5f) / 100.f;
            EXPECT_EQ(kept.pdf(EdgeHierarchy::Lights, t), coned.pdf(EdgeHierarchy::Lights, t));
        }
    }
}

// The square light (two triangles, 1 x 1 at height 3) of the light strategy's tests, seen from a
// point p: the cone towards it widened by the margin, and its triangles.
struct SquareLightSeen {
    static constexpr float kMargin = 4e-4f;
    static inline const Vec3f kSquare[4] = {Vec3f(-0.2f, 3, -0.5f), Vec3f(0.8f, 3, -0.5f), Vec3f(0.8f, 3, 0.5f), Vec3f(-0.2f, 3, 0.5f)};
    static inline const Vec3f kTriangles[2][3] = {{kSquare[0], kSquare[2], kSquare[1]}, {kSquare[0], kSquare[3], kSquare[2]}};
    BoundsCone cone;
    LightTriangles lights;
    explicit SquareLightSeen(const Vec3f& p) : cone(cone_towards(p, Vec3f(0.3f, 3, 0), 0.5f * std::sqrt(2.f))) {
        cone.half += kMargin;
        cone.cos_half = std::cos(cone.half);
        lights.set(p, kTriangles, 2, kMargin);
    }
};

// The descent's strategy Lights kept to the light triangles (Query::lights): a square light
// (two triangles) over the sphere, box and floor, seen from points on the floor. For every edge:
// where the part of it the point sampler would take (EdgeArc::lights_part) is empty, the
// strategy's expected count is zero; where it is not (and the edge can contribute at all), it is
// positive, so no node's pruning loses an edge that can cast a shadow. Some edges the cone alone
// would give a count lose it. sample() reports pdf()'s counts, and the empirical frequencies of
// its choices match them. And a box LightTriangles::outside() leaves out holds no segment with
// a direction within the margin of a triangle.
TEST(EdgeHierarchy, LightStrategyKeepsToTheLightTriangles) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    const EdgeHierarchy h = hierarchy_of_all(scene);
    const float margin = SquareLightSeen::kMargin;
    Rng rng(5, 3);
    int zeroed = 0, kept = 0, checked = 0, sampled = 0;
    for (int i = 0; i < 60; ++i) {
        const Vec3f p(4.f * rng.next_float() - 2.f, 0.01f, 4.f * rng.next_float() - 2.f);
        SquareLightSeen seen(p);
        const BoundsCone& cone = seen.cone;
        const LightTriangles& lights = seen.lights;
        EdgeHierarchy::Query coned, q;
        coned.p = p;
        const bool glossy = i % 2 == 1;
        coned.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1.f, rng.next_float() - 0.5f)),
                                     0.5f, glossy ? 0.8f : 0.f, 0.1f);
        coned.cone = &cone;
        q = coned;
        q.lights = &lights;
        EdgeHierarchy::Memo memo;  // kept across the calls of this query (not across queries)
        q.memo = &memo;
        for (size_t e = 0; e < scene.edges().size(); ++e) {
            const Edge& edge = scene.edges()[e];
            const Mesh& m = scene.meshes[size_t(edge.mesh)];
            EdgeArc arc;
            float lo, hi;
            const bool part = arc.set(p, m.vertex(edge.v0), m.vertex(edge.v1)) && arc.lights_part(cone, &lights, lo, hi) &&
                              arc.param(hi) > arc.param(lo);
            const EdgeHierarchy::Choice c = h.pdf(q, int32_t(e)), cc = h.pdf(coned, int32_t(e));
            EXPECT_EQ(c.prob[0], cc.prob[0]);  // strategy All is not changed
            if (!part) {
                EXPECT_EQ(c.prob[1], 0.f) << "query " << i << " edge " << e;
                zeroed += cc.prob[1] > 0.f;
            } else if (c.prob[0] > 0.f) {
                EXPECT_GT(c.prob[1], 0.f) << "query " << i << " edge " << e;
                ++kept;
            }
            ++checked;
        }
        // The frequencies of strategy Lights' choices (the first queries where it picks some).
        if (sampled >= 3) continue;
        double sum = 0;
        for (size_t e = 0; e < scene.edges().size(); ++e) sum += h.pdf(q, int32_t(e)).prob[1];
        if (!(sum > 0.1)) continue;
        ++sampled;
        const int n = 20000;
        std::map<int32_t, int> counts;
        long picked = 0;
        Rng draws(9, uint64_t(i));
        for (int k = 0; k < n; ++k) {
            EdgeHierarchy::Choice cs[EdgeHierarchy::kMaxChoices];
            const int got = h.sample(q, EdgeHierarchy::Lights, draws.next_float(), cs);
            for (int j = 0; j < got; ++j) {
                const EdgeHierarchy::Choice ref = h.pdf(q, cs[j].edge);
                ASSERT_NEAR(cs[j].prob[0], ref.prob[0], 1e-5f * ref.prob[0] + 1e-12f);
                ASSERT_NEAR(cs[j].prob[1], ref.prob[1], 1e-5f * ref.prob[1] + 1e-12f);
                ++counts[cs[j].edge];
            }
            picked += got;
        }
        EXPECT_NEAR(double(picked), n * sum, 5 * std::sqrt(double(n)) * EdgeHierarchy::kMaxChoices / 2 + 1);
        for (const auto& [e, c] : counts) {
            const double pe = h.pdf(q, e).prob[1], sigma = std::sqrt(n * pe * (1 - std::min(pe, 1.0))) + 1;
            EXPECT_NEAR(c, n * pe, 5 * sigma) << "edge " << e << " query " << i;
        }
    }
    EXPECT_GT(checked, 10000);
    EXPECT_GT(kept, 100);  // 163
    EXPECT_GT(zeroed, 50);  // edges in the cone that meet no light triangle (110)
    EXPECT_EQ(sampled, 3);
    // Boxes left out hold no segment that comes within the margin of a triangle: random boxes
    // around the light's wedge seen from the origin, random segments inside each.
    const Vec3f p(0.f, 0.f, 0.f);
    LightTriangles lights;
    lights.set(p, SquareLightSeen::kTriangles, 2, margin);
    const BoundsCone everywhere;
    int out = 0, in = 0;
    for (int i = 0; i < 4000; ++i) {
        const Vec3f c(2.5f * rng.next_float() - 1.f, 0.5f + 2.f * rng.next_float(), 1.6f * rng.next_float() - 0.8f);
        const Vec3f half = Vec3f(rng.next_float(), rng.next_float(), rng.next_float()) * 0.2f;
        const bool left_out = lights.outside(c - half, c + half);
        (left_out ? out : in)++;
        if (!left_out) continue;
        for (int k = 0; k < 20; ++k) {
            auto inside = [&] {
                return c + Vec3f((2.f * rng.next_float() - 1.f) * half.x, (2.f * rng.next_float() - 1.f) * half.y,
                                 (2.f * rng.next_float() - 1.f) * half.z);
            };
            EdgeArc arc;
            float lo, hi;
            if (!arc.set(p, inside(), inside())) continue;
            ASSERT_FALSE(arc.lights_part(everywhere, &lights, lo, hi)) << "box " << i;
        }
    }
    EXPECT_GT(out, 300);
    EXPECT_GT(in, 300);
    // A box around a segment that crosses the light's wedge is never left out.
    EXPECT_FALSE(lights.outside(Vec3f(0.3f, 1.4f, -0.2f), Vec3f(0.3f, 1.6f, 0.2f)));
    EXPECT_TRUE(lights.outside(Vec3f(-1.f, 1.4f, -0.2f), Vec3f(-0.8f, 1.6f, 0.2f)));
}

// Degenerate configurations: a zero-length edge, the point on the edge's line, on the edge
// itself, at an end: no sample, never a NaN.
TEST(EdgePointSampler, DegenerateEdgesGiveNoSample) {
    const LobeBound lobe = LobeBound::make(Vec3f(0, 1, 0), Vec3f(0, 1, 0), 0.5f, 0.5f, 0.2f);
    EdgePointSampler ps;
    EXPECT_FALSE(ps.setup(Vec3f(0, 1, 0), Vec3f(1, 0, 0), Vec3f(1, 0, 0), lobe, nullptr));
    EXPECT_FALSE(ps.setup(Vec3f(0.5f, 0, 0), Vec3f(0, 0, 0), Vec3f(1, 0, 0), lobe, nullptr));
    EXPECT_FALSE(ps.setup(Vec3f(3, 0, 0), Vec3f(0, 0, 0), Vec3f(1, 0, 0), lobe, nullptr));
    EXPECT_FALSE(ps.setup(Vec3f(0, 0, 0), Vec3f(0, 0, 0), Vec3f(1, 0, 0), lobe, nullptr));
    // Just off the line: finite densities.
    ASSERT_TRUE(ps.setup(Vec3f(0.5f, 1e-3f, 0), Vec3f(0, 0, 0), Vec3f(1, 0, 0), lobe, nullptr));
    for (float u : {0.f, 0.3f, 0.7f, 0.99999f}) {
        float t;
        ASSERT_TRUE(ps.sample(EdgeHierarchy::All, u, t));
        EXPECT_TRUE(std::isfinite(t) && std::isfinite(ps.pdf(EdgeHierarchy::All, t)));
    }
}

// Edges shared by three faces, a sliver face with an edge of length 1e-6, and points on an edge: the
// hierarchy's probabilities stay finite and consistent, and derivative images stay finite.
TEST(EdgeHierarchy, AwkwardGeometryIsFinite) {
    // Three fins on the edge (0,0,0)-(0,1,0), a sliver triangle (an edge of length 1e-6), a floor.
    std::vector<float> v = {0, 0, 0, 0, 1, 0, 1, 0.5f, 0, -1, 0.5f, 0.5f, -1, 0.5f, -0.5f, 0.5f, 0.2f, 1, 0.5f, 0.200001f, 1,
                            1, 0.8f, 1};
    std::vector<int32_t> idx = {0, 1, 2, 1, 0, 3, 0, 1, 4, 5, 6, 7};
    MeshData floor = make_quad(Vec3f(-3, -0.5f, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    std::vector<float> light_v = {-0.5f, 3, -0.5f, 0.5f, 3, -0.5f, 0.5f, 3, 0.5f, -0.5f, 3, 0.5f};
    std::vector<int32_t> light_i = {0, 2, 1, 0, 3, 2};
    std::vector<float> kd = {0.5f, 0.5f, 0.5f}, ks = {0.3f, 0.3f, 0.3f}, rough = {0.1f}, le = {5, 5, 5};
    SceneDesc d;
    d.camera.width = d.camera.height = 12;
    d.camera.position[1] = 1.5f;
    d.camera.position[2] = -4;
    d.camera.fov = 60;
    MaterialDesc m;
    m.diffuse = {kd.data(), 1, 1, 3};
    m.specular = {ks.data(), 1, 1, 3};
    m.roughness = {rough.data(), 1, 1, 1};
    d.materials.push_back(m);
    MeshDesc fins;
    fins.vertices = v.data();
    fins.num_vertices = int64_t(v.size() / 3);
    fins.indices = idx.data();
    fins.num_triangles = int64_t(idx.size() / 3);
    MeshDesc light;
    light.vertices = light_v.data();
    light.num_vertices = 4;
    light.indices = light_i.data();
    light.num_triangles = 2;
    light.emission = {le.data(), 1, 1, 3};
    d.meshes = {fins, floor.desc(0), light};
    std::shared_ptr<const Scene> scene = build_scene(d);
    const EdgeHierarchy h = hierarchy_of_all(*scene);
    const BoundsCone cone = cone_towards(Vec3f(0, 0.5f, 0), Vec3f(0, 3, 0), 0.75f);
    // On the shared edge, at its end, on the zero-area face, on the floor.
    for (const Vec3f& p : {Vec3f(0, 0.5f, 0), Vec3f(0, 0, 0), Vec3f(0.5f, 0.2f, 1), Vec3f(0.3f, -0.5f, 0.2f)}) {
        EdgeHierarchy::Query q;
        q.p = p;
        q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(0.3f, 1, -0.2f)), 0.5f, 0.3f, 0.1f);
        q.cone = &cone;
        Rng rng(11, 2);
        for (int i = 0; i < 2000; ++i)
            for (int s = 0; s < 2; ++s) {
                EdgeHierarchy::Choice cs[EdgeHierarchy::kMaxChoices];
                if (h.sample(q, EdgeHierarchy::Strategy(s), rng.next_float(), cs) == 0) continue;
                const EdgeHierarchy::Choice& c = cs[0];
                ASSERT_TRUE(std::isfinite(c.prob[0]) && std::isfinite(c.prob[1]));
                const Edge& e = scene->edges()[size_t(c.edge)];
                const Mesh& mesh = scene->meshes[size_t(e.mesh)];
                EdgePointSampler ps;
                float t;
                if (!ps.setup(p, mesh.vertex(e.v0), mesh.vertex(e.v1), q.lobe, q.cone)) continue;
                if (!ps.sample(EdgeHierarchy::Strategy(s), rng.next_float(), t)) continue;
                ASSERT_TRUE(std::isfinite(t) && std::isfinite(ps.pdf(EdgeHierarchy::All, t)) &&
                            std::isfinite(ps.pdf(EdgeHierarchy::Lights, t)));
            }
    }
    // Derivative images along the fins' vertices, both samplers: finite.
    std::vector<float> dir(v.size(), 0.f);
    for (size_t i = 0; i < dir.size(); i += 3) dir[i] = 1.f;
    SceneGradients dirs;
    dirs.meshes.resize(3);
    dirs.meshes[0].vertices.dir = dir.data();
    for (EdgeSampling sampling : {EdgeSampling::Importance, EdgeSampling::Uniform}) {
        RenderOptions ro;
        ro.spp = 8;
        ro.max_bounces = 2;
        ro.edge_sampling = sampling;
        std::vector<float> out(12 * 12 * 3);
        derivative_image(*scene, ro, dirs, out.data());
        for (float x : out) ASSERT_TRUE(std::isfinite(x));
    }
}

}  // namespace
}  // namespace edgepath

namespace edgepath {
namespace {

// LobeBound::integral (closed form) against a fine midpoint rule over the arc's angle, for
// diffuse, glossy and mixed lobes, edges above the horizon (the closed form does not cut the
// glossy part off below it) or, for diffuse lobes, across it; sharp lobes included.
TEST(LobeBound, IntegralMatchesQuadrature) {
    Rng rng(3, 9);
    int checked = 0;
    for (int i = 0; i < 300; ++i) {
        const Vec3f p(0.f, 0.f, 0.f), n(0.f, 1.f, 0.f);
        const Vec3f wo = normalize(Vec3f(rng.next_float() - 0.5f, 0.2f + rng.next_float(), rng.next_float() - 0.5f));
        const float alpha = 0.02f + 0.5f * rng.next_float();
        const int kind = i % 3;
        const LobeBound lobe = LobeBound::make(n, wo, kind == 1 ? 0.f : 0.6f, kind == 0 ? 0.f : 0.8f, alpha);
        // Diffuse lobes: edges crossing the horizon too (the cosine is cut off at it).
        const float low = kind == 0 ? -1.f : 0.05f;
        auto point = [&] {
            return Vec3f(4.f * rng.next_float() - 2.f, low + (2.05f - low) * rng.next_float(), 4.f * rng.next_float() - 2.f);
        };
        const Vec3f v0 = point(), v1 = point();
        double h = 0.0;
        const double got = lobe.integral(p, v0, v1, &h);
        // The angle along the arc: phi(t) = atan((t len - foot) / h).
        const Vec3f e = v1 - v0;
        const double len = length(e);
        const double foot = dot(p - v0, e) / len;
        const double phi0 = std::atan(-foot / h), phi1 = std::atan((len - foot) / h);
        const int steps = 20000;
        double want = 0.0;
        for (int k = 0; k < steps; ++k) {
            const double phi = phi0 + (phi1 - phi0) * (k + 0.5) / steps;
            const double t = (foot + h * std::tan(phi)) / len;
            want += lobe.eval(normalize(v0 + e * float(t) - p)) * (phi1 - phi0) / steps;
        }
        ASSERT_GT(h, 0.0);
        EXPECT_NEAR(got, want, 2e-3 * want + 1e-7) << "case " << i << " kind " << kind << " alpha " << alpha;
        ++checked;
    }
    EXPECT_EQ(checked, 300);
}

}  // namespace
}  // namespace edgepath

namespace edgepath {
namespace {

// A query at a random point of the box [-half, half] x [y0, y0 + height] x [-half, half], with a
// glossy lobe about a random direction near the up axis and the cone towards a light at (0, 8,
// 0) (written to `cone`, which the query points to).
EdgeHierarchy::Query random_query(Rng& rng, float half, float y0, float height, bool direct_only, BoundsCone& cone) {
    EdgeHierarchy::Query q;
    q.p = Vec3f(2.f * half * rng.next_float() - half, y0 + height * rng.next_float(), 2.f * half * rng.next_float() - half);
    q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1.f, 0.3f)), 0.5f, 0.3f, 0.2f);
    cone = cone_towards(q.p, Vec3f(0.f, 8.f, 0.f), 0.5f);
    q.cone = &cone;
    q.direct_only = direct_only;
    return q;
}

// The indices of every edge of `scene`, those of mesh `first` first; and how many those are.
std::vector<int32_t> edges_mesh_first(const Scene& scene, int first, size_t* group) {
    std::vector<int32_t> ids, rest;
    for (size_t i = 0; i < scene.edges().size(); ++i)
        (scene.edges()[i].mesh == first ? ids : rest).push_back(int32_t(i));
    *group = ids.size();
    ids.insert(ids.end(), rest.begin(), rest.end());
    return ids;
}

// The kept hierarchy after random vertex moves: refit (not rebuilt) while the edges stay the
// same, and then every node's box, sphere, length, normal cone and plane range still hold the
// edges under it as they are now; a hierarchy kept from before the moves does not (so the check
// sees stale bounds). Sampling still agrees with pdf().
TEST(EdgeHierarchy, RefitBoundsHoldEveryEdgeAfterRandomMoves) {
    HierarchyScene hs;
    Rng rng(3, 9);
    // The sphere's vertices moved by a random affine map of their first positions (a shear, a
    // stretch, a turn and a shift): its normals turn unevenly, and its edges stay the same
    // (vertices at one position stay together; the diagonals of its planar quads, flat or not
    // as rounding has it, are kept by a moving scene; its degenerate triangles at the poles
    // stay degenerate).
    const std::vector<float> rest = hs.sphere.vertices;
    auto wave = [&] {
        float a[3][3], t[3];
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) a[r][c] = (r == c ? 1.f : 0.f) + 0.4f * (rng.next_float() - 0.5f);
            t[r] = 0.3f * (rng.next_float() - 0.5f);
        }
        for (size_t v = 0; v + 2 < rest.size(); v += 3)
            for (int r = 0; r < 3; ++r)
                hs.sphere.vertices[v + size_t(r)] =
                    a[r][0] * rest[v] + a[r][1] * rest[v + 1] + a[r][2] * rest[v + 2] + t[r];
    };
    SceneDesc d = hs.matte.desc();
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    const std::shared_ptr<Scene> scene = build_moved(d);
    size_t group = 0;
    const std::vector<int32_t> ids = edges_mesh_first(*scene, 0, &group);
    ASSERT_GT(group, 0u);
    // Held across the moves, as a pass in another thread would: the scene changes a copy.
    const std::shared_ptr<const EdgeHierarchy> before = scene->edge_hierarchy(ids, group);
    EXPECT_EQ(before->check_bounds(*scene, 1e-5f), -1);
    EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
    for (int round = 1; round <= 4; ++round) {
        wave();  // the sphere only; the box and the floor stay
        d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
        update_scene(*scene, d);
        size_t g = 0;
        const std::vector<int32_t> now = edges_mesh_first(*scene, 0, &g);
        ASSERT_EQ(now, ids);  // the same edges: a refit is possible
        ASSERT_EQ(g, group);
        const EdgeHierarchy& h = *scene->edge_hierarchy(now, g);  // the scene holds it
        EXPECT_NE(&h, before.get());
        EXPECT_EQ(scene->hierarchy_stats().refits, uint64_t(round));
        EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
        EXPECT_EQ(h.check_bounds(*scene, 1e-5f), -1) << "round " << round;
        EXPECT_GE(before->check_bounds(*scene, 1e-5f), 0) << "round " << round;
        for (int i = 0; i < 50; ++i) {
            EdgeHierarchy::Query q;
            q.p = Vec3f(4.f * rng.next_float() - 2.f, 0.05f + 2.f * rng.next_float(), 4.f * rng.next_float() - 2.f);
            q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1.f, 0.3f)), 0.5f, 0.3f, 0.2f);
            for (int32_t start : {0, h.group_root()}) {
                EdgeHierarchy::Choice c[EdgeHierarchy::kMaxChoices];
                const int n = h.sample(q, EdgeHierarchy::All, rng.next_float(), c, start);
                for (int j = 0; j < n; ++j) {
                    const float want = h.pdf(q, c[j].edge, start).prob[0];
                    EXPECT_NEAR(c[j].prob[0], want, 1e-5f * want);
                }
            }
        }
    }
    // Nothing moved: reused.
    scene->edge_hierarchy(ids, group);
    EXPECT_EQ(scene->hierarchy_stats().reuses, 1u);
}

// A tree asked for by key (Scene::edge_hierarchy(key, list)): the list is asked for only when no
// kept tree was updated for that key on the geometry as it is now; otherwise the same tree comes
// back, reused. A move of the vertices, another key, or the same slot taken by other edges
// asks for the list again, and the tree is then the one those edges give. A tree a pass still
// holds is shared while nothing would change it, and copied before a refit.
TEST(EdgeHierarchy, KeyedTreeIsListedOnlyWhenTheGeometryOrTheKeyChanged) {
    HierarchyScene hs;
    SceneDesc d = hs.matte.desc();
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    const std::shared_ptr<Scene> scene = build_moved(d);
    size_t group = 0;
    const std::vector<int32_t> ids = edges_mesh_first(*scene, 0, &group);
    std::vector<int32_t> every(scene->edges().size());
    for (size_t i = 0; i < every.size(); ++i) every[i] = int32_t(i);
    int lists = 0;
    auto sphere_first = [&](std::vector<int32_t>& out, size_t& g) {
        ++lists;
        out = ids;
        g = group;
    };
    auto all_edges = [&](std::vector<int32_t>& out, size_t& g) {
        ++lists;
        out = every;
        g = 0;
    };
    const std::vector<uint8_t> key_a = {1, 1, 0, 0}, key_b = {0};
    // (No tree held here: a tree a pass still holds is copied before the scene changes it.)
    const EdgeHierarchy* a = scene->edge_hierarchy(key_a, sphere_first).get();
    EXPECT_EQ(lists, 1);
    EXPECT_EQ(a->edges(), ids);
    EXPECT_EQ(a->group(), group);
    EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
    // The same key, nothing changed: the same tree, not listed again.
    EXPECT_EQ(scene->edge_hierarchy(key_a, sphere_first).get(), a);
    EXPECT_EQ(lists, 1);
    EXPECT_EQ(scene->hierarchy_stats().reuses, 1u);
    // Another key: listed, the other slot built.
    EXPECT_EQ(scene->edge_hierarchy(key_b, all_edges)->edges(), every);
    EXPECT_EQ(lists, 2);
    EXPECT_EQ(scene->hierarchy_stats().builds, 2u);
    EXPECT_EQ(scene->edge_hierarchy(key_a, sphere_first)->edges(), ids);
    EXPECT_EQ(lists, 2);
    // The vertices moved: listed again (the list may depend on the geometry), the tree refit.
    for (float& x : hs.sphere.vertices) x *= 1.25f;
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    update_scene(*scene, d);
    const EdgeHierarchy* moved = scene->edge_hierarchy(key_a, sphere_first).get();
    EXPECT_EQ(lists, 3);
    EXPECT_EQ(scene->hierarchy_stats().refits, 1u);
    EXPECT_EQ(moved->check_bounds(*scene, 1e-5f), -1);
    EXPECT_EQ(scene->edge_hierarchy(key_a, sphere_first).get(), moved);
    EXPECT_EQ(lists, 3);
    // Both slots taken by trees asked for by their edges alone: key_a's tree is gone, so the key
    // lists again and gets a tree of its own edges.
    std::vector<int32_t> box_only;
    for (size_t i = 0; i < scene->edges().size(); ++i)
        if (scene->edges()[i].mesh == 1) box_only.push_back(int32_t(i));
    scene->edge_hierarchy(box_only, 0);
    scene->edge_hierarchy(every, 0);
    const std::shared_ptr<const EdgeHierarchy> back = scene->edge_hierarchy(key_a, sphere_first);
    EXPECT_EQ(lists, 4);
    EXPECT_EQ(scene->hierarchy_stats().builds, 5u);
    EXPECT_EQ(back->edges(), ids);
    EXPECT_EQ(back->group(), group);
    // Held (a pass in another thread reads it): shared as it is while nothing would change it,
    // by key or by its edges; copied before a move refits it, the held one left as it was.
    const uint64_t reuses = scene->hierarchy_stats().reuses;
    EXPECT_EQ(scene->edge_hierarchy(key_a, sphere_first).get(), back.get());
    EXPECT_EQ(scene->edge_hierarchy(ids, group).get(), back.get());
    EXPECT_EQ(scene->hierarchy_stats().reuses, reuses + 2);
    for (float& x : hs.sphere.vertices) x *= 0.8f;
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    update_scene(*scene, d);
    const std::shared_ptr<const EdgeHierarchy> refit = scene->edge_hierarchy(key_a, sphere_first);
    EXPECT_NE(refit.get(), back.get());
    EXPECT_EQ(refit->check_bounds(*scene, 1e-5f), -1);
    EXPECT_GE(back->check_bounds(*scene, 1e-5f), 0);  // still the tree of the positions before
}

// A refit gives the hierarchy a build gives where the build would split alike: every vertex
// scaled by two (every comparison of the median splits comes out the same, every bound scales
// exactly), the refit kept hierarchy and a fresh build give the same probabilities, bit for bit.
// A material made two-sided (the creases' flags) is taken up without a rebuild, the same way.
// Both scenes are of the form of a scene whose vertices move (built at other positions, then
// updated): their edge lists keep the nearly flat edges, which the trees hold as empty leaves.
TEST(EdgeHierarchy, RefitEqualsAFreshBuildThatSplitsAlike) {
    HierarchyScene hs;
    SceneDesc d = hs.desc();
    const std::shared_ptr<Scene> scene = build_moved(d);
    int flat = 0;
    for (const Edge& e : scene->edges()) flat += e.flat;
    EXPECT_GT(flat, 0);  // the box's and the quad's diagonals at least
    size_t group = 0;
    const std::vector<int32_t> ids = edges_mesh_first(*scene, 0, &group);
    const EdgeHierarchy before = *scene->edge_hierarchy(ids, group);
    for (MeshData* m : {&hs.sphere, &hs.box, &hs.quad})
        for (float& x : m->vertices) x *= 2.f;
    // The kept hierarchy and a fresh build over the scene `d` describes: the same
    // probabilities at random points, both strategies, every edge, from either start.
    auto expect_fresh = [&](const EdgeHierarchy& kept, const SceneDesc& desc) {
        const std::shared_ptr<Scene> fresh_scene = build_moved(desc);
        EdgeHierarchy fresh;
        fresh.build(*fresh_scene, ids, group);
        ASSERT_EQ(kept.group_root(), fresh.group_root());
        // Node for node, bit for bit: the same layout, bounds, cones and flags.
        EXPECT_EQ(kept.first_difference(fresh), -1);
        EXPECT_EQ(kept.check_bounds(*fresh_scene, 1e-5f), -1);
        Rng rng(8, 1);
        int nonzero = 0;
        for (int i = 0; i < 20; ++i) {
            BoundsCone cone;
            const EdgeHierarchy::Query q = random_query(rng, 4.f, 0.1f, 4.f, i % 2 == 0, cone);
            for (int32_t start : {0, kept.group_root()})
                for (int32_t e : ids) {
                    const EdgeHierarchy::Choice a = kept.pdf(q, e, start), b = fresh.pdf(q, e, start);
                    ASSERT_EQ(a.prob[0], b.prob[0]) << "edge " << e;
                    ASSERT_EQ(a.prob[1], b.prob[1]) << "edge " << e;
                    nonzero += a.prob[0] > 0.f;
                }
        }
        EXPECT_GT(nonzero, 100);
    };
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    update_scene(*scene, d);
    const EdgeHierarchy& refit = *scene->edge_hierarchy(ids, group);
    EXPECT_EQ(refit.first_difference(before), 0);  // every bound moved: the root differs
    EXPECT_EQ(scene->hierarchy_stats().refits, 1u);
    EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
    expect_fresh(refit, d);
    // One-sided creases (the box's) are skipped from behind; two-sided ones are not.
    d.materials[0].two_sided = true;
    update_scene(*scene, d);
    const EdgeHierarchy& flags = *scene->edge_hierarchy(ids, group);
    EXPECT_EQ(scene->hierarchy_stats().reuses, 1u);
    EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
    expect_fresh(flags, d);
    // Both at once: the vertices moved and the creases one-sided again (the leaves' flags set
    // with their bounds, the inner nodes' from theirs).
    for (MeshData* m : {&hs.sphere, &hs.box, &hs.quad})
        for (float& x : m->vertices) x *= 0.5f;  // a power of two: a fresh build splits alike
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    d.materials[0].two_sided = false;
    update_scene(*scene, d);
    const EdgeHierarchy& both = *scene->edge_hierarchy(ids, group);
    EXPECT_EQ(scene->hierarchy_stats().refits, 2u);
    EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
    expect_fresh(both, d);
}

// The same at the size where the checks, the leaves and the cones of an update go in parallel
// chunks (a sphere of some 12k edges beside the box and the floor): the refit, after every
// vertex is scaled by two, equals a fresh build node for node; after an uneven move its bounds
// hold every edge.
TEST(EdgeHierarchy, RefitOfALargeTreeEqualsAFreshBuild) {
    HierarchyScene hs;
    hs.sphere = make_sphere(Vec3f(0, 1, 0), 0.5f, 64, 96);
    SceneDesc d = hs.desc();
    const std::shared_ptr<Scene> scene = build_moved(d);
    size_t group = 0;
    const std::vector<int32_t> ids = edges_mesh_first(*scene, 0, &group);
    ASSERT_GT(ids.size(), 8192u);
    scene->edge_hierarchy(ids, group);
    for (MeshData* m : {&hs.sphere, &hs.box, &hs.quad})
        for (float& x : m->vertices) x *= 2.f;
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    update_scene(*scene, d);
    const EdgeHierarchy& refit = *scene->edge_hierarchy(ids, group);
    EXPECT_EQ(scene->hierarchy_stats().refits, 1u);
    const std::shared_ptr<Scene> fresh_scene = build_moved(d);
    EdgeHierarchy fresh;
    fresh.build(*fresh_scene, ids, group);
    EXPECT_EQ(refit.first_difference(fresh), -1);
    EXPECT_EQ(refit.check_bounds(*scene, 1e-5f), -1);
    // An uneven move: each vertex raised or lowered by a wave over its x and z.
    for (size_t v = 0; v + 2 < hs.sphere.vertices.size(); v += 3)
        hs.sphere.vertices[v + 1] += 0.1f * std::sin(7.f * hs.sphere.vertices[v]) * hs.sphere.vertices[v + 2];
    d.meshes = {hs.sphere.desc(0), hs.box.desc(0), hs.quad.desc(0)};
    update_scene(*scene, d);
    const EdgeHierarchy& moved = *scene->edge_hierarchy(ids, group);
    EXPECT_EQ(scene->hierarchy_stats().refits, 2u);
    EXPECT_EQ(scene->hierarchy_stats().builds, 1u);
    EXPECT_EQ(moved.check_bounds(*scene, 1e-5f), -1);
}

// A moving scene's flat edges (Edge::flat) are empty leaves: never sampled, zero probability
// under both strategies; the others' probabilities finite, those sample() reports pdf()'s.
TEST(EdgeHierarchy, FlatEdgesOfAMovingSceneAreNeverSampled) {
    HierarchyScene hs;
    const std::shared_ptr<Scene> scene = build_moved(hs.desc());
    std::vector<int32_t> ids;
    int flat = 0;
    for (size_t i = 0; i < scene->edges().size(); ++i) {
        ids.push_back(int32_t(i));
        flat += scene->edges()[i].flat;
    }
    ASSERT_GT(flat, 0);
    EdgeHierarchy h;
    h.build(*scene, ids);
    EXPECT_EQ(h.check_bounds(*scene, 1e-5f), -1);
    Rng rng(5, 2);
    int sampled = 0;
    for (int i = 0; i < 200; ++i) {
        BoundsCone cone;
        const EdgeHierarchy::Query q = random_query(rng, 2.f, 0.05f, 2.f, i % 2 == 0, cone);
        for (EdgeHierarchy::Strategy s : {EdgeHierarchy::All, EdgeHierarchy::Lights}) {
            EdgeHierarchy::Choice c[EdgeHierarchy::kMaxChoices];
            const int n = h.sample(q, s, rng.next_float(), c);
            for (int j = 0; j < n; ++j) {
                EXPECT_FALSE(scene->edges()[size_t(c[j].edge)].flat) << "edge " << c[j].edge;
                EXPECT_TRUE(std::isfinite(c[j].prob[0]) && std::isfinite(c[j].prob[1]));
                // What the sample reports is what pdf() gives (the estimate divides by it).
                const EdgeHierarchy::Choice p = h.pdf(q, c[j].edge);
                for (int k = 0; k < 2; ++k) EXPECT_NEAR(c[j].prob[k], p.prob[k], 1e-5f * p.prob[k]);
                ++sampled;
            }
        }
        for (size_t e = 0; e < scene->edges().size(); ++e)
            if (scene->edges()[e].flat) {
                const EdgeHierarchy::Choice c = h.pdf(q, int32_t(e));
                ASSERT_EQ(c.prob[0], 0.f);
                ASSERT_EQ(c.prob[1], 0.f);
            }
    }
    EXPECT_GT(sampled, 100);
}

// The memo's answers (a hit returns the kept value without reading the node, unless the node
// is refined) change nothing where a moving scene's flat edges make nodes of zero length: with
// one memo kept across queries, descents and trees, sample() and pdf() give what they give
// without one, bit for bit. (An entry claimed for a zero-length node and left unwritten would
// be read by a later hit with whatever an earlier query left in its slot.)
TEST(EdgeHierarchy, MemoGivesTheSameSamplesWithFlatEdges) {
    HierarchyScene hs;
    const std::shared_ptr<Scene> scene = build_moved(hs.desc());
    std::vector<int32_t> ids;
    for (size_t i = 0; i < scene->edges().size(); ++i) ids.push_back(int32_t(i));
    EdgeHierarchy h;
    h.build(*scene, ids);
    // Another tree over the same edges (numbered otherwise), whose queries leave other nodes'
    // values in the memo's slots before each compared query, as a thread's memo serves every
    // hierarchy it meets.
    std::vector<int32_t> reversed(ids.rbegin(), ids.rend());
    EdgeHierarchy other;
    other.build(*scene, reversed, reversed.size() / 2);
    Rng rng(17, 3);
    EdgeHierarchy::Memo memo;
    int compared = 0;
    for (int i = 0; i < 300; ++i) {
        EdgeHierarchy::Query plain;
        plain.p = Vec3f(4.f * rng.next_float() - 2.f, 0.05f + 2.f * rng.next_float(), 4.f * rng.next_float() - 2.f);
        plain.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1.f, 0.3f)), 0.5f,
                                     i % 3 ? 0.3f : 0.f, 0.05f + 0.3f * rng.next_float());
        const BoundsCone cone = cone_towards(plain.p, Vec3f(0.f, 8.f, 0.f), 0.05f + 0.5f * rng.next_float());
        plain.cone = &cone;
        plain.direct_only = i % 2 == 0;
        EdgeHierarchy::Query kept = plain;
        kept.memo = &memo;
        EdgeHierarchy::Query dirty = plain;
        dirty.p = Vec3f(4.f * rng.next_float() - 2.f, 0.05f + 2.f * rng.next_float(), 4.f * rng.next_float() - 2.f);
        dirty.memo = &memo;
        memo.reset();
        EdgeHierarchy::Choice scratch[EdgeHierarchy::kMaxChoices];
        for (int k = 0; k < 8; ++k) other.sample(dirty, EdgeHierarchy::Strategy(k % 2), rng.next_float(), scratch);
        memo.reset();
        compared += expect_same_samples(h, plain, kept, rng, 4, true);
        // Every edge's probabilities, every tenth query: the walks from the root reach the
        // small subtrees that hold flat edges, whose entries the samples left in the memo.
        if (i % 10 == 0)
            for (size_t e = 0; e < scene->edges().size(); ++e) {
                const EdgeHierarchy::Choice pa = h.pdf(plain, int32_t(e)), pb = h.pdf(kept, int32_t(e));
                ASSERT_EQ(pa.prob[0], pb.prob[0]) << "edge " << e;
                ASSERT_EQ(pa.prob[1], pb.prob[1]) << "edge " << e;
            }
    }
    EXPECT_GT(compared, 300);
}

// LightTriangles::outside() tests a triangle's three planes at once: the same answer, box for
// box, as one plane at a time (n . c + abs_n . half + reach < 0 for some plane of each
// triangle), over random points, triangles (some degenerate, some behind or edge-on) and boxes
// that hold the point, touch the wedges or lie far off; both answers occur many times.
TEST(LightTriangles, OutsideIsThePlaneByPlaneTest) {
    Rng rng(21, 5);
    auto uniform = [&](float lo, float hi) { return lo + (hi - lo) * rng.next_float(); };
    int outside = 0, inside = 0;
    for (int round = 0; round < 400; ++round) {
        const Vec3f p(uniform(-1, 1), uniform(-1, 1), uniform(-1, 1));
        const int count = 1 + round % LightTriangles::kMax;
        Vec3f corners[LightTriangles::kMax][3];
        for (int i = 0; i < count; ++i) {
            const Vec3f c(uniform(-2, 2), uniform(2, 3), uniform(-2, 2));
            for (int k = 0; k < 3; ++k) corners[i][k] = c + Vec3f(uniform(-0.5f, 0.5f), uniform(-0.2f, 0.2f), uniform(-0.5f, 0.5f));
            if (round % 7 == 3 && i == 0) corners[i][2] = corners[i][1];                 // degenerate
            if (round % 11 == 5 && i == 0) corners[i][0].y = corners[i][1].y = corners[i][2].y = p.y;  // edge-on
        }
        LightTriangles lights;
        lights.set(p, corners, count, round % 5 == 0 ? 0.f : uniform(0.f, 0.05f));
        for (int b = 0; b < 25; ++b) {
            const Vec3f c(uniform(-4, 4), uniform(-4, 5), uniform(-4, 4)), e(uniform(0, 1), uniform(0, 1), uniform(0, 1));
            const Vec3f lo = b % 6 == 0 ? min(c, p) : c - e, hi = b % 6 == 0 ? max(c, p) : c + e;
            // Plane by plane, as the sums are written in outside().
            const Vec3f mid = (lo + hi) * 0.5f - p, half = (hi - lo) * 0.5f;
            const float far = std::abs(mid.x) + std::abs(mid.y) + std::abs(mid.z) + half.x + half.y + half.z;
            const float reach = (lights.margin + 1e-5f) * far;
            bool want = true;
            for (int i = 0; i < lights.count && want; ++i) {
                bool out = false;
                for (int k = 0; k < 3; ++k) out = out || dot(lights.n[i][k], mid) + dot(lights.abs_n[i][k], half) + reach < 0.f;
                want = out;
            }
            const bool got = lights.outside(lo, hi);
            ASSERT_EQ(got, want) << "round " << round << " box " << b;
            (got ? outside : inside) += 1;
        }
    }
    EXPECT_GT(outside, 1000);
    EXPECT_GT(inside, 1000);
    LightTriangles none;
    EXPECT_FALSE(none.outside(Vec3f(5.f), Vec3f(6.f)));  // no triangles: not known
}

// The point sampler set up from a kept arc and Lights part (ArcPart, as a leaf's scoring keeps
// them) is bit for bit the one setup() computes from the edge's ends; pdfs() gives pdf()'s two
// densities bit for bit, and with strategy Lights left out, All's alone; the lazily built light
// table gives the same densities whichever call builds it first. Random points, edges, lobes
// (diffuse and glossy), light cones and triangles.
TEST(EdgePointSampler, KeptArcAndBothDensitiesAreBitForBitTheSame) {
    Rng rng(21, 4);
    auto bits = [](float x) {
        uint32_t u;
        std::memcpy(&u, &x, 4);
        return u;
    };
    const Vec3f sq[4] = {Vec3f(-0.4f, 3, -0.4f), Vec3f(0.4f, 3, -0.4f), Vec3f(0.4f, 3, 0.4f), Vec3f(-0.4f, 3, 0.4f)};
    const Vec3f tris[2][3] = {{sq[0], sq[2], sq[1]}, {sq[0], sq[3], sq[2]}};
    int with_part = 0, compared = 0;
    for (int i = 0; i < 400; ++i) {
        const Vec3f p(2.f * rng.next_float() - 1.f, 0.5f * rng.next_float(), 2.f * rng.next_float() - 1.f);
        const Vec3f v0(4.f * rng.next_float() - 2.f, 0.6f + 2.f * rng.next_float(), 4.f * rng.next_float() - 2.f);
        const Vec3f v1(4.f * rng.next_float() - 2.f, 0.6f + 2.f * rng.next_float(), 4.f * rng.next_float() - 2.f);
        BoundsCone cone = cone_towards(p, Vec3f(0, 3, 0), 0.4f * std::sqrt(2.f));
        LightTriangles lights;
        lights.set(p, tris, 2, 4e-4f);
        const LightTriangles* tri = i % 3 == 0 ? nullptr : &lights;
        const LobeBound lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1.f, rng.next_float() - 0.5f)),
                                               0.5f, i % 2 ? 0.8f : 0.f, 0.05f + 0.3f * rng.next_float());
        EdgePointSampler ref, kept, first_pdf;
        const bool ok = ref.setup(p, v0, v1, lobe, &cone, tri);
        ArcPart known;
        const bool part = known.compute(p, v0, v1, cone, tri);
        EXPECT_EQ(known.arc_ok, ok);
        ASSERT_EQ(kept.setup(known, lobe, &cone), ok);
        ASSERT_EQ(first_pdf.setup(known, lobe, &cone), ok);
        if (!ok) continue;
        with_part += part;
        // Without a cone: strategy All's density alone, the same as setup() without a cone.
        EdgePointSampler plain_ref, plain;
        ASSERT_TRUE(plain_ref.setup(p, v0, v1, lobe, nullptr));
        ASSERT_TRUE(plain.setup(known, lobe, nullptr));
        for (int j = 0; j < 24; ++j) {
            const float u = rng.next_float(), v = (float(j) + 0.5f) / 24.f;
            // first_pdf builds its light table from a density, kept from a sample.
            float a0, l0;
            first_pdf.pdfs(v, true, a0, l0);
            for (int s = 0; s < 2; ++s) {
                const auto st = EdgeHierarchy::Strategy(s);
                float tr = -1.f, tk = -2.f;
                const bool sr = ref.sample(st, u, tr), sk = kept.sample(st, u, tk);
                ASSERT_EQ(sr, sk);
                if (sr) {
                    EXPECT_EQ(bits(tr), bits(tk)) << "query " << i << " u " << u;
                } else {
                    tr = v;
                }
                float all, lt, alone, none;
                kept.pdfs(tr, true, all, lt);
                EXPECT_EQ(bits(all), bits(ref.pdf(EdgeHierarchy::All, tr)));
                EXPECT_EQ(bits(lt), bits(ref.pdf(EdgeHierarchy::Lights, tr)));
                EXPECT_EQ(bits(first_pdf.pdf(EdgeHierarchy::Lights, tr)), bits(lt));
                kept.pdfs(tr, false, alone, none);
                EXPECT_EQ(bits(alone), bits(all));
                EXPECT_EQ(none, 0.f);
                plain.pdfs(tr, true, alone, none);
                EXPECT_EQ(bits(alone), bits(plain_ref.pdf(EdgeHierarchy::All, tr)));
                EXPECT_EQ(bits(alone), bits(all));  // the cone changes strategy Lights only
                EXPECT_EQ(none, 0.f);
                ++compared;
            }
            EXPECT_EQ(bits(a0), bits(ref.pdf(EdgeHierarchy::All, v)));
            EXPECT_EQ(bits(l0), bits(ref.pdf(EdgeHierarchy::Lights, v)));
        }
    }
    EXPECT_GT(with_part, 40);
    EXPECT_GT(compared, 10000);
}

// LeafArcs keeps the latest kSize arcs: finds the latest entry of an edge with the same ends,
// nothing for ends that differ, an entry pushed out or one from before reset().
TEST(LeafArcs, FindsTheLatestWithTheSameEnds) {
    LeafArcs arcs;
    const Vec3f p(0.1f, -1.f, 0.2f);
    auto part_of = [&](int i, ArcPart& a) {
        const Vec3f v0(float(i), 0.f, 1.f), v1(float(i), 1.f, 1.f);
        a.arc_ok = a.arc.set(p, v0, v1);
        a.lo = float(i);
        return std::make_pair(v0, v1);
    };
    const int n = LeafArcs::kSize + 5;
    for (int i = 0; i < n; ++i) {
        ArcPart a;
        const auto [v0, v1] = part_of(i, a);
        arcs.keep(int32_t(i % (n - 2)), v0, v1, a);  // edges 0 and 1 kept twice
    }
    for (int i = 0; i < n; ++i) {
        ArcPart a;
        const auto [v0, v1] = part_of(i, a);
        const ArcPart* f = arcs.find(int32_t(i % (n - 2)), v0, v1);
        if (i < n - LeafArcs::kSize) {
            // Pushed out, or (edges 0 and 1) replaced by a later entry with other ends.
            EXPECT_EQ(f, nullptr) << i;
            continue;
        }
        ASSERT_NE(f, nullptr) << i;
        EXPECT_EQ(f->lo, float(i));
        EXPECT_EQ(f->arc.h, a.arc.h);
        EXPECT_EQ(arcs.find(int32_t(i % (n - 2)), v0, v1 + Vec3f(0.f, 1e-6f, 0.f)), nullptr);
    }
    arcs.reset();
    ArcPart a;
    const auto [v0, v1] = part_of(n - 1, a);
    EXPECT_EQ(arcs.find(int32_t((n - 1) % (n - 2)), v0, v1), nullptr);
}

// A query that keeps its leaves' arcs (Query::arcs) samples the same edges with the same
// expected counts, and holds the arc and Lights part of nearly every chosen edge strategy
// Lights can pick, bit for bit those ArcPart::compute gives.
TEST(EdgeHierarchy, KeptLeafArcsAreTheChosenEdgesArcs) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    const EdgeHierarchy h = hierarchy_of_all(scene);
    Rng rng(8, 1);
    int lights_choices = 0, found = 0;
    for (int i = 0; i < 200; ++i) {
        const Vec3f p(4.f * rng.next_float() - 2.f, 0.01f, 4.f * rng.next_float() - 2.f);
        SquareLightSeen seen(p);
        const BoundsCone& cone = seen.cone;
        const LightTriangles& lights = seen.lights;
        EdgeHierarchy::Query q;
        q.p = p;
        q.lobe = LobeBound::make(Vec3f(0, 1, 0), normalize(Vec3f(rng.next_float() - 0.5f, 1.f, rng.next_float() - 0.5f)), 0.5f,
                                 i % 2 ? 0.8f : 0.f, 0.1f);
        q.cone = &cone;
        q.lights = i % 4 == 3 ? nullptr : &lights;
        EdgeHierarchy::Memo memo, memo_kept;
        LeafArcs arcs;
        const auto s = EdgeHierarchy::Strategy(i % 2);
        const float u = rng.next_float();
        memo.reset();
        q.memo = &memo;
        EdgeHierarchy::Choice plain[EdgeHierarchy::kMaxChoices], kept[EdgeHierarchy::kMaxChoices];
        const int n = h.sample(q, s, u, plain);
        memo_kept.reset();
        q.memo = &memo_kept;
        q.arcs = &arcs;
        ASSERT_EQ(h.sample(q, s, u, kept), n);
        for (int c = 0; c < n; ++c) {
            ASSERT_EQ(kept[c].edge, plain[c].edge);
            EXPECT_EQ(kept[c].prob[0], plain[c].prob[0]);
            EXPECT_EQ(kept[c].prob[1], plain[c].prob[1]);
            if (!(kept[c].prob[1] > 0.f)) continue;
            ++lights_choices;
            const Edge& e = scene.edges()[size_t(kept[c].edge)];
            const Mesh& m = scene.meshes[size_t(e.mesh)];
            const Vec3f v0 = m.vertex(e.v0), v1 = m.vertex(e.v1);
            const ArcPart* f = arcs.find(kept[c].edge, v0, v1);
            if (!f) continue;
            ++found;
            ArcPart ref;
            const bool part = ref.compute(p, v0, v1, cone, q.lights);
            EXPECT_EQ(f->part, part);
            EXPECT_EQ(f->arc_ok, ref.arc_ok);
            if (ref.arc_ok) {
                EXPECT_EQ(std::memcmp(&f->arc, &ref.arc, sizeof(EdgeArc)), 0);
            }
            if (part) {
                EXPECT_EQ(f->lo, ref.lo);
                EXPECT_EQ(f->hi, ref.hi);
                EXPECT_EQ(f->t0, ref.t0);
                EXPECT_EQ(f->t1, ref.t1);
            }
        }
    }
    EXPECT_GT(lights_choices, 50);
    EXPECT_GT(found, 0.9 * lights_choices);
}

}  // namespace
}  // namespace edgepath
