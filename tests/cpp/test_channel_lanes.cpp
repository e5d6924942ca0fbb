// Derivative images of the output channels compute a sample's hit values all at once
// (d_hit_channel_values: a lane per value, math/adjoint.h's AdjN). Here against what they did
// before, kept as the reference: d_hit_channels once per value with the adjoint of that value
// alone, for every parameter group of a scene that reaches every adjoint (textured diffuse,
// roughness and normal map, vertex colours, plastic, mirror, glass, camera), through a pinhole
// and a thin lens (and the other cameras), and for layouts of 4 to 28 lanes with radiance among
// the values.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "all_adjoints_scene.h"
#include "diff/channels.h"
#include "edgepath.h"
#include "render/channels.h"
#include "render/packet.h"
#include "render/path.h"
#include "scene/gradients.h"
#include "scene/scene.h"

namespace edgepath {
namespace {

const std::vector<Channel> kEveryValue = {Channel::Alpha,        Channel::Depth,       Channel::Position,
                                          Channel::GeometryNormal, Channel::ShadingNormal, Channel::Uv,
                                          Channel::Albedo,       Channel::Barycentrics, Channel::VertexColor,
                                          Channel::Roughness,    Channel::Specular,    Channel::Radiance};

// Every sample's values by both ways for one parameter group; returns the number of values that
// differ by more than float rounding (and, through `exact`, how many agree bit for bit).
int compare(const Scene& scene, const AllAdjointsScene& s, const Group& grp, const ChannelLayout& layout,
            int& exact, int& total, double& scale) {
    RenderOptions opt;
    opt.max_bounces = 1;
    opt.spp = 2;
    const float w = 1.f / float(opt.spp);
    std::vector<float> dir;
    SceneGradients g = directions_of(grp, dir);
    const int nv = layout.num_values, ro = layout.offset[int(Channel::Radiance)];
    GradSink sink(true);
    PathRecord rec;
    RayCounters counters;
    std::vector<double> ref, got;
    for (int y = 0; y < s.desc.camera.height; ++y)
        for (int x = 0; x < s.desc.camera.width; ++x)
            for (int k = 0; k < opt.spp; ++k) {
                record_camera_path(scene, opt, opt.seed, camera_sample(scene, opt.seed, x, y, k), rec, counters);
                if (rec.camera_missed) continue;
                const PathVertexRecord& v = rec.vertices[0];
                Ray ray;
                ray.origin = v.origin;
                ray.dir = v.dir;
                // The reference: one call per value, the adjoint w at that value alone.
                float e[kMaxChannelValues] = {};
                for (int j = 0; j < nv; ++j) {
                    if (ro >= 0 && j >= ro && j < ro + 3) {
                        ref.push_back(0.0);
                        continue;
                    }
                    e[j] = w;
                    d_hit_channels(scene, layout, g, rec.film, rec.lens, ray, v.hit, e, sink);
                    e[j] = 0.f;
                    ref.push_back(sink.take_projection());
                }
                double p[kMaxChannelValues];
                for (double& q : p) q = std::nan("");
                d_hit_channel_values(scene, layout, g, rec.film, rec.lens, ray, v.hit, w, sink, p);
                got.insert(got.end(), p, p + nv);
                EXPECT_EQ(sink.take_projection(), 0.0);  // nothing into the one-value projection
            }
    for (double r : ref) scale = std::max(scale, std::abs(r));
    int bad = 0;
    for (size_t i = 0; i < ref.size(); ++i) {
        ++total;
        if (got[i] == ref[i]) ++exact;
        if (!(std::abs(got[i] - ref[i]) <= 1e-6 * std::abs(ref[i]) + 1e-9 * scale)) {
            if (bad++ < 5)
                ADD_FAILURE() << grp.name << ": sample " << i / size_t(nv) << " value " << i % size_t(nv)
                              << ": one pass " << got[i] << ", one call per value " << ref[i];
        }
    }
    return bad;
}

TEST(ChannelLanes, EqualsOneCallPerValueForEveryParameter) {
    for (CameraType type : {CameraType::Perspective, CameraType::ThinLens}) {
        SCOPED_TRACE(type == CameraType::ThinLens ? "thin lens" : "pinhole");
        AllAdjointsScene s;
        s.desc.camera.type = type;
        s.desc.camera.aperture_radius = 0.2f;
        s.desc.camera.focus_distance = 3.5f;
        auto scene = build_scene(s.desc);
        const ChannelLayout layout(kEveryValue);
        ASSERT_EQ(layout.num_values, 28);
        int exact = 0, total = 0;
        for (const Group& grp : groups(s)) {
            double scale = 0.0;
            EXPECT_EQ(compare(*scene, s, grp, layout, exact, total, scale), 0) << grp.name;
            // Only the emitters and the environment's are out of the channels' reach.
            const bool reached = grp.name.find("lamp") == std::string::npos &&
                                 grp.name.find("point light") == std::string::npos &&
                                 grp.name.find("envmap") == std::string::npos && grp.name.find("ior") == std::string::npos;
            if (reached) {
                EXPECT_GT(scale, 1e-6) << "no value reaches " << grp.name;
            }
        }
        // Each lane runs the float operations of its own call: the same bits.
        EXPECT_EQ(exact, total);
    }
}

// The other cameras (orthographic, fisheye, panorama: the camera ray's adjoint in lanes takes
// their own branches), for the camera's parameters and the floor's vertices.
TEST(ChannelLanes, OtherCameras) {
    for (CameraType type : {CameraType::Orthographic, CameraType::Fisheye, CameraType::Panorama}) {
        SCOPED_TRACE("camera type " + std::to_string(int(type)));
        AllAdjointsScene s;
        s.desc.camera.type = type;
        s.desc.camera.ortho_scale = 2.5f;
        if (type == CameraType::Fisheye) s.desc.camera.fov = 160.f;
        auto scene = build_scene(s.desc);
        const ChannelLayout layout(kEveryValue);
        int exact = 0, total = 0;
        for (const Group& grp : groups(s)) {
            if (grp.name != "camera" && grp.name != "floor vertices") continue;
            double scale = 0.0;
            EXPECT_EQ(compare(*scene, s, grp, layout, exact, total, scale), 0) << grp.name;
            EXPECT_GT(scale, 1e-6) << "no value reaches " << grp.name;
        }
        EXPECT_EQ(exact, total);
    }
}

// Fewer values (4, 8 and 16 lanes), radiance first, in the middle or absent.
TEST(ChannelLanes, SmallerLayouts) {
    AllAdjointsScene s;
    auto scene = build_scene(s.desc);
    const std::vector<std::vector<Channel>> layouts = {
        {Channel::Specular, Channel::Roughness},
        {Channel::Radiance, Channel::Depth, Channel::Uv, Channel::Alpha},
        {Channel::Albedo, Channel::Radiance, Channel::ShadingNormal, Channel::VertexColor, Channel::Barycentrics},
    };
    const std::vector<Group> all = groups(s);
    for (const auto& list : layouts) {
        const ChannelLayout layout(list);
        SCOPED_TRACE(std::to_string(layout.num_values) + " values");
        int exact = 0, total = 0;
        for (const Group& grp : all) {
            if (grp.name != "floor vertices" && grp.name != "floor uvs" && grp.name != "floor normal map" &&
                grp.name != "floor colours" && grp.name != "floor roughness" && grp.name != "camera")
                continue;
            double scale = 0.0;
            EXPECT_EQ(compare(*scene, s, grp, layout, exact, total, scale), 0) << grp.name;
            // Every layout's values move with the vertices, the uvs and the camera.
            if (grp.name == "floor vertices" || grp.name == "floor uvs" || grp.name == "camera") {
                EXPECT_GT(scale, 1e-6) << "no value reaches " << grp.name;
            }
        }
        EXPECT_EQ(exact, total);
    }
}

}  // namespace
}  // namespace edgepath
