// The two sides of an edge sample in the limit at the edge point (edges/sides.h): which face
// each side sees (its own faces a step off the edge), the far side of a fold however thin what lies there, occlusion by a sliver
// thinner than any fixed side step, and folds told apart from creases whatever the winding.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "edgepath.h"
#include "edges/sides.h"
#include "scene/scene.h"

namespace edgepath {
namespace {

// The eye at the origin looking along +z. Mesh 0: the edge (0, -1, 2) - (0, 1, 2) with face 0
// (third vertex (-1, 0, 2), facing the eye) and either face 1 folding back behind it on the
// same side ((-1, 0, 3)) or face 1 continuing the surface on the other side ((1, 0, 2.2)).
// Mesh 1: a sliver (x from -1e-6 to 2e-6, about 1e-6 rad as seen from the eye) at depth
// `sliver_z`, across the edge's line.
struct SidesScene {
    std::vector<float> fold_vertices, sliver_vertices = {-1e-6f, -1, 0, -1e-6f, 1, 0, 2e-6f, 0, 0};
    std::vector<int32_t> fold_indices = {0, 1, 2, 1, 0, 3}, sliver_indices = {0, 1, 2};
    std::vector<float> kd = {0.5f, 0.5f, 0.5f}, ks = {0, 0, 0}, rough = {0.5f};
    std::shared_ptr<const Scene> scene;
    SidesScene(bool fold, float sliver_z, bool flip_second = false, const std::vector<float>& second = {}) {
        fold_vertices = {0, -1, 2, 0, 1, 2, -1, 0, 2, fold ? -1.f : 1.f, 0, fold ? 3.f : 2.2f};
        if (flip_second) std::swap(fold_indices[3], fold_indices[4]);
        for (int k = 0; k < 3; ++k) sliver_vertices[3 * k + 2] = sliver_z;
        if (!second.empty()) sliver_vertices = second;
        SceneDesc d;
        d.camera.width = d.camera.height = 8;
        MaterialDesc m;
        m.diffuse = {kd.data(), 1, 1, 3};
        m.specular = {ks.data(), 1, 1, 3};
        m.roughness = {rough.data(), 1, 1, 1};
        d.materials.push_back(m);
        MeshDesc a, b;
        a.vertices = fold_vertices.data();
        a.num_vertices = 4;
        a.indices = fold_indices.data();
        a.num_triangles = 2;
        b.vertices = sliver_vertices.data();
        b.num_vertices = 3;
        b.indices = sliver_indices.data();
        b.num_triangles = 1;
        d.meshes = {a, b};
        scene = build_scene(d);
    }
    Edge edge() const {
        Edge e;
        e.mesh = 0;
        e.v0 = 0;
        e.v1 = 1;
        e.f0 = 0;
        e.f1 = 1;
        e.kind = EdgeKind::Crease;
        return e;
    }
};

// The ray from the eye through the point at parameter s of the edge, and that point's distance.
Ray ray_to_edge(float s, float& t_x) {
    const Vec3f x(0.f, -1.f + 2.f * s, 2.f);
    t_x = length(x);
    Ray r;
    r.dir = x / t_x;
    return r;
}

// A side that sees one of the edge's own faces, evaluated on that face just off the edge point x
// (four times the rounding bound, 1e-6 of the distance t_x plus the largest coordinate of x,
// from the edge's line), on the way to the face's third vertex c, on its own ray: not on the
// edge itself, where a path leaving it can pass the edge's other face by rounding.
void expect_on_face_off_edge(const Scene& scene, const EdgeSide& side, const Vec3f& x, const Vec3f& c, float t_x) {
    const float step = 4e-6f * (t_x + max_abs_component(x));
    EXPECT_TRUE(side.off_edge);
    const Vec3f p = scene.surface_point(side.hit).p;
    EXPECT_NEAR(length(cross(p - x, normalize(c - x))), 0.f, 1e-6f);  // between x and c
    EXPECT_GT(dot(p - x, c - x), 0.f);
    // The edge is the line x = 0, z = 2.
    EXPECT_NEAR(std::hypot(p.x, p.z - 2.f) / step, 1.f, 0.05f);  // p is rounded to float
    EXPECT_NEAR(length(side.ray.origin + side.ray.dir * side.hit.t - p), 0.f, 1e-6f);
}

// The side function's upper side of the edge (0, -1, 2) -> (0, 1, 2) seen from the origin is
// x < 0: g = dot(cross(e0, e1), d) = -4 d.x.
TEST(EdgeSides, FoldSeesItsNearFaceAndWhatLiesJustBeyond) {
    {
        SidesScene s(true, 2.5f);  // a sliver just behind the edge
        EdgeEye eye;
        float t_x;
        const Ray ray = ray_to_edge(0.3f, t_x);
        EdgeSide upper, lower;
        ASSERT_TRUE(edge_sides(*s.scene, eye, s.edge(), ray, 0.3f, t_x, upper, lower));
        // Both faces lie on the upper side; face 0 (at depth 2) hides face 1 (going deeper).
        ASSERT_TRUE(upper.found);
        EXPECT_EQ(upper.hit.mesh, 0);
        EXPECT_EQ(upper.hit.prim, 0);
        expect_on_face_off_edge(*s.scene, upper, Vec3f(0.f, -0.4f, 2.f), Vec3f(-1.f, 0.f, 2.f), t_x);
        // The far side: the sliver, 1e-6 rad wide (a step of 1e-5 rad leaps over it).
        ASSERT_TRUE(lower.found);
        EXPECT_EQ(lower.hit.mesh, 1);
        EXPECT_GT(lower.hit.t, t_x);
    }
    // Nothing beyond (the sliver behind the eye): the far side sees nothing at all.
    SidesScene s(true, -50.f);
    EdgeEye eye;
    float t_x;
    EdgeSide upper, lower;
    const Ray ray = ray_to_edge(0.6f, t_x);
    ASSERT_TRUE(edge_sides(*s.scene, eye, s.edge(), ray, 0.6f, t_x, upper, lower));
    EXPECT_TRUE(upper.found);
    EXPECT_FALSE(lower.found);
}

// A floor through the edge's line (a wall standing on a floor): nearer than the edge's faces on
// the outer side, behind them on the other (plane z = 2 - x).
// the outer side sees the floor, not at the edge point (rays leaving it graze the edge's faces)
// but a step off the edge on the floor's plane, on a ray aimed there.
TEST(EdgeSides, OuterSideTouchingTheEdgeIsEvaluatedOffIt) {
    SidesScene s(true, 0.f, false, {-3, -5, 5, -3, 5, 5, 1.5f, 0, 0.5f});
    EdgeEye eye;
    eye.step = 1e-4f;
    float t_x;
    const Ray ray = ray_to_edge(0.4f, t_x);
    EdgeSide upper, lower;
    ASSERT_TRUE(edge_sides(*s.scene, eye, s.edge(), ray, 0.4f, t_x, upper, lower));
    EXPECT_EQ(upper.hit.prim, 0);
    expect_on_face_off_edge(*s.scene, upper, Vec3f(0.f, -0.2f, 2.f), Vec3f(-1.f, 0.f, 2.f), t_x);
    ASSERT_TRUE(lower.found);
    EXPECT_EQ(lower.hit.mesh, 1);
    ASSERT_TRUE(lower.off_edge);
    // On the floor, on the lower side (x > 0), about step * t_x off the edge.
    const Vec3f x(0.f, -0.2f, 2.f);
    const Vec3f p = s.scene->surface_point(lower.hit).p;
    EXPECT_NEAR(p.z, 2.f - p.x, 1e-6f);
    EXPECT_GT(p.x, 0.f);
    EXPECT_NEAR(length(p - x), 1e-4f * t_x, 1e-4f * t_x);
    EXPECT_NEAR(length(lower.ray.origin + lower.ray.dir * lower.hit.t - p), 0.f, 1e-5f);
    // A floor well behind the edge point is not touching: seen on the eye's ray itself.
    SidesScene behind(true, 0.f, false, {-3, -5, 5.5f, -3, 5, 5.5f, 1.5f, 0, 1.f});
    ASSERT_TRUE(edge_sides(*behind.scene, eye, behind.edge(), ray, 0.4f, t_x, upper, lower));
    EXPECT_EQ(lower.hit.mesh, 1);
    EXPECT_FALSE(lower.off_edge);
    EXPECT_GT(lower.hit.t, t_x);
}

TEST(EdgeSides, ThinOccluderHidesTheEdgePoint) {
    SidesScene s(true, 1.5f);  // the sliver in front of the edge
    EdgeEye eye;
    float t_x;
    EdgeSide upper, lower;
    const Ray through_sliver = ray_to_edge(0.5f, t_x);
    EXPECT_FALSE(edge_sides(*s.scene, eye, s.edge(), through_sliver, 0.5f, t_x, upper, lower));
    // Off the sliver (it narrows to a point at y = +-1): visible again.
    const Ray past_sliver = ray_to_edge(0.02f, t_x);
    EXPECT_TRUE(edge_sides(*s.scene, eye, s.edge(), past_sliver, 0.02f, t_x, upper, lower));
}

TEST(EdgeSides, CreaseSeesOneFaceOnEachSideWhateverTheWinding) {
    for (bool flip : {false, true}) {
        SidesScene s(false, 50.f, flip);
        EdgeEye eye;
        float t_x;
        EdgeSide upper, lower;
        const Ray ray = ray_to_edge(0.7f, t_x);
        ASSERT_TRUE(edge_sides(*s.scene, eye, s.edge(), ray, 0.7f, t_x, upper, lower));
        EXPECT_EQ(upper.hit.prim, 0);
        EXPECT_EQ(lower.hit.prim, 1);
        EXPECT_EQ(lower.hit.mesh, 0);
        expect_on_face_off_edge(*s.scene, lower, Vec3f(0.f, 0.4f, 2.f), Vec3f(1.f, 0.f, 2.2f), t_x);
        EXPECT_FALSE(is_fold(eye, s.scene->meshes[0], s.edge()));
        SidesScene f(true, 50.f, flip);
        EXPECT_TRUE(is_fold(eye, f.scene->meshes[0], f.edge()));
        // A parallel eye looking along +z sees the same.
        EdgeEye parallel;
        parallel.parallel = true;
        parallel.dir = Vec3f(0, 0, 1);
        EXPECT_FALSE(is_fold(parallel, s.scene->meshes[0], s.edge()));
        EXPECT_TRUE(is_fold(parallel, f.scene->meshes[0], f.edge()));
    }
}

// Whether the eye is behind both faces' planes, by their geometric normals (the camera pass
// leaves out an edge that does not fold seen so, on a mesh black from behind).
TEST(EdgeSides, SeenFromBehindIsByBothFacesGeometricNormals) {
    SidesScene s(false, 50.f);               // both faces' normals about +z, away from the eye
    SidesScene flipped(false, 50.f, true);   // face 1 wound the other way: it faces the eye
    const Mesh& m = s.scene->meshes[0];
    EdgeEye eye;
    EXPECT_TRUE(seen_from_behind(eye, m, s.edge()));
    EXPECT_FALSE(seen_from_behind(eye, flipped.scene->meshes[0], flipped.edge()));
    eye.origin = Vec3f(0, 0, 5);  // past both faces: in front of them
    EXPECT_FALSE(seen_from_behind(eye, m, s.edge()));
    eye.origin = Vec3f(0, 0, 2);  // in face 0's plane: not behind it
    EXPECT_FALSE(seen_from_behind(eye, m, s.edge()));
    EdgeEye parallel;
    parallel.parallel = true;
    parallel.dir = Vec3f(0, 0, 1);  // looking along the normals
    EXPECT_TRUE(seen_from_behind(parallel, m, s.edge()));
    parallel.dir = Vec3f(0, 0, -1);
    EXPECT_FALSE(seen_from_behind(parallel, m, s.edge()));
    Edge boundary = s.edge();  // one face: a boundary is never left out
    boundary.f1 = -1;
    EXPECT_FALSE(seen_from_behind(EdgeEye(), m, boundary));
}

TEST(EdgeSides, PointBehindTheEyeIsDropped) {
    SidesScene s(true, 50.f);
    EdgeEye eye;
    Ray ray;
    ray.origin = Vec3f(0, 0, 3);  // past the edge, looking on along +z
    ray.dir = Vec3f(0, 0, 1);
    EdgeSide upper, lower;
    EXPECT_FALSE(edge_sides(*s.scene, eye, s.edge(), ray, 0.5f, -1.f, upper, lower));
}

}  // namespace
}  // namespace edgepath
