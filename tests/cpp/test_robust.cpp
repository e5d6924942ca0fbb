// Ray offsets bounded by the hit point's rounding error, degenerate triangles, cancellation and
// the ranges Scene::build enforces.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "edgepath.h"
#include "math/ray.h"
#include "math/simd4.h"
#include "render/packet.h"
#include "render/shade_kernel.h"
#include "sampling/warp.h"
#include "sampling/rng.h"
#include "render/tiles.h"
#include "scene/geometry.h"
#include "scene/scene.h"
#include "support/shapes.h"

namespace edgepath {
namespace {

struct Fixture {
    std::vector<float> kd{0.5f, 0.5f, 0.5f}, ks{0.f, 0.f, 0.f}, rough{0.5f}, le{1.f, 1.f, 1.f};
    MeshData mesh;
    SceneDesc desc;

    static TextureDesc tex(const std::vector<float>& v) {
        TextureDesc t;
        t.data = v.data();
        t.height = t.width = 1;
        t.channels = int(v.size());
        return t;
    }
    // One mesh with `vertices` / `indices`, a camera at `eye` looking at `target`.
    Fixture(std::vector<float> vertices, std::vector<int32_t> indices, Vec3f eye = Vec3f(0, 0, -5),
            Vec3f target = Vec3f(0, 0, 0)) {
        mesh.vertices = std::move(vertices);
        mesh.indices = std::move(indices);
        for (int k = 0; k < 3; ++k) {
            desc.camera.position[k] = eye[k];
            desc.camera.look_at[k] = target[k];
        }
        desc.camera.width = desc.camera.height = 8;
        MaterialDesc m;
        m.diffuse = tex(kd);
        m.specular = tex(ks);
        m.roughness = tex(rough);
        desc.materials.push_back(m);
        desc.meshes.push_back(mesh.desc(0));
    }
};

std::string build_error(const SceneDesc& d) {
    try {
        build_scene(d);
    } catch (const std::invalid_argument& e) {
        return e.what();
    }
    return "";
}

// Rays leaving random points of random triangles, to either side, placed far from the origin
// or tiny, never meet their own triangle again (a relative epsilon failed at 1e5 and 1e-5).
TEST(RayOffset, SpawnedRaysNeverHitTheirOwnTriangle) {
    Rng rng(7, 1);
    for (double place : {0.0, 1e3, 1e5, -3e6}) {
        for (double scale : {1e-5, 1.0, 1e3}) {
            std::vector<float> v;
            for (int k = 0; k < 9; ++k) v.push_back(float(place + scale * (2.0 * rng.next_double() - 1.0)));
            Fixture f(v, {0, 1, 2});
            auto scene = build_scene(f.desc);
            for (int i = 0; i < 2000; ++i) {
                const float b1 = rng.next_float(), b2 = rng.next_float() * (1.f - b1);
                const SurfacePoint sp = scene->surface_point(0, 0, b1, b2);
                Vec3f d = normalize(Vec3f(rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f));
                if (i % 2) d = normalize(d + sp.ng * (i % 4 == 1 ? 1e-3f : -1e-3f) - sp.ng * dot(d, sp.ng));  // grazing
                Hit hit;
                ASSERT_FALSE(scene->intersect(spawn_ray(sp, d), hit))
                    << "place " << place << " scale " << scale << " sample " << i;
            }
        }
    }
}

// A shadow ray between two points of two parallel triangles facing each other is unoccluded
// (it must neither hit its own triangle nor the target's), at any placement.
// The inline steps to the neighbouring floats agree with std::nextafter bit for bit: zeros of
// both signs, subnormals, the largest finite values, infinities, and random bit patterns.
TEST(RayOffset, NextFloatAgreesWithNextafter) {
    const float inf = std::numeric_limits<float>::infinity();
    std::vector<float> xs = {0.f, -0.f, std::numeric_limits<float>::denorm_min(), -std::numeric_limits<float>::denorm_min(),
                             std::numeric_limits<float>::min(), -std::numeric_limits<float>::min(),
                             std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(), inf, -inf, 1.f, -1.f};
    Rng rng(9, 0);
    for (int i = 0; i < 100000; ++i) {
        const uint32_t b = rng.next_u32();
        float x;
        std::memcpy(&x, &b, sizeof b);
        if (!std::isnan(x)) xs.push_back(x);
    }
    auto bits = [](float v) {
        uint32_t b;
        std::memcpy(&b, &v, sizeof b);
        return b;
    };
    for (float x : xs) {
        ASSERT_EQ(bits(next_float_up(x)), bits(std::nextafter(x, inf))) << x;
        ASSERT_EQ(bits(next_float_down(x)), bits(std::nextafter(x, -inf))) << x;
    }
    EXPECT_TRUE(std::isnan(next_float_up(std::numeric_limits<float>::quiet_NaN())));
    EXPECT_TRUE(std::isnan(next_float_down(std::numeric_limits<float>::quiet_NaN())));
}

TEST(RayOffset, ShadowRaysReachTheirTarget) {
    Rng rng(3, 2);
    for (double place : {0.0, 1e4, 1e5}) {
        std::vector<float> v;
        for (double z : {0.0, 1.0})
            for (auto xy : {std::pair{-1.0, -1.0}, std::pair{1.0, -1.0}, std::pair{0.0, 1.0}}) {
                v.push_back(float(place + xy.first));
                v.push_back(float(place + xy.second));
                v.push_back(float(place + z));
            }
        Fixture f(v, {0, 1, 2, 3, 5, 4}, Vec3f(float(place), float(place), float(place - 5)),
                  Vec3f(float(place), float(place), float(place)));
        auto scene = build_scene(f.desc);
        for (int i = 0; i < 2000; ++i) {
            const float a1 = rng.next_float(), a2 = rng.next_float() * (1.f - a1);
            const float c1 = rng.next_float(), c2 = rng.next_float() * (1.f - c1);
            const SurfacePoint p = scene->surface_point(0, 0, a1, a2), q = scene->surface_point(0, 1, c1, c2);
            ASSERT_FALSE(scene->occluded(spawn_ray_to(p.p, p.p_error, p.ng, q.p, q.p_error, q.ng)))
                << "place " << place << " sample " << i;
        }
    }
}

TEST(Robust, DegenerateTrianglesAreSkippedNotRefused) {
    // Triangle 0 real; 1 has coincident vertices; 2 three collinear ones; 3 a sliver of angle
    // 3e-8 (its far vertex one float off the line of the others).
    Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0, -0.5f, 0.5f, -1, 0.5f, 0.5f, -1, 0, 0.5f, -1, 1.5f, 0.50000006f, -1},
              {0, 1, 2, 3, 4, 4, 3, 5, 4, 3, 4, 6});
    auto scene = build_scene(f.desc);
    EXPECT_EQ(degenerate_triangles(*scene, 0), 3);
    EXPECT_EQ(scene->edges().size(), 3u);
    for (const Edge& e : scene->edges()) EXPECT_EQ(e.f0, 0) << "an edge of a degenerate face";
    // The camera ray through the centre passes through triangle 2's line and hits triangle 0.
    Hit hit;
    Ray r;
    r.origin = Vec3f(0.f, 0.5f, -5.f);
    r.dir = Vec3f(0.f, 0.f, 1.f);
    ASSERT_TRUE(scene->intersect(r, hit));
    EXPECT_EQ(hit.prim, 0);
}

TEST(Robust, RangesAreCheckedWhenTheSceneIsBuilt) {
    {
        Fixture f({-1, -1, 0, 1, -1, 0, 0, 1e17f, 0}, {0, 1, 2});
        EXPECT_NE(build_error(f.desc).find("meshes[0].vertices: value 1e+17 of vertex 2 is out of range"),
                  std::string::npos)
            << build_error(f.desc);
    }
    {
        // A scene less than kMinExtent across (2e-11); one with every vertex at one point builds.
        Fixture f({-1e-11f, -1e-11f, 0, 1e-11f, -1e-11f, 0, 0, 1e-11f, 0}, {0, 1, 2});
        EXPECT_NE(build_error(f.desc).find("meshes: the vertices span 2e-11 units"), std::string::npos)
            << build_error(f.desc);
        Fixture point({1e-11f, 0, 0, 1e-11f, 0, 0, 1e-11f, 0, 0}, {0, 1, 2});
        EXPECT_EQ(build_error(point.desc), "");
    }
    {
        Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2}, Vec3f(0, 0, -2e18f));
        EXPECT_NE(build_error(f.desc).find("camera.position"), std::string::npos);
    }
    {
        Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2});
        f.desc.camera.type = CameraType::Orthographic;
        f.desc.camera.ortho_scale = 1e19f;
        EXPECT_NE(build_error(f.desc).find("camera.ortho_scale"), std::string::npos);
    }
    {
        Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2});
        f.desc.camera.crop_x = 2147483647;
        f.desc.camera.crop_width = 2;
        f.desc.camera.crop_height = 2;
        EXPECT_NE(build_error(f.desc).find("camera.crop_window"), std::string::npos);
    }
    {
        Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2});
        std::vector<float> bright{1e38f, 1e38f, 1e38f};
        f.desc.meshes[0].emission = Fixture::tex(bright);
        EXPECT_NE(build_error(f.desc).find("meshes[0].emission: radiance"), std::string::npos);
    }
    {
        Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2});
        std::vector<float> sky(3, 1.f);
        f.desc.has_envmap = true;
        f.desc.envmap.values = Fixture::tex(sky);
        for (float& x : f.desc.envmap.to_world) x = 0.f;
        EXPECT_NE(build_error(f.desc).find("envmap.to_world: is not a rotation"), std::string::npos);
    }
}

TEST(Robust, CancelledCallsStopAndThrow) {
    Fixture f({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2});
    auto scene = build_scene(f.desc);
    std::atomic<bool> cancel{true};
    RenderOptions opt;
    opt.spp = 1 << 30;  // would take hours
    opt.cancel = &cancel;
    std::vector<float> image(8 * 8 * 3), adjoint(8 * 8 * 3, 1.f), grad(9, 0.f);
    EXPECT_THROW(render(*scene, opt, image.data()), Cancelled);
    SceneGradients g;
    g.meshes.resize(1);
    g.meshes[0].vertices.grad = grad.data();
    EXPECT_THROW(render_gradients(*scene, opt, adjoint.data(), g), Cancelled);
    cancel = false;
    opt.spp = 1;
    EXPECT_NO_THROW(render(*scene, opt, image.data()));
}


// The passes' parallel loop: every index once, each started in increasing order; an item that
// throws stops the others from starting new items, and the exception reaches the caller.
TEST(Robust, ParallelIndicesRunEachOnceAndStopAtAnException) {
    RenderOptions opt;
    opt.num_threads = 2;
    const int64_t n = 20000;
    std::vector<std::atomic<int>> runs(static_cast<size_t>(n));
    parallel_indices(opt, n, [&](int64_t i) { runs[size_t(i)].fetch_add(1); });
    for (int64_t i = 0; i < n; ++i) ASSERT_EQ(runs[size_t(i)].load(), 1) << i;
    std::atomic<int64_t> done{0};
    EXPECT_THROW(parallel_indices(opt, n,
                                  [&](int64_t i) {
                                      if (i == 200) throw std::runtime_error("item 200");
                                      std::this_thread::sleep_for(std::chrono::microseconds(50));
                                      done.fetch_add(1);
                                  }),
                 std::runtime_error);
    // (Item 200: by then both threads are in the loop.) The other stops within an item or two
    // of the failure, not after all 20000 at 50 us each.
    EXPECT_LT(done.load(), 400);
}

// The power heuristic where the densities' squares overflow or underflow: a light seen edge-on
// from far away has a density past 1.8e19 (Inf / Inf was a NaN image). The lanes' version
// agrees with the scalar one bit for bit.
TEST(Robust, MisWeightsOfHugeAndTinyDensities) {
    const float inf = std::numeric_limits<float>::infinity(), nan = std::nanf("");
    EXPECT_EQ(mis_power(inf, 1.f), 1.f);
    EXPECT_EQ(mis_power(1.f, inf), 0.f);
    EXPECT_EQ(mis_power(inf, inf), 0.5f);
    EXPECT_EQ(mis_power(1e20f, 1e20f), 0.5f);
    EXPECT_FLOAT_EQ(mis_power(3e19f, 1e19f), 0.9f);
    EXPECT_FLOAT_EQ(mis_power(1e19f, 3e19f), 0.1f);
    EXPECT_EQ(mis_power(1e-25f, 1e-25f), 0.5f);
    EXPECT_FLOAT_EQ(mis_power(2e-25f, 1e-25f), 0.8f);
    EXPECT_EQ(mis_power(0.f, 1.f), 0.f);
    EXPECT_EQ(mis_power(nan, 1.f), 0.f);
    EXPECT_EQ(mis_power(0.3f, 0.7f), 0.09f / (0.09f + 0.7f * 0.7f));
    const float a[8] = {inf, 1.f, 3e19f, 1e-25f, 0.3f, 0.f, 2e-25f, 1e20f};
    const float b[8] = {1.f, inf, 1e19f, 1e-25f, 0.7f, 1.f, 1e-25f, 1e20f};
    for (int k = 0; k < 8; k += 4) {
        alignas(16) float w[4];
        lanes::mis_power_lanes(F4::loadu(a + k), F4::loadu(b + k)).store(w);
        for (int i = 0; i < 4; ++i) {
            const float s = mis_power(a[k + i], b[k + i]);
            EXPECT_EQ(std::memcmp(&w[i], &s, sizeof s), 0) << a[k + i] << ", " << b[k + i] << ": " << w[i] << " != " << s;
        }
    }
}

// Twice a triangle's area, its normal, where a ray meets it and the normal's adjoint, for
// triangles of any float size: the squared length of a cross product of two edges overflows
// float past about 4e9 units and underflows below about 3e-10; the re-solved hit's triple
// product overflows past about 7e12. Against double, and the adjoint against the same triangle
// at scale 1 (normalize(cross) does not change with the scale; its adjoint scales as 1/s^2).
TEST(Robust, TriangleGeometryOfHugeAndTinyTriangles) {
    const Vec3d e1d(1.0, 0.2, 0.0), e2d(0.3, 2.0, 0.5);
    const Vec3f dn(0.3f, -0.5f, 0.8f);
    const Vec3f d1 = d_cross_normal(Vec3f(e1d), Vec3f(e2d), dn);
    for (double s : {1e-12, 1.0, 1e6, 1e10, 1e14}) {
        const Vec3f e1(e1d * s), e2(e2d * s);
        const Vec3d c = cross(Vec3d(e1), Vec3d(e2));
        EXPECT_NEAR(cross_length(e1, e2) / length(c), 1.0, 1e-6) << s;
        const Vec3f n = cross_normal(e1, e2);
        EXPECT_NEAR(length(Vec3d(n) - c / length(c)), 0.0, 1e-6) << s;
        const Vec3f dc = d_cross_normal(e1, e2, dn) * float(s * s);
        EXPECT_NEAR(length(Vec3d(dc) - Vec3d(d1)) / length(Vec3d(d1)), 0.0, 1e-5) << s;
        // A ray from s (0.1, 0.1, 0) towards a triangle at z = 5 s.
        const Vec3d v0d(-1, -1, 5), v1d(2, -1, 5.5), v2d(0, 2, 4.5), od(0.1, 0.1, 0);
        const Vec3f dir = normalize(Vec3f(0.05f, 0.1f, 1.f));
        TriangleHit<float> h;
        TriangleHit<double> hd;
        ASSERT_TRUE(intersect_triangle(Vec3f(od * s), dir, Vec3f(v0d * s), Vec3f(v1d * s), Vec3f(v2d * s), h)) << s;
        ASSERT_TRUE(intersect_triangle(Vec3d(Vec3f(od * s)), Vec3d(dir), Vec3d(Vec3f(v0d * s)), Vec3d(Vec3f(v1d * s)),
                                       Vec3d(Vec3f(v2d * s)), hd));
        EXPECT_NEAR(h.t / hd.t, 1.0, 1e-5) << s;
        EXPECT_NEAR(h.b1, hd.b1, 1e-5) << s;
        EXPECT_NEAR(h.b2, hd.b2, 1e-5) << s;
    }
}

// Embree zeroes the barycentrics of hits where twice the triangle's area seen across the ray is
// below 1e-18 (edges below about 5e-10 units): every hit, from single rays and from packets,
// fast or exact, gets its own (a tiny scene's paths all left from a corner, and its gradients
// were up to 3.7 times off).
TEST(Robust, HitsOnTinyTrianglesKeepTheirBarycentrics) {
    const Vec3d v0(-1, -1, 0), v1(1, -1, 0.2), v2(0, 1, -0.1), o(0.3, 0.2, -5);
    const Vec3d aims[3] = {Vec3d(0.2, 0.1, 0), Vec3d(-0.4, -0.6, 0), Vec3d(0.5, -0.8, 0)};
    for (double s : {6e-11, 2e-10, 1e-9, 1.0, 1e6}) {  // the least extent, 1e-10: 1.2e-10 across
        std::vector<float> v;
        for (const Vec3d& x : {v0, v1, v2})
            for (int k = 0; k < 3; ++k) v.push_back(float(x[k] * s));
        Fixture f(v, {0, 1, 2}, Vec3f(o * s), Vec3f(0.f));
        auto scene = build_scene(f.desc);
        Ray rays[3];
        for (int i = 0; i < 3; ++i) {
            rays[i].origin = Vec3f(o * s);
            rays[i].dir = normalize(Vec3f(aims[i] - o));
        }
        for (Tracing tracing : {Tracing::Exact, Tracing::Fast}) {
            FirstHit packet[3];
            intersect_packet(*scene, tracing, rays, 3, packet);
            for (int i = 0; i < 3; ++i) {
                TriangleHit<double> want;
                ASSERT_TRUE(intersect_triangle(Vec3d(rays[i].origin), Vec3d(rays[i].dir), Vec3d(Vec3f(v0 * s)),
                                               Vec3d(Vec3f(v1 * s)), Vec3d(Vec3f(v2 * s)), want));
                Hit single;
                ASSERT_TRUE(scene->intersect(rays[i], single, tracing)) << s;
                ASSERT_TRUE(packet[i].found) << s;
                for (const Hit& h : {single, packet[i].hit}) {
                    EXPECT_NEAR(h.b1, want.b1, 1e-5) << "scale " << s << " ray " << i;
                    EXPECT_NEAR(h.b2, want.b2, 1e-5) << "scale " << s << " ray " << i;
                    EXPECT_NEAR(h.t / want.t, 1.0, 1e-5) << "scale " << s << " ray " << i;
                }
            }
        }
    }
}

}  // namespace
}  // namespace edgepath
