// Tests for support/teapot: the tessellated Newell teapot is a valid, well-formed mesh.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <tuple>
#include <vector>

#include "edgepath.h"
#include "support/teapot.h"

namespace edgepath {
namespace {

Vec3f vertex(const MeshData& m, int64_t i) { return Vec3f::load(&m.vertices[3 * size_t(i)]); }
Vec3f normal(const MeshData& m, int64_t i) { return Vec3f::load(&m.normals[3 * size_t(i)]); }

TEST(Teapot, TriangleCountScalesWithSubdivisions) {
    for (int n : {1, 2, 3, 4, 8, 16}) {
        MeshData m = make_teapot(n);
        EXPECT_EQ(m.num_triangles(), teapot_triangle_count(n)) << "n = " << n;
        EXPECT_EQ(m.num_vertices(), 32 * int64_t(n + 1) * (n + 1)) << "n = " << n;
    }
    EXPECT_EQ(teapot_triangle_count(1), 52);  // 32 patches x 2, less 8 at the poles, 4 at the spout tip
    EXPECT_EQ(teapot_triangle_count(2), 240); // 32 x 8, less 2 per pole patch
    EXPECT_EQ(teapot_triangle_count(10), 6320);
    EXPECT_THROW(make_teapot(0), std::invalid_argument);
}

TEST(Teapot, ArraysAreConsistent) {
    MeshData m = make_teapot(6);
    ASSERT_EQ(m.vertices.size() % 3, 0u);
    ASSERT_EQ(m.normals.size(), m.vertices.size());
    ASSERT_EQ(m.uvs.size() / 2, m.vertices.size() / 3);
    ASSERT_EQ(m.indices.size() % 3, 0u);
    for (int32_t i : m.indices) {
        ASSERT_GE(i, 0);
        ASSERT_LT(i, m.num_vertices());
    }
    for (float uv : m.uvs) {
        EXPECT_GE(uv, 0.f);
        EXPECT_LE(uv, 1.f);
    }
}

TEST(Teapot, NoZeroAreaTriangles) {
    for (int n : {1, 5, 32}) {
        MeshData m = make_teapot(n);
        for (int64_t t = 0; t < m.num_triangles(); ++t) {
            Vec3f a = vertex(m, m.indices[3 * t]), b = vertex(m, m.indices[3 * t + 1]), c = vertex(m, m.indices[3 * t + 2]);
            // As the scene validation computes it.
            double area2 = length(cross(Vec3d(b - a), Vec3d(c - a)));
            ASSERT_GT(area2, 0.0) << "n = " << n << ", triangle " << t;
            // And the renderer's float normal is well defined.
            Vec3f ng = cross(b - a, c - a);
            ASSERT_GT(length(ng), 0.f) << "n = " << n << ", triangle " << t;
        }
    }
}

TEST(Teapot, NormalsAreUnitFiniteAndAgreeWithWinding) {
    for (bool y_up : {true, false}) {
        MeshData m = make_teapot(12, y_up);
        for (int64_t i = 0; i < m.num_vertices(); ++i) {
            Vec3f n = normal(m, i);
            ASSERT_TRUE(all_finite(n)) << "vertex " << i;
            ASSERT_NEAR(length(n), 1.f, 1e-5f) << "vertex " << i;
        }
        // Every smooth normal lies on the front side of its triangles (outward winding), and
        // nearly all agree closely with the face normal.
        int64_t close = 0;
        for (int64_t t = 0; t < m.num_triangles(); ++t) {
            const int32_t* tri = &m.indices[3 * size_t(t)];
            Vec3f a = vertex(m, tri[0]), b = vertex(m, tri[1]), c = vertex(m, tri[2]);
            Vec3f ng = normalize(cross(b - a, c - a));
            float worst = 1.f;
            for (int k = 0; k < 3; ++k) worst = std::min(worst, dot(ng, normal(m, tri[k])));
            EXPECT_GT(worst, 0.f) << "triangle " << t << (y_up ? " (y up)" : " (z up)");
            if (worst > 0.9f) ++close;
        }
        EXPECT_GT(double(close) / double(m.num_triangles()), 0.97);
    }
}

TEST(Teapot, BoundingBoxIsPlausible) {
    MeshData m = make_teapot(16, /*y_up=*/false);
    Vec3f lo(1e30f), hi(-1e30f);
    for (int64_t i = 0; i < m.num_vertices(); ++i) {
        Vec3f p = vertex(m, i);
        for (int c = 0; c < 3; ++c) {
            lo[c] = std::min(lo[c], p[c]);
            hi[c] = std::max(hi[c], p[c]);
        }
    }
    // z up: base at 0, knob top at 3.15, body radius 2, handle at x = -3, spout tip near 3.43.
    EXPECT_NEAR(lo.z, 0.f, 1e-6f);
    EXPECT_NEAR(hi.z, 3.15f, 1e-5f);
    EXPECT_NEAR(lo.y, -2.f, 1e-3f);
    EXPECT_NEAR(hi.y, 2.f, 1e-3f);
    EXPECT_NEAR(lo.x, -3.f, 1e-3f);
    EXPECT_GT(hi.x, 3.3f);
    EXPECT_LT(hi.x, 3.525f);

    // y up: the same box with (x, y, z) -> (x, z, -y).
    MeshData u = make_teapot(16);
    Vec3f ulo(1e30f), uhi(-1e30f);
    for (int64_t i = 0; i < u.num_vertices(); ++i) {
        Vec3f p = vertex(u, i);
        for (int c = 0; c < 3; ++c) {
            ulo[c] = std::min(ulo[c], p[c]);
            uhi[c] = std::max(uhi[c], p[c]);
        }
    }
    EXPECT_FLOAT_EQ(ulo.x, lo.x);
    EXPECT_FLOAT_EQ(uhi.x, hi.x);
    EXPECT_FLOAT_EQ(ulo.y, lo.z);
    EXPECT_FLOAT_EQ(uhi.y, hi.z);
    EXPECT_FLOAT_EQ(ulo.z, -hi.y);
    EXPECT_FLOAT_EQ(uhi.z, -lo.y);
}

TEST(Teapot, EnclosesPositiveVolume) {
    // The surface is not closed (the lid sits inside the rim, the spout and handle pierce the
    // body), but with outward winding the divergence-theorem volume is positive and close to
    // that of the body of revolution (about 26 in the data's units).
    MeshData m = make_teapot(16);
    double volume = 0.0;
    for (int64_t t = 0; t < m.num_triangles(); ++t) {
        const int32_t* tri = &m.indices[3 * size_t(t)];
        Vec3d a(vertex(m, tri[0])), b(vertex(m, tri[1])), c(vertex(m, tri[2]));
        volume += dot(a, cross(b, c)) / 6.0;
    }
    EXPECT_GT(volume, 15.0);
    EXPECT_LT(volume, 40.0);
}

TEST(Teapot, SeamsAreWatertight) {
    // Positions shared by patches are bit-identical: every vertex position on a patch boundary
    // occurs at least twice (except on the open boundaries: the rim's edges, the spout's
    // opening, the handle's ends, the lid's outer edge), so most boundary positions repeat.
    const int n = 8;
    MeshData m = make_teapot(n);
    std::map<std::tuple<float, float, float>, int> count;
    for (int64_t i = 0; i < m.num_vertices(); ++i) {
        Vec3f p = vertex(m, i);
        ++count[{p.x, p.y, p.z}];
    }
    int64_t boundary = 0, repeated = 0;
    for (int64_t patch = 0; patch < 32; ++patch)
        for (int a = 0; a <= n; ++a)
            for (int b = 0; b <= n; ++b) {
                if (a != 0 && a != n && b != 0 && b != n) continue;
                Vec3f p = vertex(m, patch * (n + 1) * (n + 1) + a * (n + 1) + b);
                ++boundary;
                if (count[{p.x, p.y, p.z}] >= 2) ++repeated;
            }
    EXPECT_GT(double(repeated) / double(boundary), 0.7);
}

TEST(Teapot, BuildsIntoAScene) {
    MeshData m = make_teapot(4);
    float white[3] = {0.5f, 0.5f, 0.5f}, zero[3] = {0.f, 0.f, 0.f}, rough[1] = {0.3f};
    SceneDesc d;
    d.camera.position[2] = 10.f;
    d.camera.look_at[2] = 0.f;
    d.camera.width = d.camera.height = 8;
    MaterialDesc mat;
    mat.diffuse = {white, 1, 1, 3};
    mat.specular = {zero, 1, 1, 3};
    mat.roughness = {rough, 1, 1, 1};
    d.materials.push_back(mat);
    d.meshes.push_back(m.desc(0));
    EXPECT_NO_THROW(build_scene(d));
}

}  // namespace
}  // namespace edgepath
