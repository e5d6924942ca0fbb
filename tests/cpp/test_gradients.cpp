// The gradient pass against finite differences of the renderer, and reverse mode against
// forward mode, on a scene with no visibility change (interior term only).
#include <gtest/gtest.h>
#include <algorithm>

#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "edgepath.h"
#include "scene/gradients.h"
#include "scene/scene.h"
#include "support/shapes.h"

namespace edgepath {
namespace {

// A wavy floor (grid, extends past the view) with a textured glossy material, an area light
// and an environment map, seen from above: no silhouette, no shadow boundary in view.
struct FloorScene {
    MeshData floor, lamp;
    std::vector<float> tex, spec, rough, black, le, env, lamp_rough;
    SceneDesc desc;

    explicit FloorScene(bool smooth_normals, bool sunny = false) {
        const int N = 8;
        for (int j = 0; j <= N; ++j)
            for (int i = 0; i <= N; ++i) {
                float x = -4.f + 8.f * i / N, z = -4.f + 8.f * j / N;
                floor.vertices.insert(floor.vertices.end(), {x, 0.1f * std::sin(1.3f * x + 0.7f * z), z});
                floor.uvs.insert(floor.uvs.end(), {float(i) / N, float(j) / N});
                if (smooth_normals) {
                    Vec3f n = normalize(Vec3f(-0.13f * std::cos(1.3f * x + 0.7f * z), 1.f, -0.07f * std::cos(1.3f * x + 0.7f * z)));
                    floor.normals.insert(floor.normals.end(), {n.x, n.y, n.z});
                }
            }
        for (int j = 0; j < N; ++j)
            for (int i = 0; i < N; ++i) {
                int a = j * (N + 1) + i, b = a + 1, c = a + N + 1, d = c + 1;
                floor.indices.insert(floor.indices.end(), {a, c, d, a, d, b});  // normals +y
            }
        // Behind and above the camera: lights the floor, never seen.
        lamp = make_quad(Vec3f(-0.5f, 4.f, 3.f), Vec3f(1.f, 0, 0), Vec3f(0, 0, 1.f));  // faces -y
        for (int k = 0; k < 4 * 4; ++k) tex.insert(tex.end(), {0.3f + 0.04f * k, 0.5f, 0.7f - 0.03f * k});
        spec = {0.3f, 0.3f, 0.3f};
        rough = {0.3f};
        black = {0, 0, 0};
        lamp_rough = {0.5f};
        le = {5.f, 4.f, 3.f};
        // A sky with one bright region, so that normals matter.
        for (int k = 0; k < 4 * 8; ++k) {
            float sun = (sunny && (k == 10 || k == 11)) ? 6.f : 0.f;
            env.insert(env.end(), {0.1f + 0.01f * k + sun, 0.15f + sun, 0.2f + sun});
        }
        MaterialDesc m;
        m.diffuse = {tex.data(), 4, 4, 3};
        m.specular = {spec.data(), 1, 1, 3};
        m.roughness = {rough.data(), 1, 1, 1};
        MaterialDesc ml;
        ml.diffuse = {black.data(), 1, 1, 3};
        ml.specular = {black.data(), 1, 1, 3};
        ml.roughness = {lamp_rough.data(), 1, 1, 1};
        desc.materials = {m, ml};
        desc.meshes = {floor.desc(0), lamp.desc(1)};
        desc.meshes[1].emission = {le.data(), 1, 1, 3};
        desc.has_envmap = true;
        desc.envmap.values = {env.data(), 4, 8, 3};
        CameraDesc& c = desc.camera;
        float pos[3] = {0.3f, 3.f, 1.5f}, at[3] = {0.f, 0.f, -0.2f};
        std::copy(pos, pos + 3, c.position);
        std::copy(at, at + 3, c.look_at);
        c.fov = 50;
        c.width = 24;
        c.height = 20;
    }
};

struct Param {
    const char* name;
    std::function<void(FloorScene&, double)> perturb;  // adds t * direction to the parameter
    std::function<void(SceneGradients&, std::vector<float>&)> direction;  // fills dir slot
    double eps = 1e-2;  // finite-difference step
};

std::vector<Param> params() {
    std::vector<Param> p;
    p.push_back({"diffuse texels",
                 [](FloorScene& s, double t) { for (size_t i = 0; i < s.tex.size(); ++i) s.tex[i] += float(t * ((i % 5) * 0.2 - 0.3)); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d.resize(48);
                     for (size_t i = 0; i < d.size(); ++i) d[i] = float((i % 5) * 0.2 - 0.3);
                     g.materials.resize(2);
                     g.materials[0].diffuse.dir = d.data();
                 }});
    p.push_back({"roughness",
                 [](FloorScene& s, double t) { s.rough[0] += float(t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d = {1.f};
                     g.materials.resize(2);
                     g.materials[0].roughness.dir = d.data();
                 }});
    p.push_back({"specular",
                 [](FloorScene& s, double t) { s.spec[0] += float(t); s.spec[1] += float(0.5 * t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d = {1.f, 0.5f, 0.f};
                     g.materials.resize(2);
                     g.materials[0].specular.dir = d.data();
                 }});
    p.push_back({"emission",
                 [](FloorScene& s, double t) { s.le[1] += float(t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d = {0.f, 1.f, 0.f};
                     g.meshes.resize(2);
                     g.meshes[1].emission.dir = d.data();
                 }});
    p.push_back({"envmap texels",
                 [](FloorScene& s, double t) { for (size_t i = 0; i < s.env.size(); i += 3) s.env[i] += float(t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d.assign(96, 0.f);
                     for (size_t i = 0; i < d.size(); i += 3) d[i] = 1.f;
                     g.envmap.dir = d.data();
                 }});
    // A bump: the 3x3 vertices around the centre of the floor move up.
    static const int bump[9] = {30, 31, 32, 39, 40, 41, 48, 49, 50};
    p.push_back({"interior vertex height",
                 [](FloorScene& s, double t) { for (int v : bump) s.floor.vertices[3 * v + 1] += float(t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d.assign(81 * 3, 0.f);
                     for (int v : bump) d[3 * v + 1] = 1.f;
                     g.meshes.resize(2);
                     g.meshes[0].vertices.dir = d.data();
                 }});
    p.push_back({"camera fov",
                 [](FloorScene& s, double t) { s.desc.camera.fov += float(t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d.assign(kCameraParams, 0.f);
                     d[9] = 1.f;
                     g.camera.dir = d.data();
                 }});
    p.push_back({"camera position",
                 [](FloorScene& s, double t) { s.desc.camera.position[0] += float(0.3 * t); s.desc.camera.position[1] += float(t); },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d.assign(kCameraParams, 0.f);
                     d[0] = 0.3f;
                     d[1] = 1.f;
                     g.camera.dir = d.data();
                 }});
    p.push_back({"envmap rotation",
                 [](FloorScene& s, double t) {  // about y by t radians
                     float c = float(std::cos(t)), sn = float(std::sin(t));
                     const float R[9] = {c, 0, sn, 0, 1, 0, -sn, 0, c};
                     std::copy(R, R + 9, s.desc.envmap.to_world);
                 },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d = {0, 0, 1, 0, 0, 0, -1, 0, 0};
                     g.envmap_rotation.dir = d.data();
                 },
                 // The sampled sky directions turn with the map: the few that cross the outline
                 // of the lamp (which shades part of the sky) switch between lit and shadowed and
                 // move the finite difference by their whole contribution / eps. A longer step
                 // makes these jumps rarer relative to the signal (their variance goes as
                 // 1 / eps); the central difference's own error (eps^2) stays negligible.
                 5e-2});
    // The camera turned to the sky: only the environment map is seen, through moving directions.
    p.push_back({"camera look_at (sky in view)",
                 [](FloorScene& s, double t) {
                     const float at[3] = {0.3f + float(t), 10.f, -0.5f + float(0.5 * t)};
                     std::copy(at, at + 3, s.desc.camera.look_at);
                 },
                 [](SceneGradients& g, std::vector<float>& d) {
                     d.assign(kCameraParams, 0.f);
                     d[3] = 1.f;
                     d[5] = 0.5f;
                     g.camera.dir = d.data();
                 }});
    return p;
}

// A fixed weighting of the image (ramps in x and y): a scalar that does not cancel when the
// image shifts or scales.
double image_sum(const std::vector<float>& img) {
    double s = 0;
    for (size_t i = 0; i < img.size(); ++i) {
        size_t pixel = i / 3;
        double x = double(pixel % 24) / 24 - 0.5, y = double(pixel / 24) / 20 - 0.5;
        s += img[i] * (1 + 1.5 * x - 1.0 * y);
    }
    return s;
}

// Derivative image (forward mode) against central finite differences of rendered images, over
// independent seeds: the image sums must agree within their statistical error, and the
// derivative must be clearly non-zero (so that a missing gradient fails).
void check_param(bool smooth, const Param& p, double eps, bool geometric) {
    RenderOptions opt;
    opt.spp = 4;
    opt.max_bounces = 2;
    if (geometric) {
        opt.spp = 16;
        // With fixed random numbers, a BSDF-sampled ray that starts or stops hitting the lamp
        // makes the finite difference of a moving geometry very noisy; light sampling alone
        // keeps every sample smooth in the parameter (the derivative is the same in expectation).
        opt.max_bounces = 1;
        opt.sampling = LightSampling::LightOnly;
    }
    // With every direction after the camera held fixed, moving a shading point also moves the
    // outline of a nearby area light across the sampled directions: a boundary term (secondary
    // edges). An environment map has no such outline, so geometric parameters are tested under
    // the environment alone. Nor may anything shade it: the lamp (black, but still in the sky)
    // is taken out, and the sky is dark below 45 degrees of elevation (its bright patch moved
    // up), so that no sampled direction grazes the wavy floor, which shades itself within 7.4
    // degrees of the horizon. Otherwise a sample of the finite difference now and then jumps
    // by its whole value over the step, while the derivative adds the boundary term smoothly:
    // over 64 seeds the camera's fov had d - fd +0.07 to +0.18 (of 3.9) at 62 and -1.8 and
    // -2.6 at two, and 16 seeds could miss both (a mean of 0.11 +- 0.006). Without the
    // lamp and the low sky, 0.00003 +- 0.00006 (of 1.13). Where the camera sees the sky, its
    // pixels carry the signal and the sky stays as it is.
    auto prepare = [&](FloorScene& s) {
        if (!geometric) return;
        s.le = {0.f, 0.f, 0.f};
        if (std::string(p.name).find("sky") != std::string::npos) return;
        s.desc.meshes.resize(1);
        for (int k = 8; k < 32; ++k)
            for (int c = 0; c < 3; ++c) s.env[size_t(3 * k + c)] = 0.f;
        for (int k : {2, 3})
            for (int c = 0; c < 3; ++c) s.env[size_t(3 * k + c)] += 6.f;
    };
    const int runs = geometric ? 16 : 10;
    double sd = 0, sd2 = 0, sf = 0, sf2 = 0;
    const size_t n = 24 * 20 * 3;
    std::vector<float> ip(n), im(n), D(n);
    for (int r = 0; r < runs; ++r) {
        opt.seed = 77 + r;
        FloorScene plus(smooth, geometric), minus(smooth, geometric), base(smooth, geometric);
        prepare(plus);
        prepare(minus);
        prepare(base);
        p.perturb(plus, 0.5 * eps);
        p.perturb(minus, -0.5 * eps);
        p.perturb(base, 0.0);
        render(*build_scene(plus.desc), opt, ip.data());
        render(*build_scene(minus.desc), opt, im.data());
        double fd = (image_sum(ip) - image_sum(im)) / eps;
        SceneGradients g;
        std::vector<float> dir;
        p.direction(g, dir);
        derivative_image(*build_scene(base.desc), opt, g, D.data());
        double d = image_sum(D);
        double delta = d - fd;
        sd += delta;
        sd2 += delta * delta;
        sf += fd;
        sf2 += fd * fd;
    }
    double md = sd / runs, se_d = std::sqrt(std::max(0.0, sd2 / runs - md * md) / (runs - 1));
    double mf = sf / runs, se_f = std::sqrt(std::max(0.0, sf2 / runs - mf * mf) / (runs - 1));
    std::printf("%-32s derivative - fd %10.4g +- %8.3g   fd %10.4g +- %8.3g\n", p.name, md, se_d, mf, se_f);
    EXPECT_GT(std::abs(mf), 5 * se_f) << p.name << ": the finite difference is too noisy to test anything";
    EXPECT_LT(std::abs(md), 5 * se_d + 1e-3 * std::abs(mf)) << p.name << ": derivative - finite difference = " << md
                                                               << " (finite difference " << mf << ")";
}

TEST(Gradients, DerivativeImagesMatchFiniteDifferences) {
    for (bool smooth : {false, true})
        for (const Param& p : params()) {
            std::string name = p.name;
            bool geometric = name.find("camera") != std::string::npos || name.find("vertex") != std::string::npos;
            // A flat-shaded mesh has creases: moving a vertex or the camera moves them across
            // pixels, a boundary term this interior-only test does not include.
            if (geometric && !smooth) continue;
            SCOPED_TRACE(smooth ? "smooth normals" : "flat");
            check_param(smooth, p, p.eps, geometric);
        }
}

TEST(Gradients, ReverseModeEqualsForwardMode) {
    // For the same seed the two modes differentiate the same paths: sum(a * dI/dtheta) must equal
    // the reverse gradient dotted with the direction, to rounding.
    RenderOptions opt;
    opt.spp = 2;
    opt.max_bounces = 2;
    opt.seed = 5;
    const size_t n = 24 * 20 * 3;
    std::vector<float> adj(n), D(n);
    for (size_t i = 0; i < n; ++i) adj[i] = float(std::sin(0.37 * i) + 0.2);
    for (const Param& p : params()) {
        FloorScene base(true, true);
        p.perturb(base, 0.0);
        auto scene = build_scene(base.desc);
        SceneGradients fwd;
        std::vector<float> dir;
        p.direction(fwd, dir);
        derivative_image(*scene, opt, fwd, D.data());
        double a_dot_d = 0;
        for (size_t i = 0; i < n; ++i) a_dot_d += double(adj[i]) * D[i];
        // Reverse: the same slots as buffers.
        SceneGradients rev = fwd;
        std::vector<float> buf(dir.size(), 0.f);
        auto to_grad = [&](GradSlot& s) {
            if (s.dir) {
                s.dir = nullptr;
                s.grad = buf.data();
            }
        };
        for (auto& m : rev.meshes) { to_grad(m.vertices); to_grad(m.uvs); to_grad(m.normals); to_grad(m.emission); }
        for (auto& m : rev.materials) { to_grad(m.diffuse); to_grad(m.specular); to_grad(m.roughness); }
        to_grad(rev.envmap);
        to_grad(rev.envmap_rotation);
        to_grad(rev.camera);
        render_gradients(*scene, opt, adj.data(), rev);
        double g_dot_dir = 0;
        for (size_t i = 0; i < dir.size(); ++i) g_dot_dir += double(buf[i]) * dir[i];
        EXPECT_NEAR(a_dot_d, g_dot_dir, 1e-3 * (std::abs(a_dot_d) + 1e-3)) << p.name;
    }
}

// Every gradient buffer, and a derivative image, the same bit for bit on one thread and on two
// (the additions of each tile, and of each chunk of the camera's edge samples, are made in their
// order: OrderedAdds).
TEST(Gradients, SameBitForBitWhateverTheThreadCount) {
    FloorScene base(true, true);
    base.desc.camera.width = 64;  // 4 x 3 tiles
    base.desc.camera.height = 40;
    auto scene = build_scene(base.desc);
    const size_t n = 64 * 40 * 3;
    std::vector<float> adj(n);
    for (size_t i = 0; i < n; ++i) adj[i] = float(std::sin(0.37 * double(i)) + 0.2);
    struct Buffers {
        std::vector<float> verts, normals, diffuse, specular, rough, emission, env, camera;
    };
    auto run = [&](int threads, Buffers& b) {
        b.verts.assign(base.floor.vertices.size(), 0.f);
        b.normals.assign(base.floor.normals.size(), 0.f);
        b.diffuse.assign(base.tex.size(), 0.f);
        b.specular.assign(3, 0.f);
        b.rough.assign(1, 0.f);
        b.emission.assign(3, 0.f);
        b.env.assign(base.env.size(), 0.f);
        b.camera.assign(kCameraParams, 0.f);
        SceneGradients g;
        g.meshes.resize(2);
        g.meshes[0].vertices.grad = b.verts.data();
        g.meshes[0].normals.grad = b.normals.data();
        g.meshes[1].emission.grad = b.emission.data();
        g.materials.resize(2);
        g.materials[0].diffuse.grad = b.diffuse.data();
        g.materials[0].specular.grad = b.specular.data();
        g.materials[0].roughness.grad = b.rough.data();
        g.envmap.grad = b.env.data();
        g.camera.grad = b.camera.data();
        number_slots(g);
        RenderOptions opt;
        opt.spp = 4;
        opt.max_bounces = 2;
        opt.seed = 9;
        opt.num_threads = threads;
        render_gradients(*scene, opt, adj.data(), g);
    };
    Buffers one, two, again;
    run(1, one);
    run(2, two);
    run(2, again);
    double total = 0.0;
    for (float v : one.verts) total += std::abs(v);
    EXPECT_GT(total, 0.0);
    for (const Buffers* b : {&two, &again}) {
        EXPECT_EQ(one.verts, b->verts);
        EXPECT_EQ(one.normals, b->normals);
        EXPECT_EQ(one.diffuse, b->diffuse);
        EXPECT_EQ(one.specular, b->specular);
        EXPECT_EQ(one.rough, b->rough);
        EXPECT_EQ(one.emission, b->emission);
        EXPECT_EQ(one.env, b->env);
        EXPECT_EQ(one.camera, b->camera);
    }
    // Forward mode: a derivative image along the floor's vertices.
    std::vector<float> dir(base.floor.vertices.size());
    for (size_t i = 0; i < dir.size(); ++i) dir[i] = float(std::cos(0.11 * double(i)));
    auto image = [&](int threads) {
        SceneGradients g;
        g.meshes.resize(2);
        g.meshes[0].vertices.dir = dir.data();
        RenderOptions opt;
        opt.spp = 4;
        opt.max_bounces = 1;
        opt.seed = 3;
        opt.num_threads = threads;
        std::vector<float> out(n, 0.f);
        derivative_image(*scene, opt, g, out.data());
        return out;
    };
    const std::vector<float> d1 = image(1);
    EXPECT_EQ(d1, image(2));
    EXPECT_EQ(d1, image(2));
}

// The secondary term's roulette floor must lie in (0, 1]: anything else is refused by name.
TEST(Gradients, SecondarySurvivalOutsideZeroOneIsRefused) {
    FloorScene base(true, true);
    auto scene = build_scene(base.desc);
    const size_t n = 24 * 20 * 3;
    std::vector<float> adj(n, 1.f), D(n);
    SceneGradients none;
    for (float bad : {0.f, -0.5f, 1.5f, std::nanf("")}) {
        RenderOptions opt;
        opt.spp = 1;
        opt.secondary_survival = bad;
        try {
            render_gradients(*scene, opt, adj.data(), none);
            ADD_FAILURE() << "accepted secondary_survival " << bad;
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find("secondary_survival"), std::string::npos) << e.what();
        }
        EXPECT_THROW(derivative_image(*scene, opt, none, D.data()), std::invalid_argument);
    }
}

}  // namespace
}  // namespace edgepath

namespace edgepath {
namespace {

// Two parameters whose addresses share a cache entry, both hit by every sample (a camera
// parameter and a vertex, say): each keeps its sum in double precision until the flush, rather
// than the two evicting each other and adding every partial sum to the float buffer.
TEST(GradSink, CollidingParametersKeepDoublePrecision) {
    std::vector<float> buffer(1024, 0.f);
    GradSlot a, b;
    a.grad = buffer.data();
    b.grad = buffer.data() + 256;  // 1 KiB on: the same home entry
    {
        GradSink sink(false);
        for (int i = 0; i < 200000; ++i) {
            sink.add(a, 0, 0.1f);
            sink.add(b, 0, -0.1f);
        }
    }
    // Float sums of 200000 terms of 0.1 drift by far more than this.
    EXPECT_NEAR(buffer[0], 200000 * double(0.1f), 0.01);
    EXPECT_NEAR(buffer[256], -200000 * double(0.1f), 0.01);
}


// Work items committed out of order are applied in their order: the float sums are those of the
// items in order, which rounding tells apart from any other order here.
TEST(OrderedAdds, AppliesItemsInTheirOrderWhateverTheOrderOfCommits) {
    // Item i adds x_i to the one value; 1e8 + 1 - 1e8 is 0 in float, 1e8 - 1e8 + 1 is 1.
    const float x[4] = {1e8f, 1.f, -1e8f, 1.f};
    auto run = [&](const std::vector<int>& order) {
        float value = 0.f;
        OrderedAdds adds;
        size_t held = 0;
        for (int i : order) {
            GradLog log{{&value, x[i]}};
            adds.commit(i, log);
            EXPECT_TRUE(log.empty());
            held = std::max(held, adds.held());
        }
        EXPECT_EQ(adds.applied(), 4);
        EXPECT_EQ(adds.held(), 0u);
        return std::make_pair(value, held);
    };
    const float in_order = ((0.f + 1e8f) + 1.f) + -1e8f + 1.f;
    EXPECT_EQ(run({0, 1, 2, 3}).first, in_order);
    EXPECT_EQ(run({0, 1, 2, 3}).second, 0u);
    for (const std::vector<int>& order : {std::vector<int>{3, 2, 1, 0}, {2, 0, 3, 1}, {1, 3, 2, 0}}) {
        const auto r = run(order);
        EXPECT_EQ(r.first, in_order);
        EXPECT_GT(r.second, 0u);
    }
    // The other orders' sums differ: the test would see a wrong order.
    EXPECT_NE(((0.f + 1e8f) + -1e8f) + 1.f + 1.f, in_order);
}

// An ordered sink adds nothing to the buffers before its commit, and a work item's additions do
// not depend on what the sink saw before (its cache, and which entry it evicts next, start
// afresh after each commit).
TEST(GradSink, OrderedSinkCommitsTheSameAdditionsForAnItemWhateverCameBefore) {
    std::vector<float> a(4096, 0.f), b(4096, 0.f);
    GradSlot slot_a, slot_b;
    slot_a.grad = a.data();
    slot_b.grad = b.data();
    // One item: more parameters than the cache holds, each added to many times, so that which
    // entries are evicted when changes the partial sums.
    auto item = [](GradSink& sink, const GradSlot& slot, int seed, int n) {
        for (int i = 0; i < n; ++i) sink.add(slot, (i * 7919 + seed) % 700, 0.1f + 1e-3f * float(i % 13));
    };
    OrderedAdds adds_a, adds_b;
    GradSink first(false, true), second(false, true);
    // Sink `first` runs another item before; `second` runs this one alone.
    item(first, slot_a, 1, 19999);
    EXPECT_EQ(*std::max_element(a.begin(), a.end()), 0.f);  // nothing before the commit
    first.commit(adds_a, 0);
    std::fill(a.begin(), a.end(), 0.f);
    item(first, slot_a, 2, 20000);
    first.commit(adds_a, 1);
    item(second, slot_b, 2, 20000);
    second.commit(adds_b, 0);
    EXPECT_EQ(a, b);
    EXPECT_GT(*std::max_element(b.begin(), b.end()), 0.f);
}

}  // namespace
}  // namespace edgepath
