// Derivative images sweep each path once for the three colours (backprop_path_colours, scalar
// adjoints one lane per colour). Here against the three sweeps it replaces: backprop_path with
// the unit adjoint of each colour, the edge terms sampled by the first and replayed by the
// others, for every kind of parameter on a scene that reaches every adjoint of the sweep.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "diff/backprop.h"
#include "edges/secondary.h"
#include "edgepath.h"
#include "render/packet.h"
#include "render/path.h"
#include "scene/gradients.h"
#include "scene/scene.h"
#include "support/shapes.h"
#include "all_adjoints_scene.h"

namespace edgepath {
namespace {

TEST(ColourSweep, EqualsThreeSweepsForEveryParameter) {
    AllAdjointsScene s;
    auto scene = build_scene(s.desc);
    RenderOptions opt;
    opt.max_bounces = 3;
    opt.spp = 2;
    const float w = 1.f / float(opt.spp);
    for (const Group& grp : groups(s)) {
        SCOPED_TRACE(grp.name);
        std::vector<float> dir;
        SceneGradients g = directions_of(grp, dir);
        SecondaryEdges secondary(*scene, opt, g);
        const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
        GradSink sink(true);
        EdgeTermLog log, scratch;
        PathRecord rec;
        RayCounters counters;
        std::vector<double> ref, got;
        for (int y = 0; y < s.desc.camera.height; ++y)
            for (int x = 0; x < s.desc.camera.width; ++x)
                for (int k = 0; k < opt.spp; ++k) {
                    record_camera_path(*scene, opt, opt.seed, camera_sample(*scene, opt.seed, x, y, k), rec, counters);
                    // The three sweeps derivative images made before: colour by colour, the
                    // edge terms sampled by the first and replayed by the others.
                    log.replaying = false;
                    for (int col = 0; col < 3; ++col) {
                        Vec3f e(0.f);
                        e[col] = w;
                        backprop_path(*scene, g, rec, e, sink, sec, sec ? &log : nullptr);
                        log.replaying = true;
                        ref.push_back(sink.take_projection());
                    }
                    backprop_path_colours(*scene, g, rec, w, sink, sec, sec ? &scratch : nullptr);
                    double p[3];
                    sink.take_projections(p);
                    got.insert(got.end(), p, p + 3);
                    EXPECT_EQ(sink.take_projection(), 0.0);  // nothing into the one-value projection
                }
        double scale = 0.0;
        for (double v : ref) scale = std::max(scale, std::abs(v));
        // The parameter is reached (so that a missing adjoint could fail here).
        EXPECT_GT(scale, 1e-6) << "no path reaches " << grp.name;
        int bad = 0;
        for (size_t i = 0; i < ref.size(); ++i)
            if (!(std::abs(got[i] - ref[i]) <= 1e-6 * std::abs(ref[i]) + 1e-9 * scale)) {
                if (bad++ < 5)
                    ADD_FAILURE() << "sample " << i / 3 << " colour " << i % 3 << ": one sweep " << got[i]
                                  << ", three sweeps " << ref[i];
            }
        EXPECT_EQ(bad, 0);
    }
}

// The whole pass: each colour of the derivative image (every parameter group's direction at
// once), summed over the image, against the reverse-mode gradient for the unit adjoint of that
// colour at every pixel, dotted with the directions (the same paths, the same edge samples).
TEST(ColourSweep, EachColourEqualsReverseModeWithItsUnitAdjoint) {
    AllAdjointsScene s;
    auto scene = build_scene(s.desc);
    RenderOptions opt;
    opt.max_bounces = 3;
    opt.spp = 2;
    opt.seed = 9;
    const std::vector<Group> all = groups(s);
    SceneGradients fwd, rev;
    for (SceneGradients* g : {&fwd, &rev}) {
        g->meshes.resize(5);
        g->materials.resize(5);
        g->point_lights.resize(1);
    }
    std::vector<std::vector<float>> dirs, bufs;
    for (const Group& grp : all) {
        dirs.emplace_back(size_t(grp.n));
        for (size_t i = 0; i < dirs.back().size(); ++i) dirs.back()[i] = float(std::sin(0.7 * double(i) + 0.3));
        bufs.emplace_back(size_t(grp.n), 0.f);
    }
    for (size_t k = 0; k < all.size(); ++k) {
        all[k].slot(fwd).dir = dirs[k].data();
        all[k].slot(rev).grad = bufs[k].data();
    }
    number_slots(rev);
    const size_t n = size_t(s.desc.camera.width) * size_t(s.desc.camera.height) * 3;
    std::vector<float> D(n), adj(n);
    derivative_image(*scene, opt, fwd, D.data());
    for (int c = 0; c < 3; ++c) {
        SCOPED_TRACE("colour " + std::to_string(c));
        double forward = 0.0;
        for (size_t i = size_t(c); i < n; i += 3) forward += D[i];
        for (size_t i = 0; i < n; ++i) adj[i] = i % 3 == size_t(c) ? 1.f : 0.f;
        for (auto& b : bufs) std::fill(b.begin(), b.end(), 0.f);
        render_gradients(*scene, opt, adj.data(), rev);
        double reverse = 0.0;
        for (size_t k = 0; k < all.size(); ++k)
            for (size_t i = 0; i < bufs[k].size(); ++i) reverse += double(bufs[k][i]) * dirs[k][i];
        EXPECT_GT(std::abs(forward), 1e-3);
        EXPECT_NEAR(forward, reverse, 1e-4 * std::abs(forward)) << "forward " << forward << " reverse " << reverse;
    }
}

// The sweep leaves out the adjoint of the vertices' positions (finish_hit's geometric normal,
// point and intersection) where nothing wanted needs it: no camera, no vertices of a mesh the
// path met before, no smooth bounce before (past a mirror or glass the next vertex moves with the
// bounce's normal and index). For every parameter group alone (the glass made smooth), its
// projection equals, bit for bit, the one with the camera wanted too in a zero direction (which
// keeps every position's adjoint: what it adds to the projection is zero), path by path, with
// the interior term of 3 bounces.
TEST(ColourSweep, PositionsLeftOutOnlyWhereNothingWantedNeedsThem) {
    AllAdjointsScene s;
    s.glass_rough[0] = 0.f;  // smooth glass: its index moves the vertices past it
    auto scene = build_scene(s.desc);
    RenderOptions opt;
    opt.max_bounces = 3;
    opt.spp = 2;
    opt.seed = 4;
    const std::vector<float> zero(kCameraParams, 0.f);
    int reached = 0;
    for (const Group& grp : groups(s)) {
        if (grp.name == "camera") continue;
        SCOPED_TRACE(grp.name);
        std::vector<float> dir;
        const SceneGradients alone = directions_of(grp, dir);
        SceneGradients with_camera = alone;
        with_camera.camera.dir = zero.data();
        GradSink sink(true);
        PathRecord rec;
        RayCounters counters;
        int differing = 0;
        double largest = 0.0;
        for (int y = 0; y < s.desc.camera.height; ++y)
            for (int x = 0; x < s.desc.camera.width; ++x)
                for (int k = 0; k < opt.spp; ++k) {
                    record_camera_path(*scene, opt, opt.seed, camera_sample(*scene, opt.seed, x, y, k), rec, counters);
                    backprop_path(*scene, alone, rec, Vec3f(1.f), sink, nullptr);
                    const double a = sink.take_projection();
                    backprop_path(*scene, with_camera, rec, Vec3f(1.f), sink, nullptr);
                    const double b = sink.take_projection();
                    differing += std::memcmp(&a, &b, sizeof a) != 0;
                    largest = std::max(largest, std::abs(a));
                }
        EXPECT_EQ(differing, 0);
        reached += largest > 1e-6;
    }
    EXPECT_GE(reached, 20);  // the groups the interior term reaches (so that a difference could show)
}

}  // namespace
}  // namespace edgepath
