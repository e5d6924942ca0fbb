// Output channels (render/channels.h): the layout, the first-hit values against a sphere's closed
// form, their adjoint against finite differences, render_channels against render, the box
// filter's half-open support.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "diff/channels.h"
#include "edgepath.h"
#include "render/channels.h"
#include "render/path.h"
#include "scene/filter.h"
#include "scene/gradients.h"
#include "scene/scene.h"
#include "support/shapes.h"

namespace edgepath {
namespace {

const std::vector<Channel> kContinuous = {Channel::Alpha,          Channel::Depth,         Channel::Position,
                                          Channel::GeometryNormal, Channel::ShadingNormal, Channel::Uv,
                                          Channel::Albedo,         Channel::Barycentrics,  Channel::VertexColor,
                                          Channel::Roughness,      Channel::Specular};

TextureDesc texture(const std::vector<float>& v, int height, int width, int channels) {
    TextureDesc t;
    t.data = v.data();
    t.height = height;
    t.width = width;
    t.channels = channels;
    return t;
}

struct SceneArrays {
    std::vector<float> diffuse{0.2f, 0.4f, 0.6f}, specular{0.f, 0.f, 0.f}, roughness{0.5f};
    SceneDesc desc;
    SceneArrays(const MeshData& mesh, const Vec3f& eye, int width, int height, float fov) {
        desc.camera.position[0] = eye.x;
        desc.camera.position[1] = eye.y;
        desc.camera.position[2] = eye.z;
        desc.camera.look_at[0] = desc.camera.look_at[1] = desc.camera.look_at[2] = 0.f;
        desc.camera.width = width;
        desc.camera.height = height;
        desc.camera.fov = fov;
        MaterialDesc m;
        m.diffuse = texture(diffuse, 1, 1, 3);
        m.specular = texture(specular, 1, 1, 3);
        m.roughness = texture(roughness, 1, 1, 1);
        desc.materials.push_back(m);
        desc.meshes.push_back(mesh.desc(0));
    }
};

TEST(Channels, LayoutPacksContinuousChannelsAndIdsApart) {
    ChannelLayout l({Channel::TriangleId, Channel::Depth, Channel::Radiance, Channel::MeshId, Channel::Uv});
    EXPECT_EQ(l.num_values, 1 + 3 + 2);
    EXPECT_EQ(l.num_ids, 2);
    EXPECT_EQ(l.offset[int(Channel::Depth)], 0);
    EXPECT_EQ(l.offset[int(Channel::Radiance)], 1);
    EXPECT_EQ(l.offset[int(Channel::Uv)], 4);
    EXPECT_EQ(l.offset[int(Channel::TriangleId)], 0);
    EXPECT_EQ(l.offset[int(Channel::MeshId)], 1);
    EXPECT_FALSE(l.has(Channel::Alpha));
    EXPECT_TRUE(l.has_hit_values());
    EXPECT_FALSE(ChannelLayout::radiance().has_hit_values());
    int all = 0;
    for (Channel c : kContinuous) all += channel_width(c);
    EXPECT_EQ(all + 3, kMaxChannelValues);
    EXPECT_THROW(ChannelLayout({Channel::Alpha, Channel::Alpha}), std::invalid_argument);
    EXPECT_THROW(ChannelLayout(std::vector<Channel>{}), std::invalid_argument);
    EXPECT_EQ(channel_from_name("shading_normal", "c"), Channel::ShadingNormal);
    try {
        channel_from_name("normal", "channels[2]");
        FAIL();
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("channels[2]: unknown channel 'normal'"), std::string::npos);
    }
}

TEST(Channels, BoxFilterSupportIsHalfOpen) {
    PixelFilter f;
    f.build(FilterType::Box, 0.5f);
    EXPECT_EQ(f.eval(-0.5f), 1.f);
    EXPECT_EQ(f.eval(0.49999997f), 1.f);
    EXPECT_EQ(f.eval(0.5f), 0.f);  // the next pixel's
    EXPECT_EQ(f.sample(0.f), -0.5f);
}

// A sphere tessellated with its vertices on the sphere lies between the sphere of radius r_in
// (its nearest face plane) and r_out: along a ray through the inner sphere its depth lies between
// the two spheres'. Rays through the pixel centres are checked within that band.
TEST(Channels, SphereHitValuesMatchTheClosedForm) {
    const Vec3d centre(0.1, -0.05, 0.0), eye(0.0, 0.0, 3.0);
    const double radius = 0.5;
    MeshData sphere = make_sphere(Vec3f(centre), float(radius), 64, 128);
    SceneArrays arrays(sphere, Vec3f(eye), 24, 24, 30.f);
    auto scene = build_scene(arrays.desc);

    double r_in = 1e30, r_out = 0.0, chord = 0.0;  // chord: face normal to its vertices' directions
    auto vertex = [&](int32_t i) { return Vec3d(sphere.vertices[3 * i], sphere.vertices[3 * i + 1], sphere.vertices[3 * i + 2]) - centre; };
    for (int64_t f = 0; f < sphere.num_triangles(); ++f) {
        Vec3d v[3];
        for (int k = 0; k < 3; ++k) v[k] = vertex(sphere.indices[3 * f + k]);
        const Vec3d n = normalize(cross(v[1] - v[0], v[2] - v[0]));
        r_in = std::min(r_in, dot(v[0], n));
        for (int k = 0; k < 3; ++k) {
            r_out = std::max(r_out, length(v[k]));
            chord = std::max(chord, length(normalize(v[k]) - n));
        }
    }
    ASSERT_LT(radius - r_in, 1e-3);
    auto sphere_t = [&](const Vec3d& d, double r) {
        const Vec3d oc = eye - centre;
        const double b = dot(d, oc), disc = b * b - (dot(oc, oc) - r * r);
        return disc < 0 ? std::nan("") : -b - std::sqrt(disc);
    };

    const ChannelLayout layout(kContinuous);
    const auto o = [&](Channel c) { return layout.offset[int(c)]; };
    int tested = 0;
    float v[kMaxChannelValues];
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) {
            const Ray ray = scene->camera.generate_ray(x + 0.5f, y + 0.5f);
            const FirstHit first = first_hit(*scene, ray);
            eval_hit_channels(*scene, layout, ray, first.found, first.hit, v);
            const Vec3d d = normalize(Vec3d(ray.dir));
            const double t_out = sphere_t(d, r_out), t_in = sphere_t(d, r_in);
            if (std::isnan(t_out)) {  // misses the outer sphere: nothing
                EXPECT_FALSE(first.found);
                for (int k = 0; k < layout.num_values; ++k) EXPECT_EQ(v[k], 0.f);
                continue;
            }
            if (std::isnan(t_in)) continue;  // between the two: the outline
            ASSERT_TRUE(first.found);
            ++tested;
            const double band = t_in - t_out + 1e-5;  // + float rounding
            const Vec3d p = eye + d * t_out, normal = (p - centre) / r_out;
            EXPECT_EQ(v[o(Channel::Alpha)], 1.f);
            EXPECT_NEAR(v[o(Channel::Depth)], 0.5 * (t_in + t_out), 0.5 * band);
            // |a/|a| - b/|b|| <= 2 |a - b| / |b|; the face normal adds at most `chord`.
            for (int k = 0; k < 3; ++k) {
                EXPECT_NEAR(v[o(Channel::Position) + k], p[k], band);
                EXPECT_NEAR(v[o(Channel::ShadingNormal) + k], normal[k], 2 * band / r_in);
                EXPECT_NEAR(v[o(Channel::GeometryNormal) + k], normal[k], chord + 2 * band / r_in);
                EXPECT_FLOAT_EQ(v[o(Channel::Albedo) + k], arrays.diffuse[size_t(k)]);
                EXPECT_EQ(v[o(Channel::VertexColor) + k], 1.f);  // no colours
                EXPECT_EQ(v[o(Channel::Specular) + k], 0.f);
            }
            EXPECT_EQ(v[o(Channel::Roughness)], 0.5f);
            // The barycentrics of the hit: position = sum b_i v_i.
            const float b1 = v[o(Channel::Barycentrics)], b2 = v[o(Channel::Barycentrics) + 1];
            const int32_t* tri = sphere.indices.data() + 3 * first.hit.prim;
            for (int k = 0; k < 3; ++k) {
                const auto x = [&](int j) { return sphere.vertices[size_t(3 * tri[j] + k)]; };
                EXPECT_NEAR(v[o(Channel::Position) + k], (1 - b1 - b2) * x(0) + b1 * x(1) + b2 * x(2), 1e-5);
            }
        }
    EXPECT_GT(tested, 40);
}

// d_hit_channels projected on a direction in the vertices, normals, uvs, vertex colours, the
// diffuse, specular and roughness textures and the camera equals the central difference of
// eval_hit_channels.
TEST(Channels, HitAdjointMatchesFiniteDifferences) {
    MeshData tri;
    tri.vertices = {-0.8f, -0.6f, 0.1f, 0.9f, -0.4f, -0.3f, -0.1f, 0.8f, 0.2f};
    tri.normals = {0.1f, 0.0f, 1.0f, 0.3f, 0.2f, 0.9f, -0.2f, 0.1f, 1.0f};
    tri.uvs = {0.1f, 0.2f, 0.8f, 0.3f, 0.4f, 0.9f};
    tri.indices = {0, 1, 2};
    std::vector<float> tex = {0.1f, 0.5f, 0.9f, 0.7f, 0.2f, 0.4f, 0.3f, 0.8f, 0.6f, 0.9f, 0.1f, 0.2f};
    std::vector<float> spec = {0.3f, 0.1f, 0.2f, 0.05f, 0.4f, 0.15f, 0.25f, 0.35f, 0.1f, 0.2f, 0.3f, 0.45f};
    std::vector<float> rough = {0.2f, 0.6f, 0.4f, 0.8f};
    std::vector<float> colors = {0.9f, 0.2f, 0.5f, 0.3f, 0.7f, 1.2f, 0.6f, 0.4f, 0.1f};
    std::mt19937 gen(5);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    std::vector<float> dv(9), dn(9), duv(6), dtex(tex.size()), dspec(spec.size()), drough(rough.size()),
        dcol(colors.size()), dcam(kCameraParams);
    for (auto* dir : {&dv, &dn, &duv, &dtex, &dspec, &drough, &dcol, &dcam})
        for (float& x : *dir) x = u(gen);
    dcam[10] = 0.f;  // ortho_scale: no effect on a perspective camera

    const ChannelLayout layout(kContinuous);
    const float film_x = 13.3f, film_y = 9.6f;
    auto values = [&](float eps, float* out) {
        MeshData m = tri;
        std::vector<float> t = tex, sp = spec, r = rough, c = colors;
        for (size_t i = 0; i < sp.size(); ++i) sp[i] += eps * dspec[i];
        for (size_t i = 0; i < r.size(); ++i) r[i] += eps * drough[i];
        for (size_t i = 0; i < c.size(); ++i) c[i] += eps * dcol[i];
        for (int i = 0; i < 9; ++i) m.vertices[size_t(i)] += eps * dv[size_t(i)];
        for (int i = 0; i < 9; ++i) m.normals[size_t(i)] += eps * dn[size_t(i)];
        for (int i = 0; i < 6; ++i) m.uvs[size_t(i)] += eps * duv[size_t(i)];
        for (size_t i = 0; i < t.size(); ++i) t[i] += eps * dtex[i];
        SceneArrays a(m, Vec3f(0.2f, 0.1f, 3.f), 24, 20, 40.f);
        a.desc.materials[0].diffuse = texture(t, 2, 2, 3);
        a.desc.materials[0].specular = texture(sp, 2, 2, 3);
        a.desc.materials[0].roughness = texture(r, 2, 2, 1);
        a.desc.meshes[0].colors = c.data();
        for (int k = 0; k < 3; ++k) {
            a.desc.camera.position[k] += eps * dcam[size_t(k)];
            a.desc.camera.look_at[k] += eps * dcam[size_t(3 + k)];
            a.desc.camera.up[k] += eps * dcam[size_t(6 + k)];
        }
        a.desc.camera.fov += eps * dcam[9];
        auto scene = build_scene(a.desc);
        const Ray ray = scene->camera.generate_ray(film_x, film_y);
        const FirstHit first = first_hit(*scene, ray);
        ASSERT_TRUE(first.found);
        eval_hit_channels(*scene, layout, ray, true, first.hit, out);
    };
    float plus[kMaxChannelValues], minus[kMaxChannelValues];
    const float eps = 1e-3f;
    values(eps, plus);
    values(-eps, minus);

    SceneArrays a(tri, Vec3f(0.2f, 0.1f, 3.f), 24, 20, 40.f);
    a.desc.materials[0].diffuse = texture(tex, 2, 2, 3);
    a.desc.materials[0].specular = texture(spec, 2, 2, 3);
    a.desc.materials[0].roughness = texture(rough, 2, 2, 1);
    a.desc.meshes[0].colors = colors.data();
    auto scene = build_scene(a.desc);
    SceneGradients dirs;
    dirs.meshes.resize(1);
    dirs.meshes[0].vertices.dir = dv.data();
    dirs.meshes[0].normals.dir = dn.data();
    dirs.meshes[0].uvs.dir = duv.data();
    dirs.materials.resize(1);
    dirs.materials[0].diffuse.dir = dtex.data();
    dirs.materials[0].specular.dir = dspec.data();
    dirs.materials[0].roughness.dir = drough.data();
    dirs.meshes[0].colors.dir = dcol.data();
    dirs.camera.dir = dcam.data();
    const Ray ray = scene->camera.generate_ray(film_x, film_y);
    const FirstHit first = first_hit(*scene, ray);
    ASSERT_TRUE(first.found);
    GradSink sink(true);
    for (int j = 0; j < layout.num_values; ++j) {
        float e[kMaxChannelValues] = {};
        e[j] = 1.f;
        d_hit_channels(*scene, layout, dirs, Vec2f(film_x, film_y), Vec2f(kLensCentre, kLensCentre), ray, first.hit, e, sink);
        const double got = sink.take_projection(), fd = (double(plus[j]) - minus[j]) / (2.0 * eps);
        EXPECT_NEAR(got, fd, 2e-3 + 5e-3 * std::abs(fd)) << "value " << j;
        if (j == layout.offset[int(Channel::Alpha)]) {
            EXPECT_EQ(got, 0.0);
        } else {
            EXPECT_GT(std::abs(fd), 1e-2) << "value " << j << ": nothing is tested";
        }
    }
}

// A tangent-space normal map: the shading normal's adjoint in the map's texels, the vertices,
// normals and uvs (the tangent dp/du depends on them) equals the central difference, with and
// without normals and uvs (then the barycentrics stand in for the uvs).
TEST(Channels, NormalMapAdjointMatchesFiniteDifferences) {
    const std::vector<float> map = {0.9f, 0.3f, 0.8f, 0.7f, 0.8f, 0.7f, 0.85f, 0.6f, 0.9f, 0.75f, 0.2f, 0.8f};
    for (bool attributes : {true, false}) {
        MeshData tri;
        tri.vertices = {-0.8f, -0.6f, 0.1f, 0.9f, -0.4f, -0.3f, -0.1f, 0.8f, 0.2f};
        tri.indices = {0, 1, 2};
        if (attributes) {
            tri.normals = {0.1f, 0.0f, 1.0f, 0.3f, 0.2f, 0.9f, -0.2f, 0.1f, 1.0f};
            tri.uvs = {0.1f, 0.2f, 0.8f, 0.3f, 0.4f, 0.9f};
        }
        std::mt19937 gen(11);
        std::uniform_real_distribution<float> u(-1.f, 1.f);
        std::vector<float> dv(9), dn(9), duv(6), dmap(map.size());
        for (auto* dir : {&dv, &dn, &duv, &dmap})
            for (float& x : *dir) x = u(gen);
        const ChannelLayout layout({Channel::ShadingNormal});
        const float film_x = 11.3f, film_y = 10.6f;
        auto values = [&](float eps, float* out) {
            MeshData m = tri;
            std::vector<float> t = map;
            for (int i = 0; i < 9; ++i) m.vertices[size_t(i)] += eps * dv[size_t(i)];
            for (size_t i = 0; i < m.normals.size(); ++i) m.normals[i] += eps * dn[i];
            for (size_t i = 0; i < m.uvs.size(); ++i) m.uvs[i] += eps * duv[i];
            for (size_t i = 0; i < t.size(); ++i) t[i] += eps * dmap[i];
            SceneArrays a(m, Vec3f(0.2f, 0.1f, 3.f), 24, 20, 40.f);
            a.desc.materials[0].normal_map = texture(t, 2, 2, 3);
            auto scene = build_scene(a.desc);
            const Ray ray = scene->camera.generate_ray(film_x, film_y);
            const FirstHit first = first_hit(*scene, ray);
            ASSERT_TRUE(first.found);
            eval_hit_channels(*scene, layout, ray, true, first.hit, out);
        };
        float plus[3], minus[3], base[3];
        const float eps = 1e-3f;
        values(eps, plus);
        values(-eps, minus);
        values(0.f, base);

        SceneArrays a(tri, Vec3f(0.2f, 0.1f, 3.f), 24, 20, 40.f);
        a.desc.materials[0].normal_map = texture(map, 2, 2, 3);
        auto scene = build_scene(a.desc);
        // The map bends the normal away from the unmapped one.
        const Ray ray = scene->camera.generate_ray(film_x, film_y);
        const FirstHit first = first_hit(*scene, ray);
        ASSERT_TRUE(first.found);
        const Vec3f unmapped = scene->unmapped_normal(first.hit.mesh, first.hit.prim, first.hit.b1, first.hit.b2);
        EXPECT_LT(dot(unmapped, Vec3f(base[0], base[1], base[2])), 0.99f);
        EXPECT_NEAR(length(Vec3f(base[0], base[1], base[2])), 1.f, 1e-5f);
        SceneGradients dirs;
        dirs.meshes.resize(1);
        dirs.meshes[0].vertices.dir = dv.data();
        if (attributes) {
            dirs.meshes[0].normals.dir = dn.data();
            dirs.meshes[0].uvs.dir = duv.data();
        }
        dirs.materials.resize(1);
        dirs.materials[0].normal_map.dir = dmap.data();
        GradSink sink(true);
        for (int j = 0; j < 3; ++j) {
            float e[kMaxChannelValues] = {};
            e[j] = 1.f;
            d_hit_channels(*scene, layout, dirs, Vec2f(film_x, film_y), Vec2f(kLensCentre, kLensCentre), ray, first.hit, e,
                           sink);
            const double got = sink.take_projection(), fd = (double(plus[j]) - minus[j]) / (2.0 * eps);
            EXPECT_NEAR(got, fd, 2e-3 + 5e-3 * std::abs(fd)) << "attributes " << attributes << ", value " << j;
            EXPECT_GT(std::abs(fd), 1e-2) << "value " << j << ": nothing is tested";
        }
    }
}

TEST(Channels, RadianceChannelIsRenderAndIdsAreThePixelCentres) {
    MeshData sphere = make_sphere(Vec3f(0.f, 0.f, 0.f), 0.6f, 12, 24);
    MeshData lamp = make_quad(Vec3f(-1.f, 2.f, -1.f), Vec3f(2.f, 0.f, 0.f), Vec3f(0.f, 0.f, 2.f));  // facing down
    SceneArrays a(sphere, Vec3f(0.f, 0.5f, 3.f), 14, 10, 40.f);
    std::vector<float> white{5.f, 5.f, 5.f};
    a.desc.materials.push_back(a.desc.materials[0]);
    MeshDesc light = lamp.desc(1);  // material 1
    light.emission = texture(white, 1, 1, 3);
    a.desc.meshes.push_back(light);
    auto scene = build_scene(a.desc);
    RenderOptions opt;
    opt.spp = 3;
    opt.seed = 11;
    std::vector<float> image(14 * 10 * 3), values(14 * 10 * 5);
    std::vector<int32_t> ids(14 * 10 * 3);
    render(*scene, opt, image.data());
    const ChannelLayout layout({Channel::MeshId, Channel::Alpha, Channel::Radiance, Channel::Depth, Channel::TriangleId,
                                Channel::MaterialId});
    ASSERT_EQ(layout.num_values, 5);
    ASSERT_EQ(layout.num_ids, 3);
    render_channels(*scene, opt, layout, values.data(), ids.data());
    double radiance = 0.0;
    for (int p = 0; p < 14 * 10; ++p) {
        for (int c = 0; c < 3; ++c) {
            EXPECT_EQ(values[size_t(5 * p + 1 + c)], image[size_t(3 * p + c)]);  // bit for bit
            radiance += image[size_t(3 * p + c)];
        }
        const Ray ray = scene->camera.generate_ray(float(p % 14) + 0.5f, float(p / 14) + 0.5f);
        const FirstHit f = first_hit(*scene, ray);
        EXPECT_EQ(ids[size_t(3 * p)], f.found ? f.hit.mesh : -1);
        EXPECT_EQ(ids[size_t(3 * p + 1)], f.found ? int32_t(f.hit.prim) : -1);
        EXPECT_EQ(ids[size_t(3 * p + 2)], f.found ? f.hit.mesh : -1);  // mesh i has material i
    }
    EXPECT_GT(radiance, 0.0);
    EXPECT_THROW(render_channels(*scene, opt, layout, values.data(), nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace edgepath
