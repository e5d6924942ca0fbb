// Closed-form checks of the forward renderer.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>

#include "edgepath.h"
#include "edges/primary.h"
#include "moved_scene.h"
#include "render/packet.h"
#include "render/path.h"
#include "render/shade_lanes.h"
#include "render/tiles.h"
#include "scene/gradients.h"
#include "scene/plastic.h"
#include "scene/scene.h"
#include "support/shapes.h"

namespace edgepath {
namespace {

struct ConstTex {
    std::vector<float> v;
    explicit ConstTex(std::vector<float> x) : v(std::move(x)) {}
    TextureDesc desc() const {
        TextureDesc t;
        t.data = v.data();
        t.height = 1;
        t.width = 1;
        t.channels = int(v.size());
        return t;
    }
};

MaterialDesc material(const ConstTex& kd, const ConstTex& ks, const ConstTex& r) {
    MaterialDesc m;
    m.diffuse = kd.desc();
    m.specular = ks.desc();
    m.roughness = r.desc();
    return m;
}

CameraDesc camera(Vec3f pos, Vec3f target, int w, int h, float fov) {
    CameraDesc c;
    for (int k = 0; k < 3; ++k) {
        c.position[k] = pos[k];
        c.look_at[k] = target[k];
    }
    c.up[0] = 0;
    c.up[1] = 1;
    c.up[2] = 0;
    c.width = w;
    c.height = h;
    c.fov = fov;
    return c;
}

// Per-pixel mean and standard error from `runs` independent renders.
struct Stats {
    std::vector<double> mean, stderr_;
};
Stats render_stats(const Scene& s, RenderOptions opt, int runs) {
    size_t n = size_t(image_width(s)) * image_height(s) * 3;
    std::vector<double> sum(n, 0), sum2(n, 0);
    std::vector<float> img(n);
    for (int r = 0; r < runs; ++r) {
        opt.seed = 1000 + r;
        render(s, opt, img.data());
        for (size_t i = 0; i < n; ++i) {
            sum[i] += img[i];
            sum2[i] += double(img[i]) * img[i];
        }
    }
    Stats st;
    st.mean.resize(n);
    st.stderr_.resize(n);
    for (size_t i = 0; i < n; ++i) {
        st.mean[i] = sum[i] / runs;
        double var = std::max(0.0, sum2[i] / runs - st.mean[i] * st.mean[i]) * runs / (runs - 1);
        st.stderr_[i] = std::sqrt(var / runs);
    }
    return st;
}

// The white furnace: a flat-shaded sphere (a convex polyhedron: it never sees itself) of albedo
// 0.6 under a uniform environment of radiance 1, seen from (0, 0, 4) on a 32 x 32 film.
struct WhiteFurnace {
    MeshData sphere = make_sphere(Vec3f(0, 0, 0), 1.f, 24, 48);
    ConstTex kd{{0.6f, 0.6f, 0.6f}}, ks{{0, 0, 0}}, rough{{0.5f}}, env{{1, 1, 1}};
    std::shared_ptr<Scene> scene;
    // Pixels whose whole footprint lies on the sphere are those within this distance of the
    // film's centre, less a pixel and a half: the projected radius is tan(asin(1/4)) / tan(20
    // deg) of the half width.
    const double radius = std::tan(std::asin(0.25)) / std::tan(20.0 * M_PI / 180.0) * 16.0;
    WhiteFurnace() {
        sphere.normals.clear();
        SceneDesc d;
        d.camera = camera(Vec3f(0, 0, 4), Vec3f(0, 0, 0), 32, 32, 40);
        d.materials.push_back(material(kd, ks, rough));
        d.meshes.push_back(sphere.desc(0));
        d.has_envmap = true;
        d.envmap.values = env.desc();
        scene = build_scene(d);
    }
    WhiteFurnace(const WhiteFurnace&) = delete;  // the scene points into it
    WhiteFurnace& operator=(const WhiteFurnace&) = delete;
    bool inside(int x, int y) const { return std::hypot(x + 0.5 - 16, y + 0.5 - 16) <= radius - 1.5; }
};

// White furnace: a convex object of albedo rho under a uniform environment of radiance 1 has
// radiance rho everywhere, for any max_bounces >= 1.
TEST(Render, WhiteFurnaceFlatSphere) {
    const WhiteFurnace furnace;
    const Scene* scene = furnace.scene.get();
    for (int bounces : {1, 3}) {
        RenderOptions opt;
        opt.spp = 8;
        opt.max_bounces = bounces;
        // 32 independent runs: the per-pixel standard error is itself estimated from them, and
        // with few runs its own error makes 5-sigma outliers common over hundreds of pixels.
        Stats st = render_stats(*scene, opt, 32);
        int tested = 0;
        for (int y = 0; y < 32; ++y)
            for (int x = 0; x < 32; ++x) {
                if (!furnace.inside(x, y)) continue;
                for (int c = 0; c < 3; ++c) {
                    size_t i = (size_t(y) * 32 + x) * 3 + c;
                    EXPECT_NEAR(st.mean[i], 0.6, 5 * st.stderr_[i] + 1e-4) << "pixel " << x << "," << y;
                }
                ++tested;
            }
        EXPECT_GT(tested, 100);
    }
}


// A constant sky is left to the BSDF's samples when the strategies are combined, in an image no
// gradient pass retraces (env_nee in render/path.h): on the white furnace's convex sphere each
// such sample escapes with the weight rho exactly, so every sample of a pixel inside the outline
// is rho, with no shadow ray traced, where a light sample of the sky (uniform over the sphere,
// half of it below the surface) mixed by MIS scatters them. Light-only sampling still samples
// the sky (without it that strategy would see nothing), and so do replayable images.
TEST(Render, ConstantSkyIsLeftToTheBsdfSamples) {
    const WhiteFurnace furnace;
    const Scene* scene = furnace.scene.get();
    for (bool mis : {true, false}) {
        RenderOptions opt;
        opt.spp = 4;
        opt.max_bounces = 2;
        opt.sampling = mis ? LightSampling::MIS : LightSampling::LightOnly;
        opt.replayable = false;
        std::vector<float> img(32 * 32 * 3);
        const RenderStats stats = render(*scene, opt, img.data());
        if (mis) {
            EXPECT_EQ(stats.shadow_rays, 0u);
        } else {
            EXPECT_GT(stats.shadow_rays, 400u);  // about one a vertex (none for the lower half of the sky's samples)
        }
        double worst = 0, sum = 0;
        int tested = 0;
        for (int y = 0; y < 32; ++y)
            for (int x = 0; x < 32; ++x) {
                if (!furnace.inside(x, y)) continue;
                for (int c = 0; c < 3; ++c) {
                    const double v = img[(size_t(y) * 32 + x) * 3 + c];
                    worst = std::max(worst, std::abs(v - 0.6));
                    sum += v;
                }
                ++tested;
            }
        ASSERT_GT(tested, 100);
        if (mis) {
            EXPECT_LT(worst, 1e-5);
        } else {  // noisy, but right on average
            EXPECT_GT(worst, 1e-2);
            EXPECT_NEAR(sum / (3 * tested), 0.6, 0.02);
        }
    }
    // The paths recorded for the adjoint sweep keep the sky's light sample (env_nee), and so
    // does an image they may retrace: the same camera ray traced with and without a record, and
    // an image with the default options.
    RenderOptions opt;
    opt.max_bounces = 1;
    std::vector<float> img(32 * 32 * 3);
    EXPECT_GT(render(*scene, opt, img.data()).shadow_rays, 400u);
    opt.replayable = false;
    int sampled = 0;
    for (uint64_t s = 0; s < 64; ++s) {
        const Ray ray = scene->camera.generate_ray(16.f, 16.f);
        RayCounters plain, recorded;
        Rng rng = Rng::for_sample(1, 0, s), rng2 = rng;
        trace_path(*scene, opt, ray, rng, plain);
        PathRecord rec;
        trace_path(*scene, opt, ray, rng2, recorded, &rec);
        EXPECT_EQ(plain.shadow, 0u);
        ASSERT_EQ(rec.vertices.size(), 1u);
        EXPECT_EQ(recorded.shadow, rec.vertices[0].nee_env.used ? 1u : 0u);
        sampled += rec.vertices[0].nee_env.used;
    }
    EXPECT_GT(sampled, 16);  // about half: the sky's samples above the surface
}

// Projects a world point to full-film pixel coordinates (perspective camera of scene/camera.h).
Vec2f project(const Camera& c, const Vec3f& p) {
    Vec3f d = p - c.position;
    float z = dot(d, c.forward);
    float sx = dot(d, c.right) / z, sy = dot(d, c.up) / z;
    float px = (sx / c.tx + 1.f) * 0.5f * float(c.width);
    float py = (1.f - sy / (c.tx * float(c.height) / float(c.width))) * 0.5f * float(c.height);
    return {px, py};
}

// Area (in pixels) of the part of a convex polygon inside the film rectangle.
double clipped_area(std::vector<Vec2d> poly, double W, double H) {
    auto clip = [](const std::vector<Vec2d>& in, int axis, double bound, bool keep_less) {
        std::vector<Vec2d> out;
        for (size_t i = 0; i < in.size(); ++i) {
            Vec2d a = in[i], b = in[(i + 1) % in.size()];
            auto inside = [&](const Vec2d& p) { return keep_less ? p[axis] <= bound : p[axis] >= bound; };
            if (inside(a)) out.push_back(a);
            if (inside(a) != inside(b)) {
                double t = (bound - a[axis]) / (b[axis] - a[axis]);
                out.push_back(Vec2d(a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)));
            }
        }
        return out;
    };
    poly = clip(poly, 0, 0, false);
    poly = clip(poly, 0, W, true);
    poly = clip(poly, 1, 0, false);
    poly = clip(poly, 1, H, true);
    double a = 0;
    for (size_t i = 0; i < poly.size(); ++i) {
        const Vec2d &p = poly[i], &q = poly[(i + 1) % poly.size()];
        a += p.x * q.y - q.x * p.y;
    }
    return std::abs(a) * 0.5;
}

// An emissive triangle over black seen directly: the image sum is its projected area (in
// pixels) times its radiance, also when part of it lies outside the image.
TEST(Render, EmissiveTriangleProjectedArea) {
    const std::vector<std::vector<float>> tris = {
        {-1.7f, 1.f, 0.f, 1.f, 1.f, 0.f, -0.5f, -1.f, 0.f},    // the classic test triangle
        {-3.5f, 0.5f, 1.f, 0.5f, 2.5f, 0.f, 0.2f, -0.4f, -1.f}, // partly outside the image
    };
    for (const auto& v : tris) {
        MeshData m;
        m.vertices = v;
        m.indices = {0, 1, 2};
        ConstTex kd({0, 0, 0}), ks({0, 0, 0}), rough({0.5f}), le({2.f, 1.f, 0.5f});
        SceneDesc d;
        d.camera = camera(Vec3f(0, 0, -5), Vec3f(0, 0, 0), 64, 48, 45);
        d.materials.push_back(material(kd, ks, rough));
        d.meshes.push_back(m.desc(0));
        d.meshes[0].emission = le.desc();
        d.meshes[0].two_sided_emission = true;
        auto scene = build_scene(d);
        std::vector<Vec2d> poly;
        for (int k = 0; k < 3; ++k) {
            Vec2f p = project(scene->camera, Vec3f(v[3 * k], v[3 * k + 1], v[3 * k + 2]));
            poly.push_back(Vec2d(p.x, p.y));
        }
        double area = clipped_area(poly, 64, 48);
        RenderOptions opt;
        opt.spp = 64;
        opt.max_bounces = 0;
        std::vector<float> img(64 * 48 * 3);
        render(*scene, opt, img.data());
        double sum[3] = {0, 0, 0};
        for (size_t i = 0; i < img.size(); ++i) sum[i % 3] += img[i];
        // Only edge pixels are noisy: each contributes at most its radiance, with binomial noise
        // of a stratum-free estimate; 64 spp bounds the relative error of the sum well below 1%.
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(sum[c], area * le.v[c], 0.01 * area * le.v[c]) << "channel " << c;
    }
}

// Irradiance at p from a polygonal Lambertian emitter of unit radiance (Lambert's formula).
double polygon_irradiance(const Vec3d& p, const Vec3d& n, const std::vector<Vec3d>& poly) {
    double e = 0;
    for (size_t i = 0; i < poly.size(); ++i) {
        Vec3d a = normalize(poly[i] - p), b = normalize(poly[(i + 1) % poly.size()] - p);
        double theta = std::acos(std::clamp(dot(a, b), -1.0, 1.0));
        e += theta * dot(normalize(cross(a, b)), n);
    }
    return std::abs(e) * 0.5;
}

// A diffuse plane lit by one rectangular light: each pixel equals albedo / pi times the analytic
// irradiance, averaged over the pixel's footprint (orthographic camera looking straight down).
TEST(Render, RectangleLightIrradiance) {
    MeshData floor = make_quad(Vec3f(-2, 0, -2), Vec3f(0, 0, 4), Vec3f(4, 0, 0));  // normal +y
    MeshData lamp = make_quad(Vec3f(-0.3f, 1.f, -0.2f), Vec3f(0.7f, 0, 0), Vec3f(0, 0, 0.5f));  // normal -y
    ConstTex kd({0.7f, 0.5f, 0.3f}), black({0, 0, 0}), ks({0, 0, 0}), rough({0.5f}), le({3.f, 3.f, 3.f});
    SceneDesc d;
    d.camera = camera(Vec3f(0, 3, 0), Vec3f(0, 0, 0), 24, 24, 45);
    d.camera.up[1] = 0;
    d.camera.up[2] = 1;
    d.camera.type = CameraType::Orthographic;
    d.camera.ortho_scale = 1.5f;
    d.materials.push_back(material(kd, ks, rough));
    d.materials.push_back(material(black, ks, rough));
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(lamp.desc(1));
    d.meshes[1].emission = le.desc();
    auto scene = build_scene(d);
    std::vector<Vec3d> poly;
    for (int k = 0; k < 4; ++k) poly.push_back(Vec3d(Vec3f::load(lamp.vertices.data() + 3 * k)));
    RenderOptions opt;
    opt.spp = 4;
    opt.max_bounces = 1;
    Stats st = render_stats(*scene, opt, 32);
    const Camera& cam = scene->camera;
    int checked = 0, outliers = 0;
    double zsum = 0;
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) {
            double e = 0;
            const int sub = 6;
            bool under_lamp = false;
            for (int j = 0; j < sub; ++j)
                for (int i = 0; i < sub; ++i) {
                    Ray r = cam.generate_ray(x + (i + 0.5f) / sub, y + (j + 0.5f) / sub);
                    Vec3d p(r.origin.x, 0.0, r.origin.z);
                    if (p.x > -0.35 && p.x < 0.45 && p.z > -0.25 && p.z < 0.35) under_lamp = true;
                    e += polygon_irradiance(p, Vec3d(0, 1, 0), poly);
                }
            e /= sub * sub;
            if (under_lamp) continue;  // the camera sees the lamp's black back there
            for (int c = 0; c < 3; ++c) {
                size_t idx = (size_t(y) * 24 + x) * 3 + c;
                double expect = kd.v[c] / M_PI * le.v[c] * e;
                double z = std::abs(st.mean[idx] - expect) / (st.stderr_[idx] + 1e-6);
                if (z > 4.5) ++outliers;
                zsum += (st.mean[idx] - expect) / (st.stderr_[idx] + 1e-6);
                ++checked;
            }
        }
    // With ~1600 values and 32-run error estimates (t with 31 degrees of freedom), a correct
    // renderer exceeds 4.5 standard errors about 0.1 times; a bias shows up in the mean z-score
    // (standard deviation 1/sqrt(checked) without bias; neighbouring channels are correlated, so
    // allow 6 of those).
    EXPECT_LE(outliers, 3) << "of " << checked;
    EXPECT_LT(std::abs(zsum / checked), 6.0 / std::sqrt(double(checked)));
}

// Light sampling alone, BSDF sampling alone and their MIS combination estimate the same image:
// compared per pixel and over the whole image with bounds from the sample variance.
TEST(Render, SamplingStrategiesAgree) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0.2f, -0.3f, 0.3f), 0.7f, 12, 24);
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.5f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    ConstTex kd({0.6f, 0.6f, 0.5f}), ks_floor({0.2f, 0.2f, 0.2f}), r_floor({0.3f});
    ConstTex kd_ball({0.2f, 0.3f, 0.6f}), ks_ball({0.5f, 0.5f, 0.5f}), r_ball({0.25f});
    ConstTex black({0, 0, 0}), le({4.f, 4.f, 4.f}), r_any({0.5f});
    const int EW = 16, EH = 8;
    std::vector<float> env(EW * EH * 3);
    for (int j = 0; j < EH; ++j)
        for (int i = 0; i < EW; ++i)
            for (int c = 0; c < 3; ++c) env[(j * EW + i) * 3 + c] = 0.2f + 0.1f * c + (j < 3 ? 0.5f : 0.f) + (i == 3 ? 1.f : 0.f);
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.5f, 5), Vec3f(0, -0.3f, 0), 32, 24, 50);
    d.materials.push_back(material(kd, ks_floor, r_floor));
    d.materials.push_back(material(kd_ball, ks_ball, r_ball));
    d.materials.push_back(material(black, black, r_any));
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(ball.desc(1));
    d.meshes.push_back(lamp.desc(2));
    d.meshes[2].emission = le.desc();
    d.meshes[2].two_sided_emission = true;
    d.has_envmap = true;
    d.envmap.values.data = env.data();
    d.envmap.values.height = EH;
    d.envmap.values.width = EW;
    d.envmap.values.channels = 3;
    auto scene = build_scene(d);
    RenderOptions opt;
    opt.spp = 8;
    opt.max_bounces = 2;
    std::vector<Stats> st;
    for (LightSampling mode : {LightSampling::MIS, LightSampling::LightOnly, LightSampling::BSDFOnly}) {
        opt.sampling = mode;
        st.push_back(render_stats(*scene, opt, 24));
    }
    for (int b = 1; b < 3; ++b) {
        const Stats &x = st[0], &y = st[b];
        size_t n = x.mean.size();
        int outliers = 0;
        double diff[3] = {0, 0, 0}, var[3] = {0, 0, 0};
        for (size_t i = 0; i < n; ++i) {
            double se2 = x.stderr_[i] * x.stderr_[i] + y.stderr_[i] * y.stderr_[i];
            double dlt = x.mean[i] - y.mean[i];
            if (std::abs(dlt) > 5.0 * std::sqrt(se2) + 1e-6) ++outliers;
            diff[i % 3] += dlt;
            var[i % 3] += se2;
        }
        EXPECT_LE(outliers, int(n / 200)) << "strategy " << b;
        for (int c = 0; c < 3; ++c)
            EXPECT_LT(std::abs(diff[c]), 5.0 * std::sqrt(var[c])) << "strategy " << b << " channel " << c;
    }
}

// A sphere over a floor under a small lamp, described at a film size (the description points
// into these meshes and textures).
struct BallOverFloor {
    MeshData ball = make_sphere(Vec3f(0, 0, 0), 1.f, 16, 32);
    MeshData floor = make_quad(Vec3f(-3, -1, 3), Vec3f(6, 0, 0), Vec3f(0, 0, -6));
    MeshData lamp = make_quad(Vec3f(-0.5f, 3, -0.5f), Vec3f(1, 0, 0), Vec3f(0, 0, 1));
    ConstTex kd{{0.6f, 0.5f, 0.4f}}, ks{{0.1f, 0.1f, 0.1f}}, rough{{0.3f}}, black{{0, 0, 0}}, light{{5, 5, 5}};
    SceneDesc desc(int width, int height) const {
        SceneDesc d;
        d.camera = camera(Vec3f(0.5f, 1.f, 4.f), Vec3f(0, 0, 0), width, height, 45);
        d.materials = {material(kd, ks, rough), material(black, black, rough)};
        d.meshes = {ball.desc(0), floor.desc(0), lamp.desc(1)};
        d.meshes[2].emission = light.desc();
        return d;
    }
};

// A mesh whose vertices are known to move (MeshDesc::moves): the scene is built in the form of
// a scene whose vertices have moved, so the first move refits the BVH and the edge hierarchy
// (without the hint it rebuilds both), and the edge list keeps its nearly flat edges from the
// start (the sphere's planar quads' diagonals), as a scene built and then moved does.
TEST(SceneUpdate, MeshesKnownToMoveAreBuiltForRefittingFromTheStart) {
    const BallOverFloor s;
    const MeshData& ball = s.ball;
    SceneDesc d = s.desc(24, 20);
    RenderOptions opt;
    opt.spp = 1;
    opt.num_threads = 1;
    std::vector<float> adjoint(24 * 20 * 3, 1.f), grad(ball.vertices.size());
    SceneGradients slots;
    slots.meshes.resize(3);
    slots.meshes[0].vertices.grad = grad.data();
    for (bool moves : {false, true}) {
        d.meshes[0].moves = moves;
        d.meshes[0].vertices = ball.vertices.data();
        const std::shared_ptr<Scene> scene = build_scene(d);
        render_gradients(*scene, opt, adjoint.data(), slots);
        size_t flat = 0;
        for (const Edge& e : scene->edges()) flat += e.flat;
        EXPECT_EQ(flat > 0, moves);
        std::vector<float> moved(ball.vertices);
        for (float& x : moved) x *= 1.5f;
        d.meshes[0].vertices = moved.data();
        update_scene(*scene, d);
        render_gradients(*scene, opt, adjoint.data(), slots);
        const SceneBuildCounts bvh = scene_build_counts(*scene), tree = scene_hierarchy_counts(*scene);
        EXPECT_EQ(bvh.builds, moves ? 1u : 2u) << moves;
        EXPECT_EQ(bvh.refits, moves ? 1u : 0u) << moves;
        EXPECT_EQ(tree.builds, moves ? 1u : 2u) << moves;
        EXPECT_EQ(tree.refits, moves ? 1u : 0u) << moves;
    }
}

// Gradient passes on one scene from several threads at once (the scene is documented as safe
// for that): each equals the pass made alone, bit for bit, and they share the kept edge
// hierarchy (reused by each, never rebuilt nor refit).
TEST(SceneUpdate, ConcurrentGradientPassesShareTheKeptHierarchy) {
    const BallOverFloor s;
    const MeshData& ball = s.ball;
    const std::shared_ptr<Scene> scene = build_scene(s.desc(24, 20));
    RenderOptions opt;
    opt.spp = 2;
    opt.num_threads = 1;
    const std::vector<float> adjoint(24 * 20 * 3, 1.f);
    auto pass = [&](std::vector<float>& grad) {
        grad.assign(ball.vertices.size(), 0.f);
        SceneGradients slots;
        slots.meshes.resize(3);
        slots.meshes[0].vertices.grad = grad.data();
        render_gradients(*scene, opt, adjoint.data(), slots);
    };
    std::vector<float> alone;
    pass(alone);
    ASSERT_GT(std::abs(alone[0]) + std::abs(alone[3]) + std::abs(alone[300]), 0.f);
    constexpr int kThreads = 4;
    std::vector<std::vector<float>> grads(kThreads);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) threads.emplace_back([&, t] { pass(grads[size_t(t)]); });
    for (std::thread& t : threads) t.join();
    for (int t = 0; t < kThreads; ++t) EXPECT_EQ(grads[size_t(t)], alone) << "thread " << t;
    const SceneBuildCounts tree = scene_hierarchy_counts(*scene);
    EXPECT_EQ(tree.builds, 1u);
    EXPECT_EQ(tree.refits, 0u);
    EXPECT_EQ(tree.reuses, uint64_t(kThreads));
}

// The two BVHs (scene.h, Tracing): each built on its first use, the fast one by images no
// gradient follows, the exact one by the rest; the gradient passes trace the exact one whatever
// the options say; and the two give the same image but for the last bits of the intersections.
TEST(SceneUpdate, EachKindOfTracingBuildsItsBvhOnFirstUse) {
    BallOverFloor s;  // (its ball is moved below)
    MeshData& ball = s.ball;
    const SceneDesc d = s.desc(48, 40);
    const std::shared_ptr<Scene> scene = build_scene(d);
    EXPECT_FALSE(scene->has_bvh(Tracing::Exact));
    EXPECT_FALSE(scene->has_bvh(Tracing::Fast));
    RenderOptions opt;
    opt.spp = 4;
    opt.max_bounces = 2;
    opt.num_threads = 1;
    opt.replayable = false;
    const size_t n = 48 * 40 * 3;
    std::vector<float> fast(n), exact(n);
    render(*scene, opt, fast.data());
    EXPECT_TRUE(scene->has_bvh(Tracing::Fast));
    EXPECT_FALSE(scene->has_bvh(Tracing::Exact));
    EXPECT_EQ(scene_build_counts(*scene).builds, 1u);
    opt.replayable = true;
    render(*scene, opt, exact.data());
    EXPECT_TRUE(scene->has_bvh(Tracing::Exact));
    EXPECT_EQ(scene_build_counts(*scene).builds, 2u);
    // The same paths, but for the last bits of each hit (the two intersection tests round
    // differently): nearly every value within 1e-4 of the other (all of them, when this was
    // written), the means within 1e-6 (5e-8).
    double sum_fast = 0, sum_exact = 0;
    int far = 0;
    for (size_t i = 0; i < n; ++i) {
        sum_fast += fast[i];
        sum_exact += exact[i];
        far += std::abs(fast[i] - exact[i]) > 1e-4f * (1.f + std::abs(exact[i]));
    }
    EXPECT_GT(sum_exact, 0.0);
    EXPECT_LT(std::abs(sum_fast - sum_exact), 1e-6 * sum_exact);
    EXPECT_LE(far, int(n / 1000));
    // A gradient pass asked for replayable false traces the exact BVH all the same, and gives
    // the gradients it gives with replayable true, bit for bit.
    const std::shared_ptr<Scene> other = build_scene(d);
    std::vector<float> adjoint(n, 1.f), ga(ball.vertices.size(), 0.f), gb(ga);
    SceneGradients g;
    g.meshes.resize(3);
    g.meshes[0].vertices.grad = ga.data();
    render_gradients(*scene, opt, adjoint.data(), g);
    opt.replayable = false;
    g.meshes[0].vertices.grad = gb.data();
    render_gradients(*other, opt, adjoint.data(), g);
    EXPECT_EQ(ga, gb);
    EXPECT_TRUE(other->has_bvh(Tracing::Exact));
    EXPECT_FALSE(other->has_bvh(Tracing::Fast));
    double total = 0;
    for (float v : ga) total += std::abs(v);
    EXPECT_GT(total, 0.0);

    // Vertices moved: the first time both are dropped (a refittable build follows on use);
    // then each held one is refitted on its next use, not by the update: one only an
    // occasional call traces is not refitted at every move.
    auto move = [&] {
        for (size_t i = 1; i < ball.vertices.size(); i += 3) ball.vertices[i] += 0.01f;
        return update_scene(*scene, d);
    };
    EXPECT_EQ(move(), SceneUpdate::Built);
    EXPECT_FALSE(scene->has_bvh(Tracing::Exact));
    opt.replayable = false;
    render(*scene, opt, fast.data());
    render_gradients(*scene, opt, adjoint.data(), g);
    EXPECT_EQ(scene_build_counts(*scene).builds, 4u);
    for (int round = 0; round < 3; ++round) EXPECT_EQ(move(), SceneUpdate::Refit);
    EXPECT_TRUE(scene->has_bvh(Tracing::Exact) && scene->has_bvh(Tracing::Fast));
    EXPECT_EQ(scene_build_counts(*scene).refits, 0u);
    render(*scene, opt, fast.data());
    EXPECT_EQ(scene_build_counts(*scene).refits, 1u);
    render_gradients(*scene, opt, adjoint.data(), g);
    EXPECT_EQ(scene_build_counts(*scene).refits, 2u);
    EXPECT_EQ(scene_build_counts(*scene).builds, 4u);
    // Refitted to the last positions: the image of a scene built afresh there in the moving
    // form (built at other positions, then updated), bit for bit.
    const std::shared_ptr<Scene> fresh = build_moved(d);
    render(*fresh, opt, exact.data());
    EXPECT_EQ(fast, exact);
}

// A scene updated across calls (update_scene) renders and differentiates exactly as one built
// afresh from the same description, and rebuilds only what changed.
TEST(SceneUpdate, EqualsAFreshBuildAndRebuildsOnlyWhatChanged) {
    MeshData ball = make_sphere(Vec3f(0, 0, 0), 1.f, 8, 16);
    MeshData floor = make_quad(Vec3f(-3, -1, 3), Vec3f(6, 0, 0), Vec3f(0, 0, -6));
    MeshData lamp = make_quad(Vec3f(-0.5f, 3, -0.5f), Vec3f(1, 0, 0), Vec3f(0, 0, 1));
    ConstTex kd({0.6f, 0.5f, 0.4f}), ks({0.1f, 0.1f, 0.1f}), rough({0.3f}), black({0, 0, 0}), light({5, 5, 5});
    auto describe = [&](const ConstTex& diffuse) {
        SceneDesc d;
        d.camera = camera(Vec3f(0.5f, 1.f, 4.f), Vec3f(0, 0, 0), 16, 12, 45);
        d.materials = {material(diffuse, ks, rough), material(black, black, rough)};
        d.meshes = {ball.desc(0), floor.desc(0), lamp.desc(1)};
        d.meshes[2].emission = light.desc();
        return d;
    };
    RenderOptions opt;
    opt.spp = 2;
    opt.num_threads = 1;
    const size_t pixels = 16 * 12 * 3;
    // A fresh build of `d`; `moved`: in the form of a scene whose vertices have moved (its edge
    // list keeps the nearly flat edges, scene/edges.h): built at other positions, then updated
    // to d's.
    auto fresh_build = [&](const SceneDesc& d, bool moved) {
        if (!moved) return build_scene(d);
        SceneUpdate done;
        const auto s = build_moved(d, &done);
        EXPECT_EQ(done, SceneUpdate::Built);
        return s;
    };
    // Image and vertex gradients of `scene`, against a fresh build of `d` (of the form of a scene
    // whose vertices moved, once the scene's have: `moved`). The edge hierarchy is kept too, and
    // refit when only vertices move: a tree with the splits of the positions it was built at
    // (tests/cpp/test_hierarchy.cpp checks its bounds), which a fresh build need not share. So
    // the gradients are also compared with `twin`, a scene that went through the same updates
    // and gradient passes; with the fresh build only where the kept hierarchy was built afresh
    // too (`refit`: false).
    std::shared_ptr<Scene> twin;
    bool moved = false;
    auto expect_fresh = [&](const Scene& scene, const SceneDesc& d, bool refit = false) {
        // The kept triangle data (Mesh::triangle_data, what surface points read) are those of
        // the vertices the description's index arrays name now.
        ASSERT_EQ(scene.meshes.size(), d.meshes.size());
        for (size_t m = 0; m < d.meshes.size(); ++m)
            for (int64_t t = 0; t < d.meshes[m].num_triangles; ++t) {
                const TriangleData& td = scene.meshes[m].triangle_data[t];
                const int32_t* tri = d.meshes[m].indices + 3 * t;
                const Vec3f v0 = Vec3f::load(d.meshes[m].vertices + 3 * int64_t(tri[0]));
                const Vec3f v1 = Vec3f::load(d.meshes[m].vertices + 3 * int64_t(tri[1]));
                const Vec3f v2 = Vec3f::load(d.meshes[m].vertices + 3 * int64_t(tri[2]));
                const Vec3f ng = normalize(cross(v1 - v0, v2 - v0));
                for (int c = 0; c < 3; ++c) {
                    ASSERT_EQ(td.v0[c], v0[c]) << "mesh " << m << ", triangle " << t;
                    ASSERT_EQ(td.v1[c], v1[c]) << "mesh " << m << ", triangle " << t;
                    ASSERT_EQ(td.v2[c], v2[c]) << "mesh " << m << ", triangle " << t;
                    ASSERT_EQ(td.ng[c], ng[c]) << "mesh " << m << ", triangle " << t;
                }
                ASSERT_EQ(td.largest_edge, triangle_largest_edge(v0, v1, v2)) << "mesh " << m << ", triangle " << t;
            }
        std::vector<float> a(pixels), b(pixels), adjoint(pixels);
        for (size_t i = 0; i < pixels; ++i) adjoint[i] = float(i % 7) - 3.f;
        render(scene, opt, a.data());
        const auto fresh = fresh_build(d, moved);
        render(*fresh, opt, b.data());
        EXPECT_EQ(a, b);
        // The image alone, which traces the other BVH (scene.h, Tracing), kept, refitted and
        // rebuilt alike.
        RenderOptions alone = opt;
        alone.replayable = false;
        render(scene, alone, a.data());
        render(*fresh, alone, b.data());
        EXPECT_EQ(a, b);
        std::vector<float> ga(ball.vertices.size(), 0.f), gb(ball.vertices.size(), 0.f), gt(ga);
        SceneGradients g;
        g.meshes.resize(3);
        g.meshes[0].vertices.grad = ga.data();
        render_gradients(scene, opt, adjoint.data(), g);
        g.meshes[0].vertices.grad = gb.data();
        render_gradients(*fresh, opt, adjoint.data(), g);
        g.meshes[0].vertices.grad = gt.data();
        render_gradients(*twin, opt, adjoint.data(), g);
        EXPECT_EQ(ga, gt);
        if (!refit) {
            EXPECT_EQ(ga, gb);
        }
    };
    SceneDesc d = describe(kd);
    const std::shared_ptr<Scene> scene = build_scene(d);
    twin = build_scene(d);
    // update_scene on both.
    auto update = [&](const SceneDesc& d) {
        update_scene(*twin, d);
        return update_scene(*scene, d);
    };
    expect_fresh(*scene, d);
    EXPECT_EQ(update(d), SceneUpdate::Reused);

    ConstTex other({0.2f, 0.7f, 0.3f});  // a material only, in memory of its own
    d = describe(other);
    EXPECT_EQ(update(d), SceneUpdate::Reused);
    expect_fresh(*scene, d);

    d.camera = camera(Vec3f(-1.f, 1.5f, 4.f), Vec3f(0, 0.2f, 0), 16, 12, 40);
    EXPECT_EQ(update(d), SceneUpdate::Reused);
    expect_fresh(*scene, d);

    // Vertices moved in place: the first time a refittable build (and an edge hierarchy over
    // the edge list that keeps the nearly flat edges: equal to a fresh build of that form), then
    // refits.
    moved = true;
    for (SceneUpdate expected : {SceneUpdate::Built, SceneUpdate::Refit, SceneUpdate::Refit}) {
        for (size_t i = 1; i < ball.vertices.size(); i += 3) ball.vertices[i] += 0.05f * ball.vertices[i - 1];
        EXPECT_EQ(update(d), expected);
        expect_fresh(*scene, d, expected != SceneUpdate::Built);
    }
    // Topology: two triangles' winding flipped.
    std::swap(ball.indices[1], ball.indices[2]);
    std::swap(ball.indices[4], ball.indices[5]);
    EXPECT_EQ(update(d), SceneUpdate::Built);
    expect_fresh(*scene, d);
    // A triangle made degenerate: rebuilt (Embree's index buffer changes), then moved back.
    const std::vector<float> before = ball.vertices;
    const int32_t* t = ball.indices.data() + 3 * 20;
    for (int k = 0; k < 3; ++k) ball.vertices[size_t(3 * t[1] + k)] = ball.vertices[size_t(3 * t[0] + k)];
    EXPECT_EQ(update(d), SceneUpdate::Built);
    EXPECT_GT(degenerate_triangles(*scene, 0), 0);
    expect_fresh(*scene, d);
    ball.vertices = before;
    d = describe(other);  // the vector may have moved
    EXPECT_EQ(update(d), SceneUpdate::Built);
    EXPECT_EQ(degenerate_triangles(*scene, 0), 0);
    expect_fresh(*scene, d);
    // A mesh more.
    MeshData box = make_box(Vec3f(1, -1, 0), Vec3f(1.5f, -0.5f, 0.5f));
    d.meshes.push_back(box.desc(0));
    EXPECT_EQ(update(d), SceneUpdate::Built);
    expect_fresh(*scene, d);

    // Six builds of each of the two BVHs, each refitted twice.
    const SceneBuildCounts n = scene_build_counts(*scene);
    EXPECT_EQ(n.builds, 12u);
    EXPECT_EQ(n.refits, 4u);
    EXPECT_EQ(n.reuses, 3u);
    // The edge hierarchy: built on the first gradient pass, rebuilt on the first move (the
    // edge list of a moving scene keeps its nearly flat edges) and refit after the others,
    // rebuilt after each change of the edges (topology, a degenerate triangle, a mesh more);
    // reused when the triangle is moved back (the tree before it, kept in the second slot, at
    // the same positions), and after the material and the camera changed.
    const SceneBuildCounts h = scene_hierarchy_counts(*scene);
    EXPECT_EQ(h.builds, 5u);
    EXPECT_EQ(h.refits, 2u);
    EXPECT_EQ(h.reuses, 3u);
    // A description that fails validation throws and names the field.
    d.meshes[0].material = 7;
    EXPECT_THROW(update_scene(*scene, d), std::invalid_argument);
}

// Camera rays are traced in packets (render/packet.h): each hit is the one a single-ray query
// finds, and the image is, bit for bit, the mean of trace_path over each pixel's samples traced
// one by one with their own streams, whatever the packets' grouping (spp 3: packets straddle
// pixels; 21 x 19 with a crop: tiles and the last packet of a tile are partial) and the thread
// count.
TEST(Render, PacketsMatchSingleRays) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0.2f, -0.3f, 0.3f), 0.7f, 12, 24);
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.5f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    ConstTex kd({0.6f, 0.6f, 0.5f}), ks({0.2f, 0.2f, 0.2f}), r({0.3f}), black({0, 0, 0}), le({4.f, 4.f, 4.f});
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.5f, 5), Vec3f(0, -0.3f, 0), 25, 23, 60);  // sees past the floor too
    d.camera.crop_x = 3;
    d.camera.crop_y = 2;
    d.camera.crop_width = 21;
    d.camera.crop_height = 19;
    d.materials.push_back(material(kd, ks, r));
    d.materials.push_back(material(black, black, r));
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(ball.desc(0));
    d.meshes.push_back(lamp.desc(1));
    d.meshes[2].emission = le.desc();
    auto scene = build_scene(d);
    const int W = image_width(*scene), H = image_height(*scene);
    ASSERT_EQ(W, 21);
    ASSERT_EQ(H, 19);

    // Every packet size from 1 to kPacketSize, hits and misses alike.
    std::vector<Ray> rays;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) rays.push_back(scene->camera.generate_ray(float(x) + 0.3f, float(y) + 0.6f));
    int misses = 0;
    for (Tracing tracing : {Tracing::Exact, Tracing::Fast})
    for (int n = 1; n <= kPacketSize; ++n)
        for (size_t begin = 0; begin + size_t(n) <= rays.size(); begin += size_t(n)) {
            FirstHit packet[kPacketSize];
            intersect_packet(*scene, tracing, rays.data() + begin, n, packet);
            for (int i = 0; i < n; ++i) {
                const FirstHit single = first_hit(*scene, rays[begin + size_t(i)], false, tracing);
                ASSERT_EQ(packet[i].found, single.found) << "ray " << begin + size_t(i);
                misses += !single.found;
                if (!single.found) continue;
                EXPECT_EQ(packet[i].hit.mesh, single.hit.mesh);
                EXPECT_EQ(packet[i].hit.prim, single.hit.prim);
                EXPECT_EQ(packet[i].hit.b1, single.hit.b1);
                EXPECT_EQ(packet[i].hit.b2, single.hit.b2);
                EXPECT_EQ(packet[i].hit.t, single.hit.t);
            }
        }
    EXPECT_GT(misses, 0);

    // Each of the two BVHs (scene.h, Tracing): an image no gradient follows traces the fast one.
    for (bool replayable : {true, false}) {
    RenderOptions opt;
    opt.spp = 3;
    opt.max_bounces = 2;
    opt.seed = 11;
    opt.replayable = replayable;
    std::vector<float> reference(size_t(W) * H * 3);
    RayCounters counters;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int fx = x + scene->crop_x, fy = y + scene->crop_y;
            const uint64_t pixel = uint64_t(fy) * uint64_t(scene->camera.width) + uint64_t(fx);
            double sum[3] = {0, 0, 0};
            for (int s = 0; s < opt.spp; ++s) {
                Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                const Vec2f film = sample_film_point(*scene, fx, fy, rng);
                const Vec3f L = trace_path(*scene, opt, scene->camera.generate_ray(film.x, film.y), rng, counters);
                for (int k = 0; k < 3; ++k) sum[k] += L[k];
            }
            for (int k = 0; k < 3; ++k) reference[(size_t(y) * W + x) * 3 + k] = float(sum[k] / opt.spp);
        }
    double total = 0;
    for (float v : reference) total += v;
    EXPECT_GT(total, 0.0);
    for (int threads : {1, 2}) {
        opt.num_threads = threads;
        std::vector<float> image(reference.size());
        render(*scene, opt, image.data());
        int differing = 0;
        for (size_t i = 0; i < image.size(); ++i) differing += image[i] != reference[i];
        EXPECT_EQ(differing, 0) << threads << " threads, replayable " << replayable;
    }
    }
}

// A last vertex's continuation is traced only where it may meet an emitter
// (Scene::may_meet_emitter, render/batch.cpp): every ray towards a point of an emitting triangle
// (inside, on an edge, at a corner; from near and far, along the axes too) may; rays that leave
// every emitter's box behind may not; the boxes follow the emitters when vertices move, and a
// scene without emitters has none. (The batched-paths tests below check the images bit for bit.)
TEST(Render, ContinuationsThatMissEveryEmitterBoxAreKnown) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.5f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    MeshData bulb = make_sphere(Vec3f(2.f, 0.5f, 0.f), 0.2f, 6, 12);
    ConstTex kd({0.6f, 0.6f, 0.5f}), black({0, 0, 0}), r({0.3f}), le({4.f, 4.f, 4.f});
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.5f, 5), Vec3f(0, 0, 0), 8, 8, 40);
    d.materials.push_back(material(kd, black, r));
    d.meshes.push_back(floor.desc(0));
    auto scene = build_scene(d);
    EXPECT_TRUE(scene->emitter_boxes.empty());
    EXPECT_FALSE(scene->may_meet_emitter(Vec3f(0, 0, 0), Vec3f(0, 1, 0)));
    d.meshes.push_back(lamp.desc(0));
    d.meshes.back().emission = le.desc();
    d.meshes.push_back(bulb.desc(0));
    d.meshes.back().emission = le.desc();
    update_scene(*scene, d);
    ASSERT_EQ(scene->emitter_boxes.size(), 2u);

    Rng rng(7, 1);
    // Every emitting triangle's corners, edge points and inner points, from origins all around.
    auto check_all = [&](const MeshData& m) {
        int checked = 0;
        for (int64_t t = 0; t < m.num_triangles(); ++t) {
            Vec3f v[3];
            for (int c = 0; c < 3; ++c) v[c] = Vec3f::load(m.vertices.data() + 3 * m.indices[size_t(3 * t + c)]);
            for (int k = 0; k < 12; ++k) {
                float b1 = rng.next_float(), b2 = rng.next_float();
                if (k < 3) b1 = float(k == 1), b2 = float(k == 2);  // the corners
                else if (k < 6) b2 = 0.f;                          // on an edge
                else if (b1 + b2 > 1.f) b1 = 1.f - b1, b2 = 1.f - b2;
                const Vec3f target = v[0] * (1.f - b1 - b2) + v[1] * b1 + v[2] * b2;
                const float dist = k % 2 ? 1e-3f : 30.f;
                Vec3f dir(rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f);
                if (k == 7) dir = Vec3f(0, 1, 0);  // axis-aligned: two slabs met with a zero direction
                dir = normalize(dir);
                const Vec3f origin = target - dir * dist;
                EXPECT_TRUE(scene->may_meet_emitter(origin, dir)) << "triangle " << t << ", point " << k;
                ++checked;
            }
        }
        return checked;
    };
    EXPECT_GT(check_all(lamp) + check_all(bulb), 12 * 100);
    // Away from both: from the floor downwards, sideways beneath the lamp, and from beside the
    // lamp (inside its box's slab of height) straight along x, missing the bulb.
    EXPECT_FALSE(scene->may_meet_emitter(Vec3f(0, -1, 0), Vec3f(0, -1, 0)));
    EXPECT_FALSE(scene->may_meet_emitter(Vec3f(-3, 1.f, 0), normalize(Vec3f(1, 0, 1))));
    EXPECT_FALSE(scene->may_meet_emitter(Vec3f(-2, 1.5f, 3), Vec3f(1, 0, 0)));
    EXPECT_FALSE(scene->may_meet_emitter(Vec3f(0, 1.f, 0), Vec3f(0, -1, 0)));  // the lamp behind
    int missed = 0;
    for (int k = 0; k < 200; ++k) {  // from the floor into the upper hemisphere: mostly past both
        const Vec3f origin(6.f * rng.next_float() - 3.f, -1.f, 6.f * rng.next_float() - 3.f);
        const float z = rng.next_float(), phi = 6.2831853f * rng.next_float(), s = std::sqrt(1.f - z * z);
        missed += !scene->may_meet_emitter(origin, Vec3f(s * std::cos(phi), z, s * std::sin(phi)));
    }
    EXPECT_GT(missed, 150);

    // The lamp moved: its box moves with it.
    MeshData moved = lamp;
    moved.transform(Vec3f(1.f), Vec3f(0.f, -3.f, 4.f));
    d.meshes[1].vertices = moved.vertices.data();
    update_scene(*scene, d);
    EXPECT_GT(check_all(moved), 0);
    EXPECT_FALSE(scene->may_meet_emitter(Vec3f(0, 1.f, 0), Vec3f(0, 1, 0)));  // towards where it was
}

// trace_path's image of `scene`: each pixel the mean of trace_path over its camera samples,
// traced one at a time with their own streams (black outside a fisheye's image circle; counted
// in `outside`). `counters` gets its rays.
std::vector<float> trace_path_image(const Scene& scene, const RenderOptions& opt, RayCounters& counters,
                                    int* outside = nullptr) {
    const int W = image_width(scene), H = image_height(scene);
    std::vector<float> image(size_t(W) * H * 3);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            double sum[3] = {0, 0, 0};
            for (int s = 0; s < opt.spp; ++s) {
                CameraSample cs = camera_sample(scene, opt.seed, x, y, s);
                if (outside) *outside += cs.outside;
                const Vec3f L = cs.outside ? Vec3f(0.f) : trace_path(scene, opt, cs.ray, cs.rng, counters);
                for (int k = 0; k < 3; ++k) sum[k] += L[k];
            }
            for (int k = 0; k < 3; ++k) image[(size_t(y) * W + x) * 3 + k] = float(sum[k] / opt.spp);
        }
    return image;
}

// A 4 x 8 sky with a bright patch, so that sampling it by radiance differs from uniform.
std::vector<float> bright_patch_sky() {
    std::vector<float> sky(4 * 8 * 3);
    for (size_t i = 0; i < sky.size(); ++i) sky[i] = 0.1f + 0.05f * float(i % 7) + (i / 3 == 9 ? 4.f : 0.f);
    return sky;
}

// An image alone samples a lat-long sky by its light above the mean (Envmap::compensated): the
// same image in expectation as the replayable one, which samples it by its whole radiance, and
// less noisy (a diffuse floor and a glossy sphere under the bright-patch sky).
TEST(Render, CompensatedSkySamplesAgreeAndAreLessNoisy) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0, -0.2f, 0), 0.8f, 16, 32);
    ConstTex kd({0.6f, 0.5f, 0.4f}), ks({0.2f, 0.2f, 0.2f}), rough({0.3f}), black({0, 0, 0});
    const std::vector<float> sky = bright_patch_sky();
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.5f, 4), Vec3f(0, -0.3f, 0), 20, 20, 50);
    d.materials.push_back(material(kd, black, rough));
    d.materials.push_back(material(kd, ks, rough));
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(ball.desc(1));
    d.has_envmap = true;
    d.envmap.values = {sky.data(), 4, 8, 3};
    auto scene = build_scene(d);
    ASSERT_TRUE(scene->envmap.compensated().valid());
    RenderOptions opt;
    opt.spp = 4;
    opt.max_bounces = 2;
    const Stats whole = render_stats(*scene, opt, 48);
    opt.replayable = false;
    const Stats comp = render_stats(*scene, opt, 48);
    double var_whole = 0, var_comp = 0, sum_whole = 0, sum_comp = 0;
    int off = 0;
    for (size_t i = 0; i < whole.mean.size(); ++i) {
        const double se = std::hypot(whole.stderr_[i], comp.stderr_[i]);
        off += std::abs(whole.mean[i] - comp.mean[i]) > 5 * se + 1e-6;
        var_whole += whole.stderr_[i] * whole.stderr_[i];
        var_comp += comp.stderr_[i] * comp.stderr_[i];
        sum_whole += whole.mean[i];
        sum_comp += comp.mean[i];
    }
    EXPECT_EQ(off, 0);
    // The image sums (the pixels' errors are independent): a bias shows there first.
    EXPECT_NEAR(sum_comp, sum_whole, 4 * std::sqrt(var_whole + var_comp));
    EXPECT_LT(var_comp, 0.9 * var_whole);
}

// The textures the batched-paths tests share: a 3 x 3 checker (a textured diffuse), a 2 x 2
// roughness, and vertex colours for a mesh of `vertices` vertices.
struct BatchTextures {
    std::vector<float> checker = std::vector<float>(3 * 3 * 3), tint;
    const float bumpy[4] = {0.1f, 0.5f, 0.3f, 0.05f};
    TextureDesc checker_tex, bumpy_tex;
    explicit BatchTextures(int64_t vertices) : tint(size_t(vertices) * 3) {
        for (size_t i = 0; i < tint.size(); ++i) tint[i] = 0.4f + 0.15f * float((i * 7) % 5);
        for (size_t i = 0; i < checker.size(); ++i) checker[i] = (i / 3) % 2 ? 0.8f : 0.2f + 0.1f * float(i % 3);
        checker_tex.data = checker.data();
        checker_tex.height = checker_tex.width = checker_tex.channels = 3;
        bumpy_tex.data = bumpy;
        bumpy_tex.height = bumpy_tex.width = 2;
        bumpy_tex.channels = 1;
    }
    BatchTextures(const BatchTextures&) = delete;  // the descriptions point into it
    BatchTextures& operator=(const BatchTextures&) = delete;
};

// The batched-paths tests' variants of a scene: 0 its own lamps alone, 1 with the sky, 2 also
// with lights whose samples the batches are given whole (a sphere light sampled by solid angle,
// a quad by spherical triangles, both of material `material`) and a point light.
struct LightVariants {
    std::vector<float> sky = bright_patch_sky();
    MeshData bulb_mesh = make_sphere(Vec3f(1.6f, 1.2f, 0.4f), 0.15f, 6, 12);
    MeshData tri_lamp = make_quad(Vec3f(-1.5f, 1.5f, -1.f), Vec3f(0.8f, 0, 0), Vec3f(0, -0.2f, 0.8f));
    ConstTex le{{6.f, 6.f, 6.f}}, le2{{1.f, 2.f, 3.f}};
    PointLightDesc bulb;
    LightVariants() {
        bulb.position[0] = -1.2f;
        bulb.position[1] = 1.f;
        bulb.position[2] = 1.5f;
    }
    // Makes d variant `variant` of the one before (variant 2 adds to it, once).
    void apply(SceneDesc& d, int variant, int material) const {
        d.has_envmap = variant > 0;
        if (d.has_envmap) d.envmap.values = {sky.data(), 4, 8, 3};
        if (variant != 2) return;
        d.meshes.push_back(bulb_mesh.desc(material));
        d.meshes.back().emission = le2.desc();
        d.meshes.back().sample_solid_angle = true;
        d.meshes.push_back(tri_lamp.desc(material));
        d.meshes.back().emission = le.desc();
        d.meshes.back().sample_spherical_triangle = true;
        d.point_lights = {bulb};
    }
};

// Whether two floats are the same bit for bit.
bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }
bool same_bits(const Vec3f& a, const Vec3f& b) { return same_bits(a.x, b.x) && same_bits(a.y, b.y) && same_bits(a.z, b.z); }
bool same_hit(const Hit& a, const Hit& b) {
    return a.mesh == b.mesh && a.prim == b.prim && same_bits(a.b1, b.b1) && same_bits(a.b2, b.b2) && same_bits(a.t, b.t);
}
bool same_nee(const NeeRecord& a, const NeeRecord& b) {
    return a.used == b.used && (!a.used || (same_bits(a.dir, b.dir) && same_bits(a.scale, b.scale) && same_hit(a.hit, b.hit)));
}
// Two records of one path, every field the gradient pass reads (escape_weight where it escaped,
// the continuation's where it has one).
bool same_record(const PathRecord& a, const PathRecord& b) {
    if (a.camera_missed != b.camera_missed || a.emitters_hidden != b.emitters_hidden || a.escaped != b.escaped ||
        (a.escaped && !same_bits(a.escape_weight, b.escape_weight)) || a.vertices.size() != b.vertices.size())
        return false;
    for (size_t k = 0; k < a.vertices.size(); ++k) {
        const PathVertexRecord &u = a.vertices[k], &v = b.vertices[k];
        if (!same_hit(u.hit, v.hit) || !same_bits(u.origin, v.origin) || !same_bits(u.dir, v.dir) ||
            !same_bits(u.beta, v.beta) || !same_bits(u.emission_weight, v.emission_weight) ||
            !same_nee(u.nee_area, v.nee_area) || !same_nee(u.nee_env, v.nee_env) || u.point_lights != v.point_lights ||
            u.next != v.next)
            return false;
        if (u.next && (u.next_delta != v.next_delta || u.next_refract != v.next_refract ||
                       !same_bits(u.next_dir, v.next_dir) || !same_bits(u.next_inv_pdf, v.next_inv_pdf)))
            return false;
    }
    return true;
}

// The gradient pass's camera paths (for_each_sample with whole paths: recorded a batch at a time,
// render/batch.h) against trace_path's records of the same samples traced one by one: the same
// records bit for bit, with the sample's film point, lens point and stream. Options made
// replayable, as a gradient pass's are. Returns the number of records with a light sample used
// (kind: 0 area, 1 environment) in `nee` (two counts), and adds the records compared to `compared`.
void expect_records_match(const Scene& scene, RenderOptions opt, const std::string& what, int& compared,
                          int nee[2]) {
    opt.replayable = true;
    opt.num_threads = 1;  // the samples in order: a pixel's s counted here
    const int W = image_width(scene), H = image_height(scene);
    std::vector<int> next_s(size_t(W) * H, 0);
    int differing = 0, identity = 0;
    RayCounters counters;
    for_each_sample(
        scene, opt, true,
        [&](int x, int y, const PathRecord& rec) {
            const int s = next_s[size_t(y) * W + x]++;
            CameraSample cs = camera_sample(scene, opt.seed, x, y, s);
            PathRecord ref;
            if (cs.outside) {
                ref.camera_missed = ref.emitters_hidden = true;
            } else {
                trace_path(scene, opt, cs.ray, cs.rng, counters, &ref);
            }
            differing += !same_record(rec, ref);
            identity += !same_bits(rec.film.x, cs.film.x) || !same_bits(rec.film.y, cs.film.y) ||
                        !same_bits(rec.lens.x, cs.lens.x) || !same_bits(rec.lens.y, cs.lens.y) ||
                        rec.stream != mix64(mix64(opt.seed ^ 0x736563ull) ^ (cs.pixel * uint64_t(opt.spp) + uint64_t(s)));
            for (const PathVertexRecord& v : ref.vertices) {
                nee[0] += v.nee_area.used;
                nee[1] += v.nee_env.used;
            }
            ++compared;
        },
        [](int64_t) {});
    EXPECT_EQ(differing, 0) << what << ": records";
    EXPECT_EQ(identity, 0) << what << ": film, lens or stream";
}

// render() on 1 and 2 threads: `reference` bit for bit, with the same rays (`counters`).
// Returns the number of renders compared.
int expect_render_matches(const Scene& scene, RenderOptions opt, const std::vector<float>& reference,
                          const RayCounters& counters, const std::string& what) {
    int compared = 0;
    for (int threads : {1, 2}) {
        opt.num_threads = threads;
        std::vector<float> image(reference.size());
        const RenderStats st = render(scene, opt, image.data());
        int differing = 0;
        for (size_t i = 0; i < image.size(); ++i) differing += image[i] != reference[i];
        EXPECT_EQ(differing, 0) << what << ", " << threads << " threads";
        EXPECT_EQ(st.camera_rays, counters.camera) << what;
        EXPECT_EQ(st.shadow_rays, counters.shadow) << what;
        EXPECT_EQ(st.bounce_rays, counters.bounce) << what;
        ++compared;
    }
    return compared;
}

// The forward pass advances its paths in batches, bounce by bounce, their shadow and
// continuation rays traced in Embree packets (render/batch.h). Each path's radiance is still
// trace_path's, bit for bit: the image equals, pixel by pixel, the mean of trace_path over the
// pixel's samples traced one at a time with their own streams, for every material (rough,
// mirror, smooth and rough glass, plastic), every kind of light (area, point, spot point,
// environment), each sampling strategy, hidden emitters and path lengths from 0 to many
// bounces, on 1 and 2 threads; and render_channels' radiance is the same image.
TEST(Render, BatchedPathsMatchTracePath) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData glass = make_sphere(Vec3f(0.9f, -0.4f, 0.6f), 0.5f, 10, 20);
    MeshData rough_glass = make_sphere(Vec3f(-1.0f, -0.5f, 0.9f), 0.45f, 10, 20);
    MeshData mirror = make_quad(Vec3f(-2.5f, -1, -1.5f), Vec3f(0, 2.5f, 0), Vec3f(1.5f, 0, -1.f));
    MeshData plastic = make_box(Vec3f(-0.3f, -1, -0.8f), Vec3f(0.4f, -0.2f, -0.1f));
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.8f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    ConstTex kd({0.6f, 0.6f, 0.5f}), ks({0.2f, 0.2f, 0.2f}), r({0.3f}), black({0, 0, 0}), le({6.f, 6.f, 6.f});
    ConstTex metal({0.9f, 0.8f, 0.6f}), smooth({0.f}), rough({0.25f}), ior({1.5f}), white({1, 1, 1});
    const std::vector<float> sky = bright_patch_sky();
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.2f, 5), Vec3f(0, 0, 0), 26, 23, 70);  // its upper half sees the sky past the floor
    d.camera.crop_x = 2;
    d.camera.crop_y = 1;
    d.camera.crop_width = 22;
    d.camera.crop_height = 21;
    d.materials.push_back(material(kd, ks, r));           // 0: rough
    d.materials.push_back(material(black, black, r));     // 1: the lamp's
    d.materials.push_back(material(black, metal, r));     // 2: mirror
    d.materials[2].kind = MaterialKind::Conductor;
    d.materials.push_back(material(black, white, smooth));  // 3: smooth glass
    d.materials[3].kind = MaterialKind::Dielectric;
    d.materials[3].ior = ior.desc();
    d.materials.push_back(material(black, white, rough));  // 4: rough glass
    d.materials[4].kind = MaterialKind::Dielectric;
    d.materials[4].ior = ior.desc();
    d.materials.push_back(material(kd, white, rough));     // 5: plastic
    d.materials[5].kind = MaterialKind::Plastic;
    d.materials[5].ior = ior.desc();
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(glass.desc(3));
    d.meshes.push_back(rough_glass.desc(4));
    d.meshes.push_back(mirror.desc(2));
    d.meshes.push_back(plastic.desc(5));
    d.meshes.push_back(lamp.desc(1));
    d.meshes[5].emission = le.desc();
    d.has_envmap = true;
    d.envmap.values = {sky.data(), 4, 8, 3};
    PointLightDesc bulb, spot;
    bulb.position[0] = 1.5f;
    bulb.position[1] = 1.f;
    bulb.position[2] = 1.f;
    spot.position[0] = -1.f;
    spot.position[1] = 1.5f;
    spot.position[2] = 0.5f;
    spot.intensity[0] = 3.f;
    spot.spot = true;
    spot.spot_profile[1] = -1.f;  // pointing down, 60 degrees wide: part of the floor outside its cone
    spot.spot_profile[2] = 0.f;
    spot.spot_profile[3] = 0.5f;
    spot.spot_profile[4] = 0.3f;
    d.point_lights = {bulb, spot};
    auto scene = build_scene(d);
    const int W = image_width(*scene), H = image_height(*scene);

    RenderOptions opt;
    opt.spp = 3;  // batches straddle pixels; a tile's last batch is partial
    opt.seed = 5;
    int compared = 0, outside = 0, records = 0, nee[2] = {0, 0};
    // A fisheye's film points outside its image circle are black (CameraSample::outside).
    for (CameraType type : {CameraType::Perspective, CameraType::Fisheye}) {
        d.camera.type = type;
        scene->set_camera(d.camera);
        for (LightSampling sampling : {LightSampling::MIS, LightSampling::LightOnly, LightSampling::BSDFOnly})
            for (bool hide : {false, true})
                for (int bounces : {0, 1, 3, 40})
                    for (bool replayable : {true, false}) {  // false: the sky's compensated samples
                        if (sampling != LightSampling::MIS && (hide || bounces == 40 || !replayable)) continue;
                        if (type == CameraType::Fisheye && (sampling != LightSampling::MIS || hide || bounces != 3))
                            continue;
                        opt.sampling = sampling;
                        opt.hide_emitters = hide;
                        opt.max_bounces = bounces;
                        opt.replayable = replayable;
                        RayCounters counters;
                        const std::vector<float> reference = trace_path_image(*scene, opt, counters, &outside);
                        const std::string what = "camera " + std::to_string(int(type)) + ", sampling " +
                                                 std::to_string(int(sampling)) + ", hide " + std::to_string(hide) + ", " +
                                                 std::to_string(bounces) + " bounces, replayable " +
                                                 std::to_string(replayable);
                        double total = 0;
                        for (float v : reference) total += v;
                        if (hide && bounces == 0)
                            EXPECT_EQ(total, 0.0) << what;  // the emitters and the sky hidden, nothing lit
                        else
                            EXPECT_GT(total, 0.0) << what;
                        compared += expect_render_matches(*scene, opt, reference, counters, what);
                        const ChannelLayout layout({Channel::Depth, Channel::Radiance});
                        std::vector<float> values(size_t(W) * H * 4);
                        render_channels(*scene, opt, layout, values.data(), nullptr);
                        int differing = 0;
                        for (size_t i = 0; i < reference.size(); ++i)
                            differing += values[i / 3 * 4 + 1 + i % 3] != reference[i];
                        EXPECT_EQ(differing, 0) << what << ", render_channels";
                        if (replayable) expect_records_match(*scene, opt, what, records, nee);
                    }
    }
    EXPECT_EQ(compared, 2 * (2 * 8 + 3 + 3 + 2));
    EXPECT_GT(outside, 0);
    EXPECT_GT(records, 0);
    EXPECT_GT(nee[0], 0);
    EXPECT_GT(nee[1], 0);
}

// The batches against trace_path for each sampling strategy at 0, 1 and 3 bounces, and with MIS
// at `long_path` bounces too; each reference image must see some light. Returns how many
// renders expect_render_matches compared.
int expect_strategies_match(const Scene& scene, RenderOptions opt, int variant, int long_path) {
    int compared = 0;
    for (LightSampling sampling : {LightSampling::MIS, LightSampling::LightOnly, LightSampling::BSDFOnly})
        for (int bounces : {0, 1, 3, long_path})
            for (bool replayable : {true, false}) {  // false: the sky's compensated samples
                if (sampling != LightSampling::MIS && (bounces == long_path || !replayable)) continue;
                if (!replayable && bounces != 3) continue;
                opt.sampling = sampling;
                opt.max_bounces = bounces;
                opt.replayable = replayable;
                RayCounters counters;
                const std::vector<float> reference = trace_path_image(scene, opt, counters);
                const std::string what = "variant " + std::to_string(variant) + ", sampling " +
                                         std::to_string(int(sampling)) + ", " + std::to_string(bounces) +
                                         " bounces, replayable " + std::to_string(replayable);
                double total = 0;
                for (float v : reference) total += v;
                EXPECT_GT(total, 0.0) << what;
                compared += expect_render_matches(scene, opt, reference, counters, what);
                if (replayable) {
                    int records = 0, nee[2] = {0, 0};
                    expect_records_match(scene, opt, what, records, nee);
                    EXPECT_GT(records, 0) << what;
                    if (sampling != LightSampling::BSDFOnly && bounces > 0) {
                        EXPECT_GT(nee[0], 0) << what;
                    }
                }
            }
    return compared;
}

// The batches shade the vertices of a diffuse material four paths at a time in vectors
// (render/shade_lanes.h; a mirror's in vectors of its own, other kinds one by one): each
// path's radiance is still trace_path's bit for bit, with several kinds in one batch (a glossy
// box with a textured roughness, in the vectors, and a mirror, in its own, among diffuse surfaces),
// a sphere with shading normals and vertex colours, a textured floor, a one-sided diffuse quad
// seen from behind, a two-sided one, a black one, a lamp emitting on one side and one on both
// (sampled by area in the vectors), with and without an environment, then with the lights whose
// samples are taken path by path beside them (a sphere light sampled by solid angle, a quad by
// spherical triangles, a spot-profiled panel with textured emission; a point light and a spot
// point light), for each sampling strategy and path lengths from 0 to many bounces.
TEST(Render, BatchedPlainPathsMatchTracePath) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0.9f, -0.4f, 0.6f), 0.5f, 10, 20);
    MeshData back_wall = make_quad(Vec3f(-2.5f, -1, -1.5f), Vec3f(1.5f, 0, -1.f), Vec3f(0, 2.5f, 0));  // seen from behind
    MeshData screen = make_quad(Vec3f(1.2f, -1, -1.2f), Vec3f(0, 2.f, 0), Vec3f(1.2f, 0, 0.5f));
    MeshData soot = make_quad(Vec3f(-1.6f, -0.99f, 0.6f), Vec3f(0, 0, 0.8f), Vec3f(0.8f, 0, 0));
    MeshData glossy = make_box(Vec3f(-0.3f, -1, -0.8f), Vec3f(0.4f, -0.2f, -0.1f));
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.8f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    MeshData panel = make_quad(Vec3f(-2.f, 0.2f, 1.2f), Vec3f(0, 0.6f, 0), Vec3f(0, 0, 0.6f));
    ConstTex kd({0.6f, 0.6f, 0.5f}), red({0.7f, 0.1f, 0.1f}), ks({0.2f, 0.2f, 0.2f}), r({0.3f}), black({0, 0, 0});
    ConstTex le({6.f, 6.f, 6.f}), le2({1.f, 2.f, 3.f});
    const BatchTextures tex(ball.num_vertices());
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.2f, 5), Vec3f(0, 0, 0), 26, 23, 70);
    d.materials.push_back(material(kd, black, r));     // 0: diffuse
    d.materials.push_back(material(red, black, r));    // 1: diffuse, two-sided
    d.materials[1].two_sided = true;
    d.materials.push_back(material(black, black, r));  // 2: black (the lamps', the soot's)
    d.materials.push_back(material(kd, ks, r));        // 3: glossy, textured roughness (in the vectors)
    d.materials[3].roughness = tex.bumpy_tex;
    d.materials.push_back(material(kd, black, r));     // 4: diffuse, textured
    d.materials[4].diffuse = tex.checker_tex;
    d.materials.push_back(material(black, ks, r));     // 5: a mirror: its own vectors
    d.materials[5].kind = MaterialKind::Conductor;
    d.meshes.push_back(floor.desc(4));
    d.meshes.push_back(ball.desc(0));
    d.meshes[1].colors = tex.tint.data();
    d.meshes.push_back(back_wall.desc(0));
    d.meshes.push_back(screen.desc(1));
    d.meshes.push_back(soot.desc(2));
    d.meshes.push_back(glossy.desc(3));
    d.meshes.push_back(lamp.desc(2));
    d.meshes.push_back(panel.desc(2));
    d.meshes[6].emission = le.desc();
    d.meshes[7].emission = le2.desc();
    d.meshes[7].two_sided_emission = true;
    MeshData mirror = make_quad(Vec3f(1.7f, -1, 0.2f), Vec3f(0, 1.4f, 0), Vec3f(-0.3f, 0, 0.9f));
    d.meshes.push_back(mirror.desc(5));
    const LightVariants variants;
    MeshData spot_panel = make_quad(Vec3f(0.5f, 1.6f, 1.f), Vec3f(0.6f, 0, 0), Vec3f(0, 0, 0.6f));
    std::vector<float> glow(2 * 2 * 3);
    for (size_t i = 0; i < glow.size(); ++i) glow[i] = 1.f + float(i % 5);
    TextureDesc glow_tex;
    glow_tex.data = glow.data();
    glow_tex.height = glow_tex.width = 2;
    glow_tex.channels = 3;
    PointLightDesc spot;
    spot.position[0] = 0.3f;
    spot.position[1] = 1.5f;
    spot.position[2] = 0.5f;
    spot.intensity[0] = 3.f;
    spot.spot = true;
    spot.spot_profile[1] = -1.f;
    spot.spot_profile[2] = 0.f;
    spot.spot_profile[3] = 0.5f;
    spot.spot_profile[4] = 0.3f;
    RenderOptions opt;
    opt.spp = 3;
    opt.seed = 11;
    int compared = 0;
    for (int variant = 0; variant < 3; ++variant) {
        variants.apply(d, variant, 2);
        if (variant == 2) {  // and a spot-profiled panel and a spot point light
            d.meshes.push_back(spot_panel.desc(2));
            d.meshes.back().emission = glow_tex;
            d.meshes.back().spot = true;
            d.meshes.back().spot_profile[1] = -1.f;
            d.meshes.back().spot_profile[2] = 0.f;
            d.point_lights.push_back(spot);
        }
        compared += expect_strategies_match(*build_scene(d), opt, variant, 40);
    }
    EXPECT_EQ(compared, 3 * 2 * (5 + 3 + 3));
}

// The room of the glossy and plastic batched-paths tests: a floor, two balls, a wall, a panel,
// a sheet just above the floor, a box, a lamp and a mirror.
struct BatchRoom {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0.9f, -0.4f, 0.6f), 0.5f, 10, 20);
    MeshData other_ball = make_sphere(Vec3f(-0.9f, -0.5f, 0.9f), 0.45f, 10, 20);
    MeshData wall = make_quad(Vec3f(-2.5f, -1, -1.5f), Vec3f(0, 2.5f, 0), Vec3f(1.5f, 0, -1.f));
    MeshData panel = make_quad(Vec3f(1.2f, -1, -1.2f), Vec3f(0, 2.f, 0), Vec3f(1.2f, 0, 0.5f));
    MeshData sheen = make_quad(Vec3f(-1.6f, -0.99f, 0.6f), Vec3f(0, 0, 0.8f), Vec3f(0.8f, 0, 0));
    MeshData box = make_box(Vec3f(-0.3f, -1, -0.8f), Vec3f(0.4f, -0.2f, -0.1f));
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.8f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    MeshData mirror = make_quad(Vec3f(1.7f, -1, 0.2f), Vec3f(0, 1.4f, 0), Vec3f(-0.3f, 0, 0.9f));
};

// expect_strategies_match on the three LightVariants of d (their lights of material
// `light_material`), at 3 spp with this seed and up to 12 bounces; each must compare its renders.
void expect_variants_match(SceneDesc& d, uint64_t seed, int light_material) {
    const LightVariants variants;
    RenderOptions opt;
    opt.spp = 3;
    opt.seed = seed;
    int compared = 0;
    for (int variant = 0; variant < 3; ++variant) {
        variants.apply(d, variant, light_material);
        compared += expect_strategies_match(*build_scene(d), opt, variant, 12);
    }
    EXPECT_EQ(compared, 3 * 2 * (5 + 3 + 3));
}

// The batches shade glossy vertices (the standard material: the diffuse and GGX lobes, its
// reflectances and roughness constant or textured) in the vectors too: each path's radiance is still
// trace_path's bit for bit, on 1 and 2 threads. Glossy surfaces of roughness 0 (alpha clamped
// to kMinRoughness), 0.05, 0.2 and 1, a grey, a weak (0.04) and a coloured specular, a black
// diffuse under a specular (the GGX lobe alone), a textured diffuse (the lobe's probability
// per point) and vertex colours, one two-sided surface seen from both sides, a textured
// roughness under a textured specular with a black texel (the GGX lobe there and not beside
// it), among a diffuse wall and a mirror (its own vectors); a lamp sampled by area in the vectors,
// then a sky, then lights whose samples are given whole (a sphere light by solid angle, a
// quad by spherical triangles) and point lights; each sampling strategy, 0 to 12 bounces.
TEST(Render, BatchedGlossyPathsMatchTracePath) {
    const BatchRoom room;
    ConstTex kd({0.6f, 0.6f, 0.5f}), red({0.7f, 0.1f, 0.1f}), black({0, 0, 0}), le({6.f, 6.f, 6.f});
    ConstTex weak({0.04f, 0.04f, 0.04f}), gold({0.9f, 0.6f, 0.2f}), grey({0.5f, 0.5f, 0.5f}), bright({0.8f, 0.8f, 0.8f});
    ConstTex r0({0.f}), r005({0.05f}), r02({0.2f}), r1({1.f}), r03({0.3f});
    const BatchTextures tex(room.ball.num_vertices());
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.2f, 5), Vec3f(0, 0, 0), 26, 23, 70);
    d.materials.push_back(material(kd, weak, r005));   // 0: textured diffuse, weak specular
    d.materials[0].diffuse = tex.checker_tex;
    d.materials.push_back(material(kd, gold, r0));     // 1: coloured specular, alpha clamped
    d.materials.push_back(material(kd, grey, r1));     // 2: the roughest
    d.materials.push_back(material(red, black, r03));  // 3: diffuse
    d.materials.push_back(material(kd, grey, r02));    // 4: two-sided
    d.materials[4].two_sided = true;
    d.materials.push_back(material(black, bright, r02));  // 5: the GGX lobe alone
    // 6: textured roughness and specular (one texel black)
    const float specs[12] = {0.5f, 0.5f, 0.5f, 0.f, 0.f, 0.f, 0.9f, 0.6f, 0.2f, 0.04f, 0.04f, 0.04f};
    TextureDesc spec_tex;
    spec_tex.data = specs;
    spec_tex.height = spec_tex.width = 2;
    spec_tex.channels = 3;
    d.materials.push_back(material(kd, grey, r03));
    d.materials[6].roughness = tex.bumpy_tex;
    d.materials[6].specular = spec_tex;
    d.materials.push_back(material(black, black, r03));   // 7: the lamps'
    d.materials.push_back(material(black, gold, r03));    // 8: a mirror: its own vectors
    d.materials[8].kind = MaterialKind::Conductor;
    d.meshes.push_back(room.floor.desc(0));
    d.meshes.push_back(room.ball.desc(1));
    d.meshes[1].colors = tex.tint.data();
    d.meshes.push_back(room.other_ball.desc(2));
    d.meshes.push_back(room.wall.desc(3));
    d.meshes.push_back(room.panel.desc(4));
    d.meshes.push_back(room.sheen.desc(5));
    d.meshes.push_back(room.box.desc(6));
    d.meshes.push_back(room.lamp.desc(7));
    d.meshes.back().emission = le.desc();
    d.meshes.push_back(room.mirror.desc(8));
    expect_variants_match(d, 13, 7);
}

// The batches shade plastic vertices (MaterialKind::Plastic) in vectors of their own
// (shade_plastic_lanes): each path's radiance is still trace_path's bit for bit, on 1 and 2
// threads. Rough coatings of roughness 0.05, 0.2, 0.3 and 1 (indices 1.5, 1.33), smooth ones
// (the mirror lobe chosen by the coating's probability; indices 1.5 and 0.7, below 1), a
// textured diffuse, vertex colours, nonlinear, a tinted and a black specular, a normal map,
// one two-sided surface seen from both sides, among a standard glossy box (its own vectors)
// and a two-sided mirror of textured specular (its own vectors too); a lamp sampled by area
// in the vectors, then a sky, then lights whose samples are given whole and a point light;
// each sampling strategy, 0 to 12 bounces.
TEST(Render, BatchedPlasticPathsMatchTracePath) {
    const BatchRoom room;
    MeshData shelf = make_quad(Vec3f(0.6f, 0.3f, -1.f), Vec3f(0.9f, 0, 0), Vec3f(0, 0, 0.7f));
    ConstTex kd({0.6f, 0.6f, 0.5f}), red({0.7f, 0.1f, 0.1f}), black({0, 0, 0}), white({1, 1, 1}), le({6.f, 6.f, 6.f});
    ConstTex tint({0.9f, 0.7f, 0.5f}), grey({0.5f, 0.5f, 0.5f}), light({0.9f, 0.9f, 0.8f});
    ConstTex r0({0.f}), r005({0.05f}), r03({0.3f}), r1({1.f}), r02({0.2f});
    ConstTex ior15({1.5f}), ior133({1.33f}), ior07({0.7f});
    const BatchTextures tex(room.ball.num_vertices());
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.2f, 5), Vec3f(0, 0, 0), 26, 23, 70);
    auto plastic = [&](const ConstTex& diffuse, const ConstTex& specular, const ConstTex& roughness,
                       const ConstTex& ior) {
        MaterialDesc m = material(diffuse, specular, roughness);
        m.kind = MaterialKind::Plastic;
        m.ior = ior.desc();
        return m;
    };
    d.materials.push_back(plastic(kd, white, r005, ior15));  // 0: textured diffuse
    d.materials[0].diffuse = tex.checker_tex;
    d.materials.push_back(plastic(light, tint, r03, ior133));  // 1: vertex colours, nonlinear, tinted
    d.materials[1].nonlinear = true;
    d.materials.push_back(plastic(kd, tint, r0, ior15));      // 2: smooth, tinted
    d.materials.push_back(plastic(red, white, r1, ior15));    // 3: the roughest, a normal map
    const float bumps[12] = {0.65f, 0.5f, 1.f, 0.4f, 0.55f, 1.f, 0.5f, 0.35f, 1.f, 0.5f, 0.5f, 1.f};
    TextureDesc bump_map;
    bump_map.data = bumps;
    bump_map.height = bump_map.width = 2;
    bump_map.channels = 3;
    d.materials[3].normal_map = bump_map;
    d.materials.push_back(plastic(kd, white, r03, ior15));    // 4: two-sided
    d.materials[4].two_sided = true;
    d.materials.push_back(plastic(kd, black, r02, ior15));    // 5: black specular (the base alone)
    d.materials.push_back(plastic(grey, white, r0, ior07));   // 6: smooth, two-sided, index below 1
    d.materials[6].two_sided = true;
    d.materials.push_back(material(kd, grey, r03));           // 7: standard, glossy
    d.materials.push_back(material(black, black, r03));       // 8: the lamps'
    d.materials.push_back(material(black, tint, r03));        // 9: a mirror: its own vectors
    d.materials[9].kind = MaterialKind::Conductor;
    d.materials[9].two_sided = true;
    d.materials[9].specular = tex.checker_tex;
    d.meshes.push_back(room.floor.desc(0));
    d.meshes.push_back(room.ball.desc(1));
    d.meshes[1].colors = tex.tint.data();
    d.meshes.push_back(room.other_ball.desc(2));
    d.meshes.push_back(room.wall.desc(3));
    d.meshes.push_back(room.panel.desc(4));
    d.meshes.push_back(room.sheen.desc(5));
    d.meshes.push_back(shelf.desc(6));
    d.meshes.push_back(room.box.desc(7));
    d.meshes.push_back(room.lamp.desc(8));
    d.meshes.back().emission = le.desc();
    d.meshes.push_back(room.mirror.desc(9));
    expect_variants_match(d, 17, 8);
}

// shade_lanes' widths in force for the life of a test, then the processor's widest again.
struct ForcedShadeWidth {
    explicit ForcedShadeWidth(ShadeWidth w) { force_shade_width(w); }
    ~ForcedShadeWidth() { force_shade_width(ShadeWidth::Auto); }
};

// ShadeLanes' inputs for n paths, drawn from `rng`: unit normals and directions, small error
// bounds, a GGX lobe on half of them (a grey or coloured specular, alpha from the smallest,
// kMinRoughness, to 1) with specular_lobe_probability's probability and lobe choices on both
// sides of it, the disk's numbers with its centre (0.5, 0.5) and its diagonals among them,
// masks on and off, light samples by area (some at the shading point itself, some seen edge on
// or from behind) and given ones, sky samples, with a black reflectance or throughput here and
// there.
void random_lanes(ShadeLanes<kShadeBatch>& L, int n, Rng& rng) {
    auto u = [&] { return rng.next_float(); };
    auto unit = [&] {
        const Vec3f v(2 * u() - 1, 2 * u() - 1, 2 * u() - 1);
        return length(v) > 1e-3f ? normalize(v) : Vec3f(0, 0, 1);
    };
    auto put = [](float (&a)[3][kShadeBatch], int k, const Vec3f& v) {
        for (int c = 0; c < 3; ++c) a[c][k] = v[c];
    };
    for (int k = 0; k < n; ++k) {
        const Vec3f p(4 * u() - 2, 4 * u() - 2, 4 * u() - 2), ng = unit();
        put(L.p, k, p);
        put(L.p_error, k, Vec3f(1e-6f * u(), 1e-6f * u(), 1e-6f * u()));
        put(L.ng, k, ng);
        put(L.ns, k, u() < 0.3f ? ng : normalize(ng + 0.8f * unit()));
        put(L.dir, k, unit());
        put(L.beta, k, u() < 0.05f ? Vec3f(0.f) : Vec3f(u(), u(), u()));
        BsdfParams bp;
        bp.diffuse = u() < 0.05f ? Vec3f(0.f) : Vec3f(u(), u(), u());
        const float g = u();
        bp.specular = g < 0.5f ? Vec3f(0.f) : g < 0.65f ? Vec3f(0.04f) : Vec3f(u(), u(), u());
        const float a = u();
        bp.alpha = a < 0.15f ? kMinRoughness : a < 0.3f ? 1.f : a < 0.45f ? 0.05f : std::max(u(), kMinRoughness);
        put(L.diffuse, k, bp.diffuse);
        put(L.specular, k, bp.specular);
        L.alpha[k] = bp.alpha;
        L.has_specular[k] = lane_mask(!is_black(bp.specular));
        L.lobe_p[k] = specular_lobe_probability(bp);
        L.u_lobe[k] = u();
        if (is_black(bp.specular)) {  // what the lanes without the lobe hold is not to be used
            put(L.specular, k, Vec3f(0.5f, 0.3f, 0.2f));
            L.lobe_p[k] = 0.7f;
        }
        L.two_sided[k] = lane_mask(u() < 0.5f);
        // Scene::bsdf_params' reflecting (not always: the mask is obeyed)
        L.reflects[k] = lane_mask(u() < 0.95f && !(luminance(bp.diffuse) + luminance(bp.specular) <= 0.f));
        const float d = u();
        L.disk[0][k] = d < 0.05f ? 0.5f : u();
        L.disk[1][k] = d < 0.05f ? 0.5f : d < 0.1f ? L.disk[0][k] : u();
        L.light_on[k] = lane_mask(u() < 0.8f);
        L.light_given[k] = lane_mask(lane_set(L.light_on, k) && u() < 0.25f);
        const float b1 = u(), b2 = u() * (1 - b1);
        L.b1[k] = b1;
        L.b2[k] = b2;
        const Vec3f v0(4 * u() - 2, 2 + u(), 4 * u() - 2);
        const Vec3f v1 = v0 + Vec3f(u(), 0.1f * u(), 0), v2 = v0 + Vec3f(0, 0.1f * u(), u());
        put(L.v0, k, u() < 0.03f ? p : v0);  // some light points at the shading point
        put(L.v1, k, v1);
        put(L.v2, k, v2);
        put(L.light_ng, k, u() < 0.5f ? Vec3f(0, -1, 0) : unit());
        L.edge[k] = 2 + u();
        L.pmf[k] = 0.1f + u();
        L.area[k] = u() < 0.03f ? 0.f : 0.05f + u();
        put(L.emission, k, u() < 0.05f ? Vec3f(0.f) : Vec3f(5 * u(), 5 * u(), 5 * u()));
        L.two_sided_emission[k] = lane_mask(u() < 0.5f);
        put(L.given_dir, k, unit());
        L.given_pdf[k] = 0.01f + u();
        put(L.given_radiance, k, Vec3f(u(), u(), u()));
        put(L.given_p, k, p + 3.f * unit());
        put(L.given_p_error, k, Vec3f(1e-6f * u(), 1e-6f * u(), 1e-6f * u()));
        put(L.given_ng, k, unit());
        L.env_on[k] = lane_mask(u() < 0.7f);
        put(L.env_dir, k, unit());
        put(L.env_radiance, k, Vec3f(u(), u(), u()));
        L.env_pdf[k] = u() < 0.03f ? 0.f : 0.05f + u();
    }
}

// The forward pass's plain vertices (diffuse, or diffuse and GGX) are shaded in AVX2's vectors
// of eight where the processor has AVX2, in SSE2's of four otherwise (render/shade_lanes.h):
// each lane's operations are the same, so both give the same bits. Checked on shade_lanes'
// arrays (every output of 64 random paths and of a partial batch of 13, each strategy of
// weights), each lane against the scalar BSDF code (its continuation and its sky sample's
// value, bit for bit), and on whole images, each width forced in turn: both bit for bit
// trace_path's.
// How many of the values the batch reads back from lanes [0, n) differ, bit for bit, between
// two shadings of the same lanes: the bent normal, the continuation (its mask, whether it is a
// delta lobe's, its ray, throughput and density), the shadow rays' masks and, where a mask is
// set, their rays and values. (A vector in which no path has a light sample leaves those arrays
// as they were: the two widths group the paths differently.)
int lanes_differing(const ShadeLanes<kShadeBatch>& a, const ShadeLanes<kShadeBatch>& b, int n) {
    int differing = 0;
    for (int k = 0; k < n; ++k) {
        auto same = [&](const float* x, const float* y) { differing += std::memcmp(x + k, y + k, sizeof(float)) != 0; };
        auto same3 = [&](const float (&x)[3][kShadeBatch], const float (&y)[3][kShadeBatch]) {
            for (int c = 0; c < 3; ++c) same(x[c], y[c]);
        };
        same3(a.ns, b.ns);
        same(a.goes_on, b.goes_on);
        same(a.next_delta, b.next_delta);
        same3(a.next_origin, b.next_origin);
        same3(a.next_dir, b.next_dir);
        same3(a.next_beta, b.next_beta);
        same(a.next_pdf, b.next_pdf);
        same(a.light_on, b.light_on);
        if (lane_set(a.light_on, k)) {
            same3(a.light_origin, b.light_origin);
            same3(a.light_dir, b.light_dir);
            same(a.light_tmax, b.light_tmax);
            same3(a.light_value, b.light_value);
        }
        same(a.env_on, b.env_on);
        if (lane_set(a.env_on, k)) {
            same3(a.env_origin, b.env_origin);
            same3(a.env_value, b.env_value);
        }
    }
    return differing;
}

TEST(Render, ShadeLanesWidthsAgree) {
    EXPECT_TRUE(shade_width_available(ShadeWidth::Sse2));
    const bool avx2 = shade_width_available(ShadeWidth::Avx2);
    if (!avx2) {
        EXPECT_EQ(shade_width(), ShadeWidth::Sse2);
        EXPECT_THROW(force_shade_width(ShadeWidth::Avx2), std::invalid_argument);
    } else {
        EXPECT_EQ(shade_width(), ShadeWidth::Avx2);
    }
    Rng rng(5, 7);
    int goes_on = 0, light_on = 0, env_on = 0, compared = 0, ggx_on = 0, glossy_env = 0;
    for (int round = 0; round < 40; ++round)
        for (int n : {kShadeBatch, 13})
            for (bool mis : {true, false}) {
                auto in = std::make_unique<ShadeLanes<kShadeBatch>>();
                random_lanes(*in, n, rng);
                // One round in four with the Lambertian lobe alone (the kernel made for it).
                const bool glossy = round % 4 != 3;
                if (!glossy)
                    for (int k = 0; k < n; ++k) in->has_specular[k] = lane_mask(false);
                auto narrow = std::make_unique<ShadeLanes<kShadeBatch>>(*in);
                auto wide = std::make_unique<ShadeLanes<kShadeBatch>>(*in);
                shade_lanes(*narrow, n, mis, glossy, ShadeWidth::Sse2);
                shade_lanes(*wide, n, mis, glossy, avx2 ? ShadeWidth::Avx2 : ShadeWidth::Sse2);
                const ShadeLanes<kShadeBatch>&a = *narrow, &b = *wide;
                EXPECT_EQ(lanes_differing(a, b, n), 0) << "round " << round << ", " << n << " paths, mis " << mis;
                // And each lane's the scalar code's (shade_vertex's bend_normal, Frame,
                // bsdf_sample, bsdf_eval, bsdf_pdf and mis_power), bit for bit.
                int unlike = 0;
                auto bits = [&](const float* x, int k, float y) { unlike += std::memcmp(x + k, &y, sizeof y) != 0; };
                auto bits3 = [&](const float (&x)[3][kShadeBatch], int k, const Vec3f& y) {
                    for (int c = 0; c < 3; ++c) bits(x[c], k, y[c]);
                };
                auto get = [](const float (&x)[3][kShadeBatch], int k) { return Vec3f(x[0][k], x[1][k], x[2][k]); };
                for (int k = 0; k < n; ++k) {
                    const ShadeLanes<kShadeBatch>& i = *in;
                    const Vec3f dir = get(i.dir, k), beta = get(i.beta, k);
                    const Vec3f ns = bend_normal(get(i.ns, k), get(i.ng, k), -dir);
                    const Frame frame(ns);
                    const Vec3f wo = frame.to_local(-dir);
                    BsdfParams bp;
                    bp.diffuse = get(i.diffuse, k);
                    bp.specular = lane_set(i.has_specular, k) ? get(i.specular, k) : Vec3f(0.f);
                    bp.alpha = i.alpha[k];
                    bp.two_sided = lane_set(i.two_sided, k);
                    BsdfSample bs;
                    Vec3f nb(0.f);
                    const bool sampled =
                        lane_set(i.reflects, k) && bsdf_sample(bp, wo, i.u_lobe[k], i.disk[0][k], i.disk[1][k], bs);
                    if (sampled) nb = beta * (bsdf_eval(bp, wo, bs.wi) / bs.pdf);
                    bits3(a.ns, k, ns);
                    const bool on = sampled && !is_black(nb);
                    unlike += lane_set(a.goes_on, k) != on;
                    if (on) {
                        bits3(a.next_dir, k, frame.to_world(bs.wi));
                        bits3(a.next_beta, k, nb);
                        bits(a.next_pdf, k, bs.pdf);
                        ggx_on += lane_set(i.has_specular, k) && i.u_lobe[k] < i.lobe_p[k];
                    }
                    if (lane_set(i.env_on, k) && i.env_pdf[k] > 0.f) {
                        const Vec3f wi = frame.to_local(get(i.env_dir, k));
                        const Vec3f f = bsdf_eval(bp, wo, wi);
                        unlike += lane_set(a.env_on, k) != !is_black(f);
                        const float w = mis ? mis_power(i.env_pdf[k], bsdf_pdf(bp, wo, wi)) : 1.f;
                        if (!is_black(f)) bits3(a.env_value, k, beta * f * get(i.env_radiance, k) * (w / i.env_pdf[k]));
                        glossy_env += !is_black(f) && !is_black(bp.specular);
                    }
                }
                EXPECT_EQ(unlike, 0) << "round " << round << ", " << n << " paths, mis " << mis << ": scalar";
                for (int k = 0; k < n; ++k) {
                    goes_on += lane_set(narrow->goes_on, k);
                    light_on += lane_set(narrow->light_on, k);
                    env_on += lane_set(narrow->env_on, k);
                }
                ++compared;
            }
    EXPECT_EQ(compared, 40 * 2 * 2);
    // Not a vacuous comparison: many paths go on and have light samples, not all.
    const int paths = 40 * 2 * (kShadeBatch + 13);
    EXPECT_GT(goes_on, paths / 3);
    EXPECT_LT(goes_on, paths);
    EXPECT_GT(light_on, paths / 8);
    EXPECT_LT(light_on, paths);
    EXPECT_GT(env_on, paths / 8);
    EXPECT_LT(env_on, paths);
    // The GGX lobe's samples and values among them (three rounds in four have the lobe).
    EXPECT_GT(ggx_on, paths / 20);
    EXPECT_GT(glossy_env, paths / 12);

    if (!avx2) GTEST_SKIP() << "this processor (or build) has no AVX2: only the SSE2 width runs";

    // Whole images: diffuse surfaces (one- and two-sided, vertex colours), glossy ones (one of
    // them two-sided), a lamp, a sky.
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0.4f, -0.4f, 0.3f), 0.6f, 12, 24);
    MeshData screen = make_quad(Vec3f(1.2f, -1, -1.2f), Vec3f(0, 2.f, 0), Vec3f(1.2f, 0, 0.5f));
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.8f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    MeshData shiny = make_sphere(Vec3f(-1.0f, -0.5f, 0.8f), 0.45f, 10, 20);
    ConstTex kd({0.6f, 0.6f, 0.5f}), red({0.7f, 0.1f, 0.1f}), r({0.3f}), black({0, 0, 0}), le({6.f, 6.f, 6.f});
    ConstTex gold({0.9f, 0.6f, 0.2f});
    std::vector<float> tint(size_t(ball.num_vertices()) * 3);
    for (size_t i = 0; i < tint.size(); ++i) tint[i] = 0.4f + 0.15f * float((i * 7) % 5);
    std::vector<float> sky(4 * 8 * 3);
    for (size_t i = 0; i < sky.size(); ++i) sky[i] = 0.1f + 0.05f * float(i % 7);
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.2f, 5), Vec3f(0, 0, 0), 24, 20, 60);
    d.materials.push_back(material(kd, black, r));
    d.materials.push_back(material(red, black, r));
    d.materials[1].two_sided = true;
    d.materials.push_back(material(black, black, r));
    d.materials.push_back(material(kd, gold, r));  // 3: glossy, two-sided
    d.materials[3].two_sided = true;
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(ball.desc(0));
    d.meshes[1].colors = tint.data();
    d.meshes.push_back(screen.desc(1));
    d.meshes.push_back(lamp.desc(2));
    d.meshes[3].emission = le.desc();
    d.meshes.push_back(shiny.desc(3));
    d.has_envmap = true;
    d.envmap.values = {sky.data(), 4, 8, 3};
    auto scene = build_scene(d);
    RenderOptions opt;
    opt.spp = 4;
    opt.seed = 3;
    int images = 0;
    for (int bounces : {1, 3}) {
        opt.max_bounces = bounces;
        RayCounters counters;
        const std::vector<float> reference = trace_path_image(*scene, opt, counters);
        for (ShadeWidth w : {ShadeWidth::Sse2, ShadeWidth::Avx2}) {
            ForcedShadeWidth forced(w);
            EXPECT_EQ(shade_width(), w);
            images += expect_render_matches(*scene, opt, reference, counters,
                                            "width " + std::to_string(int(w)) + ", " + std::to_string(bounces) + " bounces");
        }
    }
    EXPECT_EQ(images, 2 * 2 * 2);
    EXPECT_EQ(shade_width(), ShadeWidth::Avx2);
}

// The plastic's lanes (shade_plastic_lanes): random_lanes' paths made plastic, each with one of
// a few coatings (rough of alpha 0.05, 0.3 and 1 with indices 1.5 and 1.33, smooth with 1.5,
// 1.33 and 0.7; or the smooth ones alone, whose T(c) the kernel computes in vectors where a
// whole vector has them), a specular of 1, tinted or black, nonlinear or not; their
// BsdfParams (as Scene::bsdf_params makes a plastic's) for the scalar code.
struct PlasticLaneCoats {
    std::shared_ptr<const CoatTable> coats[6] = {coat_table(0.05f, 1.5f, false), coat_table(0.3f, 1.33f, false),
                                                 coat_table(1.f, 1.5f, false),   coat_table(0.f, 1.5f, true),
                                                 coat_table(0.f, 1.33f, true),   coat_table(0.f, 0.7f, true)};
};
std::vector<BsdfParams> random_plastic_lanes(ShadeLanes<kShadeBatch>& L, int n, Rng& rng, const PlasticLaneCoats& c,
                                             bool smooth_only) {
    random_lanes(L, n, rng);
    std::vector<BsdfParams> params(static_cast<size_t>(n));
    auto u = [&] { return rng.next_float(); };
    auto get = [](const float (&x)[3][kShadeBatch], int k) { return Vec3f(x[0][k], x[1][k], x[2][k]); };
    for (int k = 0; k < n; ++k) {
        BsdfParams& bp = params[size_t(k)];
        const float pick = u();
        const CoatTable* coat = c.coats[smooth_only ? 3 + std::min(int(pick * 3.f), 2) : std::min(int(pick * 6.f), 5)].get();
        const float s = u();
        bp.diffuse = get(L.diffuse, k);
        bp.specular = s < 0.5f ? Vec3f(1.f) : s < 0.85f ? Vec3f(u(), u(), u()) : Vec3f(0.f);
        bp.alpha = coat->smooth ? kMinRoughness : ggx_alpha(coat->alpha);
        bp.two_sided = lane_set(L.two_sided, k);
        bp.kind = MaterialKind::Plastic;
        bp.eta = coat->eta;
        bp.rough = !coat->smooth;
        bp.coat = coat;
        bp.nonlinear = u() < 0.3f;
        for (int ch = 0; ch < 3; ++ch) L.specular[ch][k] = bp.specular[ch];
        L.alpha[k] = bp.alpha;
        L.eta[k] = bp.eta;
        L.coat[k] = coat;
        L.coat_r[k] = coat->r;
        L.rough[k] = lane_mask(bp.rough);
        L.coat_smooth[k] = lane_mask(coat->smooth);
        L.coat_lobe[k] = lane_mask(!coat->smooth && !is_black(bp.specular));
        L.nonlinear[k] = lane_mask(bp.nonlinear);
        L.ks[k] = plastic_mean(bp.specular);
        L.kd[k] = plastic_mean(bp.diffuse);
        // Scene::bsdf_params' reflecting (not always: the mask is obeyed)
        L.reflects[k] = lane_mask(u() < 0.95f && !(luminance(bp.diffuse) + luminance(bp.specular) <= 0.f));
    }
    return params;
}

// The plastic's vertices are shaded in the vectors too, by the same kernel with the plastic's
// lobes (render/shade_lanes.h): both widths give the same bits, and each lane the scalar
// code's (bend_normal, Frame, bsdf_sample, bsdf_eval, bsdf_pdf, mis_power) bit for bit: its
// continuation (the coating's GGX sample, the smooth coating's mirror with its weight, or the
// base's cosine-weighted sample), its sky sample's and its given light sample's values, on 64
// random paths and a partial batch of 13, with each strategy's weights; T(c) from the tables
// path by path, and in vectors where all of a vector's coatings are smooth.
TEST(Render, ShadePlasticLanesWidthsAgree) {
    const bool avx2 = shade_width_available(ShadeWidth::Avx2);
    const PlasticLaneCoats coats;
    Rng rng(9, 4);
    int goes_on = 0, ggx_on = 0, mirror_on = 0, base_on = 0, env_on = 0, given_on = 0, lobe_env = 0, compared = 0;
    for (int round = 0; round < 40; ++round)
        for (int n : {kShadeBatch, 13})
            for (bool mis : {true, false}) {
                auto in = std::make_unique<ShadeLanes<kShadeBatch>>();
                // One round in four with smooth coatings alone.
                const std::vector<BsdfParams> params = random_plastic_lanes(*in, n, rng, coats, round % 4 == 3);
                auto narrow = std::make_unique<ShadeLanes<kShadeBatch>>(*in);
                auto wide = std::make_unique<ShadeLanes<kShadeBatch>>(*in);
                shade_plastic_lanes(*narrow, n, mis, ShadeWidth::Sse2);
                shade_plastic_lanes(*wide, n, mis, avx2 ? ShadeWidth::Avx2 : ShadeWidth::Sse2);
                const ShadeLanes<kShadeBatch>&a = *narrow, &b = *wide;
                EXPECT_EQ(lanes_differing(a, b, n), 0) << "round " << round << ", " << n << " paths, mis " << mis;
                int unlike = 0;
                auto bits = [&](const float* x, int k, float y) { unlike += std::memcmp(x + k, &y, sizeof y) != 0; };
                auto bits3 = [&](const float (&x)[3][kShadeBatch], int k, const Vec3f& y) {
                    for (int c = 0; c < 3; ++c) bits(x[c], k, y[c]);
                };
                auto get = [](const float (&x)[3][kShadeBatch], int k) { return Vec3f(x[0][k], x[1][k], x[2][k]); };
                for (int k = 0; k < n; ++k) {
                    const ShadeLanes<kShadeBatch>& i = *in;
                    const BsdfParams& bp = params[size_t(k)];
                    const Vec3f dir = get(i.dir, k), beta = get(i.beta, k);
                    const Vec3f ns = bend_normal(get(i.ns, k), get(i.ng, k), -dir);
                    const Frame frame(ns);
                    const Vec3f wo = frame.to_local(-dir);
                    BsdfSample bs;
                    Vec3f nb(0.f);
                    const bool sampled =
                        lane_set(i.reflects, k) && bsdf_sample(bp, wo, i.u_lobe[k], i.disk[0][k], i.disk[1][k], bs);
                    if (sampled) nb = beta * (bs.delta ? bs.weight : bsdf_eval(bp, wo, bs.wi) / bs.pdf);
                    bits3(a.ns, k, ns);
                    const bool on = sampled && !is_black(nb);
                    unlike += lane_set(a.goes_on, k) != on;
                    if (on) {
                        unlike += lane_set(a.next_delta, k) != bs.delta;
                        bits3(a.next_dir, k, continuation_dir(frame, get(i.ng, k), dir, bs));
                        bits3(a.next_beta, k, nb);
                        bits(a.next_pdf, k, bs.pdf);
                        ++goes_on;
                        mirror_on += bs.delta;
                        const bool coat_lobe = i.u_lobe[k] < plastic_coat_probability(bp, bp.two_sided ? std::abs(wo.z) : wo.z);
                        ggx_on += !bs.delta && coat_lobe;
                        base_on += !coat_lobe;
                    }
                    // next_event's value for a light sample (dir, pdf, radiance) of the lane's.
                    auto expect_sample = [&](const float* mask, const float (&value)[3][kShadeBatch], const Vec3f& ldir,
                                             float lpdf, const Vec3f& radiance) {
                        const Vec3f wi = frame.to_local(ldir);
                        const Vec3f f = bsdf_eval(bp, wo, wi);
                        unlike += lane_set(mask, k) != !is_black(f);
                        const float w = mis ? mis_power(lpdf, bsdf_pdf(bp, wo, wi)) : 1.f;
                        if (!is_black(f)) bits3(value, k, beta * f * radiance * (w / lpdf));
                        return !is_black(f);
                    };
                    if (lane_set(i.env_on, k) && i.env_pdf[k] > 0.f) {
                        const bool lit = expect_sample(a.env_on, a.env_value, get(i.env_dir, k), i.env_pdf[k],
                                                       get(i.env_radiance, k));
                        env_on += lit;
                        lobe_env += lit && lane_set(i.coat_lobe, k);
                    }
                    if (lane_set(i.light_given, k))
                        given_on += expect_sample(a.light_on, a.light_value, get(i.given_dir, k), i.given_pdf[k],
                                                  get(i.given_radiance, k));
                }
                EXPECT_EQ(unlike, 0) << "round " << round << ", " << n << " paths, mis " << mis << ": scalar";
                ++compared;
            }
    EXPECT_EQ(compared, 40 * 2 * 2);
    // Not a vacuous comparison: every lobe is sampled, many light samples are lit, not all.
    const int paths = 40 * 2 * (kShadeBatch + 13);
    EXPECT_GT(goes_on, paths / 4);
    EXPECT_LT(goes_on, paths);
    EXPECT_GT(ggx_on, paths / 40);
    EXPECT_GT(mirror_on, paths / 40);
    EXPECT_GT(base_on, paths / 8);
    EXPECT_GT(env_on, paths / 8);
    EXPECT_LT(env_on, paths);
    EXPECT_GT(lobe_env, paths / 20);
    EXPECT_GT(given_on, paths / 40);
}

// The mirror's lanes (shade_mirror_lanes, MaterialKind::Conductor): random_lanes' paths with a
// random specular (black at times) and two-sided or not through both widths, the same bits,
// and each lane's continuation the scalar bsdf_sample's delta branch bit for bit (its
// direction, weight and probability; none where wo is behind a one-sided mirror).
TEST(Render, ShadeMirrorLanesWidthsAgree) {
    const bool avx2 = shade_width_available(ShadeWidth::Avx2);
    Rng rng(3, 8);
    int goes_on = 0, behind = 0, compared = 0, mirrored = 0;
    auto get = [](const float (&x)[3][kShadeBatch], int k) { return Vec3f(x[0][k], x[1][k], x[2][k]); };
    for (int round = 0; round < 20; ++round)
        for (int n : {kShadeBatch, 13}) {
            auto in = std::make_unique<ShadeLanes<kShadeBatch>>();
            random_lanes(*in, n, rng);
            for (int k = 0; k < n; ++k) {
                const float g = rng.next_float();
                const Vec3f s = g < 0.1f ? Vec3f(0.f) : Vec3f(rng.next_float(), rng.next_float(), rng.next_float());
                for (int c = 0; c < 3; ++c) in->specular[c][k] = s[c];
            }
            auto narrow = std::make_unique<ShadeLanes<kShadeBatch>>(*in);
            auto wide = std::make_unique<ShadeLanes<kShadeBatch>>(*in);
            shade_mirror_lanes(*narrow, n, ShadeWidth::Sse2);
            shade_mirror_lanes(*wide, n, avx2 ? ShadeWidth::Avx2 : ShadeWidth::Sse2);
            int unlike = 0;
            auto bits = [&](const float* x, int k, float y) { unlike += std::memcmp(x + k, &y, sizeof y) != 0; };
            auto bits3 = [&](const float (&x)[3][kShadeBatch], int k, const Vec3f& y) {
                for (int c = 0; c < 3; ++c) bits(x[c], k, y[c]);
            };
            const ShadeLanes<kShadeBatch>&a = *narrow, &b = *wide, &i = *in;
            for (int k = 0; k < n; ++k) {
                const Vec3f dir = get(i.dir, k), beta = get(i.beta, k);
                const Vec3f ns = bend_normal(get(i.ns, k), get(i.ng, k), -dir);
                const Frame frame(ns);
                const Vec3f wo = frame.to_local(-dir);
                BsdfParams bp;
                bp.kind = MaterialKind::Conductor;
                bp.specular = get(i.specular, k);
                bp.two_sided = lane_set(i.two_sided, k);
                BsdfSample bs;
                Vec3f nb(0.f);
                const bool sampled = bsdf_sample(bp, wo, i.u_lobe[k], i.disk[0][k], i.disk[1][k], bs);
                if (sampled) nb = beta * bs.weight;
                bits3(a.ns, k, ns);
                const bool on = sampled && !is_black(nb);
                unlike += lane_set(a.goes_on, k) != on || lane_set(a.next_delta, k) != on;
                behind += !sampled;
                if (on) {
                    unlike += !bs.delta;
                    const Vec3f w = continuation_dir(frame, get(i.ng, k), dir, bs);
                    mirrored += length(w - frame.to_world(bs.wi)) > 0.f;
                    bits3(a.next_dir, k, w);
                    bits3(a.next_origin, k, offset_ray_origin(get(i.p, k), get(i.p_error, k), get(i.ng, k), w));
                    bits3(a.next_beta, k, nb);
                    bits(a.next_pdf, k, bs.pdf);
                    ++goes_on;
                }
            }
            EXPECT_EQ(lanes_differing(a, b, n), 0) << "round " << round << ", " << n << " paths";
            EXPECT_EQ(unlike, 0) << "round " << round << ", " << n << " paths: scalar";
            ++compared;
        }
    EXPECT_EQ(compared, 20 * 2);
    const int paths = 20 * (kShadeBatch + 13);
    EXPECT_GT(goes_on, paths / 3);
    EXPECT_GT(behind, paths / 20);
    EXPECT_GT(mirrored, 0);  // directions kept on their side of the face are among them
}

// A sphere light sampled by solid angle: every sample lands on the side it shows, its density
// is the one light_pdf gives the same point (MIS needs both to agree), and the irradiance it
// estimates at a few points equals the area sampling's estimate of the same mesh (measured:
// within 0.5% at 1e5 samples, 0.2% at 2e6, by turns above and below: the noise).
TEST(Render, SphereLightSampledBySolidAngle) {
    MeshData ball = make_sphere(Vec3f(0.3f, 1.5f, -0.2f), 0.2f, 8, 16);
    ConstTex black({0, 0, 0}), rough({0.5f}), le({2.f, 2.f, 2.f});
    double estimate[2][3] = {};
    const Vec3f points[3] = {Vec3f(0, 0, 0), Vec3f(1.f, 0.5f, 0.3f), Vec3f(-0.5f, 1.4f, -0.4f)};
    const Vec3f n(0, 1, 0);
    for (int mode = 0; mode < 2; ++mode) {
        SceneDesc d;
        d.camera = camera(Vec3f(0, 0, -5), Vec3f(0, 0, 0), 8, 8, 45);
        d.materials.push_back(material(black, black, rough));
        d.meshes.push_back(ball.desc(0));
        d.meshes[0].emission = le.desc();
        d.meshes[0].sample_solid_angle = mode == 0;
        auto scene = build_scene(d);
        Rng rng = Rng::for_sample(7, 0, 0);
        const int N = 100000;
        for (int i = 0; i < 3; ++i) {
            double sum = 0;
            for (int s = 0; s < N; ++s) {
                LightSample ls;
                const float u0 = rng.next_float(), u1 = rng.next_float(), u2 = rng.next_float();
                if (!scene->sample_area_light(points[i], u0, u1, u2, ls)) continue;
                const SurfacePoint q = scene->surface_point(ls.hit);
                ASSERT_GT(dot(q.ng, -ls.dir), 0.f);
                if (mode == 0 && s < 1000) {
                    EXPECT_NEAR(ls.pdf, scene->light_pdf(points[i], q), 1e-4f * ls.pdf);
                }
                sum += ls.radiance.x * std::max(0.f, dot(n, ls.dir)) / ls.pdf;
            }
            estimate[mode][i] = sum / N;
        }
    }
    for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(estimate[0][i], estimate[1][i], 0.01 * estimate[1][i]) << "point " << i << ": " << estimate[0][i] << " by solid angle, " << estimate[1][i] << " by area";
}


// A quad light sampled by spherical triangles, whole (2 triangles: picked by the solid angle
// each shows) and as a 5 x 5 grid (50: picked by power): at points below it, near (each
// triangle subtending up to about 2 sr) and far (below the bound: left to area sampling),
// every sample's density is the one light_pdf gives its point (MIS needs both to agree);
// light_pdf integrates to one over the directions towards the light; the irradiance estimates
// equal the closed form (Lambert's polygon formula), with a lower variance than area
// sampling's where the light is near.
TEST(Render, QuadLightSampledBySphericalTriangles) {
    struct Acc {
        double s = 0, s2 = 0;
        long n = 0;
        void add(double v) { s += v; s2 += v * v; ++n; }
        double mean() const { return s / n; }
        double se() const { return std::sqrt(std::max(0.0, s2 / n - mean() * mean()) / n); }
    };
    for (int grid : {1, 5}) {
        MeshData lamp;
        for (int gi = 0; gi < grid; ++gi)
            for (int gj = 0; gj < grid; ++gj) {
                MeshData cell = make_quad(Vec3f(-0.6f + 1.2f * gi / grid, 0.3f, -0.5f + 1.f * gj / grid),
                                          Vec3f(1.2f / grid, 0, 0), Vec3f(0, 0, 1.f / grid));  // normal -y
                if (gi == 0 && gj == 0) lamp = cell;
                else lamp.append(cell);
            }
        const std::vector<Vec3d> poly = {Vec3d(-0.6, 0.3, -0.5), Vec3d(0.6, 0.3, -0.5), Vec3d(0.6, 0.3, 0.5),
                                         Vec3d(-0.6, 0.3, 0.5)};
        ConstTex black({0, 0, 0}), rough({0.5f}), le({2.f, 2.f, 2.f});
        const Vec3f points[4] = {Vec3f(0, 0, 0), Vec3f(0.5f, 0.1f, 0.4f), Vec3f(1.2f, 0.f, -0.3f),
                                 Vec3f(30.f, -5.f, 10.f)};
        const Vec3f n(0, 1, 0);
        double variance[2][4] = {};
        for (int mode = 0; mode < 2; ++mode) {
            SceneDesc d;
            d.camera = camera(Vec3f(0, 0, -5), Vec3f(0, 0, 0), 8, 8, 45);
            d.materials.push_back(material(black, black, rough));
            d.meshes.push_back(lamp.desc(0));
            d.meshes[0].emission = le.desc();
            d.meshes[0].sample_spherical_triangle = mode == 0;
            auto scene = build_scene(d);
            Rng rng = Rng::for_sample(3, 0, 0);
            const int N = 100000;
            for (int i = 0; i < 4; ++i) {
                Acc acc;
                int checked = 0;
                for (int s = 0; s < N; ++s) {
                    LightSample ls;
                    const float u0 = rng.next_float(), u1 = rng.next_float(), u2 = rng.next_float();
                    if (!scene->sample_area_light(points[i], u0, u1, u2, ls)) {
                        acc.add(0.0);
                        continue;
                    }
                    const SurfacePoint q = scene->surface_point(ls.hit);
                    ASSERT_GT(dot(q.ng, -ls.dir), 0.f);
                    if (checked++ < 2000) {
                        EXPECT_NEAR(ls.pdf, scene->light_pdf(points[i], q), 2e-4f * ls.pdf);
                    }
                    acc.add(ls.radiance.x * std::max(0.f, dot(n, ls.dir)) / ls.pdf);
                }
                const double expect = 2.0 * polygon_irradiance(Vec3d(points[i]), Vec3d(n), poly);
                EXPECT_NEAR(acc.mean(), expect, 5 * acc.se() + 1e-6 * expect) << "mode " << mode << " point " << i;
                variance[mode][i] = acc.se() * acc.se() * N;

                // light_pdf over the directions of the light's bounding cone (radius 0.79 around
                // its centre; the whole sphere from inside it): the sum over the triangles of the
                // probability of landing on each, one.
                const Vec3d centre(0, 0.3, 0), pd(points[i]);
                const double dist = length(centre - pd), radius = 0.79;
                const double omc = dist > radius ? 1 - std::sqrt(1 - radius * radius / (dist * dist)) : 2.0;
                const Frame frame(Vec3f(normalize(centre - pd)));
                Acc integral;
                for (int s = 0; s < N; ++s) {
                    const float cos_t = 1.f - rng.next_float() * float(omc), phi = 2.f * kPi * rng.next_float();
                    const float sin_t = std::sqrt(std::max(0.f, 1.f - cos_t * cos_t));
                    const Vec3f w = frame.to_world(Vec3f(std::cos(phi) * sin_t, std::sin(phi) * sin_t, cos_t));
                    Hit h;
                    const bool hit = scene->intersect(Ray{points[i], w}, h);
                    integral.add(hit ? scene->light_pdf(points[i], scene->surface_point(h)) * 2 * M_PI * omc : 0.0);
                }
                EXPECT_NEAR(integral.mean(), 1.0, 5 * integral.se()) << "mode " << mode << " point " << i;
            }
        }
        for (int i = 0; i < 4; ++i)
            std::printf("%d x %d quads, point %d: variance %.4g by spherical triangles, %.4g by area\n", grid, grid, i,
                        variance[0][i], variance[1][i]);
        // The grid's triangles are picked by power, as area sampling picks them, and that pick's
        // noise dominates (measured: 0.90 to 0.91 of area sampling's variance; 0.016 to 0.043
        // for the whole quad).
        for (int i = 0; i < 3; ++i)
            EXPECT_LT(variance[0][i], (grid == 1 ? 0.2 : 0.95) * variance[1][i])
                << "point " << i << ": " << variance[0][i] << " by solid angle, " << variance[1][i] << " by area";
    }
}


// The side a lamp sampled by spherical triangles lights: from above a one-sided quad facing
// down no sample is drawn; made two-sided, the estimate there equals the closed form.
TEST(Render, SphericalTriangleLightSides) {
    MeshData lamp = make_quad(Vec3f(-0.6f, 0.3f, -0.5f), Vec3f(1.2f, 0, 0), Vec3f(0, 0, 1.f));  // normal -y
    const std::vector<Vec3d> poly = {Vec3d(-0.6, 0.3, -0.5), Vec3d(0.6, 0.3, -0.5), Vec3d(0.6, 0.3, 0.5),
                                     Vec3d(-0.6, 0.3, 0.5)};
    ConstTex black({0, 0, 0}), rough({0.5f}), le({2.f, 2.f, 2.f});
    const Vec3f p(0.2f, 0.7f, -0.1f), n(0, -1, 0);
    for (int two_sided = 0; two_sided < 2; ++two_sided) {
        SceneDesc d;
        d.camera = camera(Vec3f(0, 0, -5), Vec3f(0, 0, 0), 8, 8, 45);
        d.materials.push_back(material(black, black, rough));
        d.meshes.push_back(lamp.desc(0));
        d.meshes[0].emission = le.desc();
        d.meshes[0].two_sided_emission = two_sided == 1;
        d.meshes[0].sample_spherical_triangle = true;
        auto scene = build_scene(d);
        Rng rng = Rng::for_sample(4, 0, 0);
        const int N = 20000;
        double sum = 0, sum2 = 0;
        int drawn = 0;
        for (int s = 0; s < N; ++s) {
            LightSample ls;
            const float u0 = rng.next_float(), u1 = rng.next_float(), u2 = rng.next_float();
            if (!scene->sample_area_light(p, u0, u1, u2, ls)) continue;
            ++drawn;
            EXPECT_NEAR(ls.pdf, scene->light_pdf(p, scene->surface_point(ls.hit)), 2e-4f * ls.pdf);
            const double v = ls.radiance.x * std::max(0.f, dot(n, ls.dir)) / ls.pdf;
            sum += v;
            sum2 += v * v;
        }
        if (two_sided == 0) {
            EXPECT_EQ(drawn, 0);
            continue;
        }
        EXPECT_EQ(drawn, N);
        const double mean = sum / N, se = std::sqrt(std::max(0.0, sum2 / N - mean * mean) / N);
        EXPECT_NEAR(mean, 2.0 * polygon_irradiance(Vec3d(p), Vec3d(n), poly), 5 * se + 1e-9);
    }
}

// The primary edge pass traces the side paths of up to kPrimaryEdgeBatch edge samples together
// (render/batch.h) and splats the samples' jumps in their order afterwards: its gradients and
// derivative images are the same, bit for bit, as with every sample's paths traced on their own
// (batches of 1), for a pinhole, a thin lens, a fisheye and a panorama (several images of an edge
// point per sample), on the radiance alone and with a hit channel beside it, with diffuse
// (vectorised) and glossy vertices, an area light, a point light and an environment.
TEST(Render, PrimaryEdgeBatchesMatchOneByOne) {
    MeshData floor = make_quad(Vec3f(-3, -1, -3), Vec3f(0, 0, 6), Vec3f(6, 0, 0));
    MeshData ball = make_sphere(Vec3f(0.6f, -0.4f, 0.4f), 0.5f, 8, 16);
    MeshData box = make_box(Vec3f(-0.9f, -1, -0.6f), Vec3f(-0.2f, -0.3f, 0.1f));
    MeshData lamp = make_quad(Vec3f(-0.5f, 1.8f, -0.5f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));
    ConstTex kd({0.6f, 0.6f, 0.5f}), ks({0.3f, 0.3f, 0.3f}), r({0.3f}), black({0, 0, 0}), le({6.f, 6.f, 6.f});
    std::vector<float> sky(4 * 8 * 3);
    for (size_t i = 0; i < sky.size(); ++i) sky[i] = 0.1f + 0.05f * float(i % 7);
    SceneDesc d;
    d.camera = camera(Vec3f(0, 1.2f, 5), Vec3f(0, -0.3f, 0), 24, 18, 60);
    d.materials.push_back(material(kd, black, r));  // 0: diffuse (the vectors shade it)
    d.materials.push_back(material(kd, ks, r));     // 1: glossy
    d.materials.push_back(material(black, black, r));
    d.meshes.push_back(floor.desc(0));
    d.meshes.push_back(ball.desc(1));
    d.meshes.push_back(box.desc(0));
    d.meshes.push_back(lamp.desc(2));
    d.meshes[3].emission = le.desc();
    d.has_envmap = true;
    d.envmap.values = {sky.data(), 4, 8, 3};
    PointLightDesc bulb;
    bulb.position[0] = 1.5f;
    bulb.position[1] = 1.f;
    bulb.position[2] = 1.f;
    d.point_lights = {bulb};
    auto scene = build_scene(d);
    const int W = image_width(*scene), H = image_height(*scene);

    RenderOptions opt;
    opt.spp = 2;
    opt.seed = 3;
    opt.max_bounces = 3;
    opt.num_threads = 1;  // one sink: its sums in one order
    int checked = 0;
    for (CameraType type : {CameraType::Perspective, CameraType::ThinLens, CameraType::Fisheye, CameraType::Panorama}) {
        CameraDesc c = d.camera;
        c.type = type;
        if (type == CameraType::ThinLens) {
            c.aperture_radius = 0.15f;
            c.focus_distance = 4.f;
        }
        if (type == CameraType::Fisheye || type == CameraType::Panorama) c.fov = 180.f;
        scene->set_camera(c);
        for (bool with_depth : {false, true}) {
            const ChannelLayout layout = with_depth ? ChannelLayout({Channel::Radiance, Channel::Depth})
                                                    : ChannelLayout::radiance();
            const size_t nv = size_t(layout.num_values), pixels = size_t(W) * size_t(H);
            std::vector<float> adjoint(pixels * nv);
            for (size_t i = 0; i < adjoint.size(); ++i) adjoint[i] = float(std::sin(0.31 * double(i)) + 0.3);
            // Every vertex of every mesh and the camera; directions for the forward mode.
            std::vector<std::vector<float>> dirs(scene->meshes.size());
            std::vector<float> camera_dir(kCameraParams);
            for (size_t k = 0; k < camera_dir.size(); ++k) camera_dir[k] = float(std::cos(1.7 * double(k)));
            auto run = [&](int batch, bool reverse) {
                std::vector<std::vector<float>> grads(scene->meshes.size());
                std::vector<float> camera_grad(kCameraParams, 0.f), image(pixels * nv, 0.f);
                SceneGradients slots;
                slots.meshes.resize(scene->meshes.size());
                for (size_t m = 0; m < scene->meshes.size(); ++m) {
                    const size_t n3 = size_t(scene->meshes[m].num_vertices) * 3;
                    grads[m].assign(n3, 0.f);
                    dirs[m].resize(n3);
                    for (size_t k = 0; k < n3; ++k) dirs[m][k] = float(std::sin(0.7 * double(k) + double(m)));
                    if (reverse)
                        slots.meshes[m].vertices.grad = grads[m].data();
                    else
                        slots.meshes[m].vertices.dir = dirs[m].data();
                }
                if (reverse)
                    slots.camera.grad = camera_grad.data();
                else
                    slots.camera.dir = camera_dir.data();
                number_slots(slots);
                primary_edge_pass(*scene, opt, slots, layout, reverse ? adjoint.data() : nullptr,
                                  reverse ? nullptr : image.data(), batch);
                std::vector<float> all = camera_grad;
                for (const auto& g : grads) all.insert(all.end(), g.begin(), g.end());
                return reverse ? all : image;
            };
            for (bool reverse : {true, false}) {
                const std::string what = "camera " + std::to_string(int(type)) + (with_depth ? ", depth" : "") +
                                         (reverse ? ", gradients" : ", derivative image");
                const std::vector<float> one = run(1, reverse), batched = run(kPrimaryEdgeBatch, reverse),
                                         some = run(5, reverse);
                ASSERT_EQ(one.size(), batched.size());
                int differing = 0, nonzero = 0;
                for (size_t i = 0; i < one.size(); ++i) {
                    differing += std::memcmp(&one[i], &batched[i], sizeof(float)) != 0;
                    differing += std::memcmp(&one[i], &some[i], sizeof(float)) != 0;
                    nonzero += one[i] != 0.f;
                }
                EXPECT_EQ(differing, 0) << what;
                EXPECT_GT(nonzero, 10) << what << ": the pass found no edge";
                ++checked;
            }
        }
    }
    EXPECT_EQ(checked, 16);
    SceneGradients none;
    EXPECT_THROW(primary_edge_pass(*scene, opt, none, ChannelLayout::radiance(), nullptr, nullptr, 0),
                 std::invalid_argument);
    EXPECT_THROW(primary_edge_pass(*scene, opt, none, ChannelLayout::radiance(), nullptr, nullptr, kPrimaryEdgeBatch + 1),
                 std::invalid_argument);
}

}  // namespace
}  // namespace edgepath
