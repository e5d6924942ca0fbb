// A scene that reaches every adjoint of the gradient pass's sweep, and its parameter groups:
// shared by the tests that compare two ways of computing the same derivatives
// (test_colour_sweep.cpp, test_channel_lanes.cpp).
#pragma once
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "edgepath.h"
#include "scene/gradients.h"
#include "scene/spot.h"
#include "support/shapes.h"

namespace edgepath {

// A wavy floor with textured diffuse, roughness and normal map and vertex colours (glossy
// standard material), a rough plastic sphere, a mirror box, a rough glass sphere, an area light
// with a textured spot emission, a spot point light and a rotated environment map.
struct AllAdjointsScene {
    MeshData floor, ball, box, glass, lamp;
    std::vector<float> floor_colors, ball_colors;
    std::vector<float> tex, spec, rough, nmap, black, half, plastic_rough, ior, glass_rough, le, env;
    SceneDesc desc;

    AllAdjointsScene() {
        const int N = 6;
        for (int j = 0; j <= N; ++j)
            for (int i = 0; i <= N; ++i) {
                const float x = -3.f + 6.f * i / N, z = -3.f + 6.f * j / N;
                floor.vertices.insert(floor.vertices.end(), {x, 0.1f * std::sin(1.3f * x + 0.7f * z), z});
                floor.uvs.insert(floor.uvs.end(), {float(i) / N, float(j) / N});
                const Vec3f n = normalize(Vec3f(-0.13f * std::cos(1.3f * x + 0.7f * z), 1.f, -0.07f * std::cos(1.3f * x + 0.7f * z)));
                floor.normals.insert(floor.normals.end(), {n.x, n.y, n.z});
                floor_colors.insert(floor_colors.end(), {0.6f + 0.05f * i, 0.8f, 0.9f - 0.05f * j});
            }
        for (int j = 0; j < N; ++j)
            for (int i = 0; i < N; ++i) {
                const int a = j * (N + 1) + i, b = a + 1, c = a + N + 1, d = c + 1;
                floor.indices.insert(floor.indices.end(), {a, c, d, a, d, b});
            }
        ball = make_sphere(Vec3f(-0.8f, 0.6f, 0.2f), 0.5f, 8, 12);
        for (int64_t v = 0; v < ball.num_vertices(); ++v)
            ball_colors.insert(ball_colors.end(), {0.9f, 0.7f + 0.02f * float(v % 10), 0.6f});
        box = make_box(Vec3f(0.5f, 0.f, -0.9f), Vec3f(1.1f, 0.7f, -0.3f));
        glass = make_sphere(Vec3f(0.9f, 0.4f, 0.8f), 0.35f, 6, 10);
        lamp = make_quad(Vec3f(-0.6f, 3.f, -0.6f), Vec3f(1.2f, 0, 0), Vec3f(0, 0, 1.2f));  // faces -y
        for (int k = 0; k < 4 * 4; ++k) tex.insert(tex.end(), {0.3f + 0.04f * k, 0.5f, 0.7f - 0.03f * k});
        spec = {0.2f, 0.3f, 0.4f};
        rough = {0.2f, 0.35f, 0.3f, 0.25f};
        for (int k = 0; k < 4 * 4; ++k) nmap.insert(nmap.end(), {0.5f + 0.03f * (k % 4 - 1.5f), 0.5f + 0.02f * (k / 4 - 1.5f), 0.95f});
        black = {0, 0, 0};
        half = {0.5f};
        plastic_rough = {0.15f};
        ior = {1.5f};
        glass_rough = {0.2f};
        le = {6.f, 5.f, 4.f, 5.f, 6.f, 4.f, 4.f, 5.f, 6.f, 6.f, 6.f, 5.f};
        for (int k = 0; k < 4 * 8; ++k) env.insert(env.end(), {0.2f + 0.02f * k, 0.3f + (k == 9 ? 3.f : 0.f), 0.25f});
        MaterialDesc m_floor, m_ball, m_box, m_glass, m_lamp;
        m_floor.diffuse = {tex.data(), 4, 4, 3};
        m_floor.specular = {spec.data(), 1, 1, 3};
        m_floor.roughness = {rough.data(), 2, 2, 1};
        m_floor.normal_map = {nmap.data(), 4, 4, 3};
        m_ball.kind = MaterialKind::Plastic;
        m_ball.diffuse = {tex.data(), 4, 4, 3};
        m_ball.specular = {spec.data(), 1, 1, 3};
        m_ball.roughness = {plastic_rough.data(), 1, 1, 1};
        m_ball.ior = {ior.data(), 1, 1, 1};
        m_box.kind = MaterialKind::Conductor;
        m_box.specular = {spec.data(), 1, 1, 3};
        m_box.diffuse = {black.data(), 1, 1, 3};
        m_box.roughness = {half.data(), 1, 1, 1};
        m_glass.kind = MaterialKind::Dielectric;
        m_glass.diffuse = {black.data(), 1, 1, 3};
        m_glass.specular = {spec.data(), 1, 1, 3};
        m_glass.roughness = {glass_rough.data(), 1, 1, 1};
        m_glass.ior = {ior.data(), 1, 1, 1};
        m_lamp.diffuse = {black.data(), 1, 1, 3};
        m_lamp.specular = {black.data(), 1, 1, 3};
        m_lamp.roughness = {half.data(), 1, 1, 1};
        desc.materials = {m_floor, m_ball, m_box, m_glass, m_lamp};
        desc.meshes = {floor.desc(0), ball.desc(1), box.desc(2), glass.desc(3), lamp.desc(4)};
        desc.meshes[0].colors = floor_colors.data();
        desc.meshes[1].colors = ball_colors.data();
        MeshDesc& l = desc.meshes[4];
        l.emission = {le.data(), 2, 2, 3};
        l.spot = true;
        const float profile[5] = {0.1f, -1.f, 0.05f, 1.2f, 0.6f};
        std::copy(profile, profile + 5, l.spot_profile);
        PointLightDesc pl;
        const float pos[3] = {1.5f, 2.5f, 1.5f}, inten[3] = {4.f, 3.f, 2.f}, axis[5] = {-0.5f, -1.f, -0.5f, 0.9f, 0.4f};
        std::copy(pos, pos + 3, pl.position);
        std::copy(inten, inten + 3, pl.intensity);
        pl.spot = true;
        std::copy(axis, axis + 5, pl.spot_profile);
        desc.point_lights = {pl};
        desc.has_envmap = true;
        desc.envmap.values = {env.data(), 4, 8, 3};
        const float c = std::cos(0.4f), s = std::sin(0.4f);
        const float R[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
        std::copy(R, R + 9, desc.envmap.to_world);
        CameraDesc& cam = desc.camera;
        const float eye[3] = {0.2f, 2.6f, 3.2f}, at[3] = {0.f, 0.2f, 0.f};
        std::copy(eye, eye + 3, cam.position);
        std::copy(at, at + 3, cam.look_at);
        cam.fov = 60;
        cam.width = 20;
        cam.height = 16;
    }
};

// One parameter group: its slot in `g` pointed at a direction of `n` values.
struct Group {
    std::string name;
    std::function<GradSlot&(SceneGradients&)> slot;
    int64_t n;
};

// Slots sized for the scene, with group `grp`'s slot pointed at a fixed direction, kept in `dir`.
inline SceneGradients directions_of(const Group& grp, std::vector<float>& dir) {
    SceneGradients g;
    g.meshes.resize(5);
    g.materials.resize(5);
    g.point_lights.resize(1);
    dir.resize(size_t(grp.n));
    for (size_t i = 0; i < dir.size(); ++i) dir[i] = float(std::sin(0.7 * double(i) + 0.3));
    grp.slot(g).dir = dir.data();
    return g;
}

inline std::vector<Group> groups(const AllAdjointsScene& s) {
    std::vector<Group> out;
    const char* mesh_names[5] = {"floor", "ball", "box", "glass", "lamp"};
    const MeshData* meshes[5] = {&s.floor, &s.ball, &s.box, &s.glass, &s.lamp};
    for (int m = 0; m < 5; ++m) {
        const std::string mn = mesh_names[m];
        const int64_t nv = meshes[m]->num_vertices();
        out.push_back({mn + " vertices", [m](SceneGradients& g) -> GradSlot& { return g.meshes[size_t(m)].vertices; }, 3 * nv});
        // (The mirror and the glass have constant textures: their uvs change nothing.)
        if (!meshes[m]->uvs.empty() && m != 2 && m != 3)
            out.push_back({mn + " uvs", [m](SceneGradients& g) -> GradSlot& { return g.meshes[size_t(m)].uvs; }, 2 * nv});
        if (!meshes[m]->normals.empty())
            out.push_back({mn + " normals", [m](SceneGradients& g) -> GradSlot& { return g.meshes[size_t(m)].normals; }, 3 * nv});
    }
    out.push_back({"floor colours", [](SceneGradients& g) -> GradSlot& { return g.meshes[0].colors; }, 3 * s.floor.num_vertices()});
    out.push_back({"ball colours", [](SceneGradients& g) -> GradSlot& { return g.meshes[1].colors; }, 3 * s.ball.num_vertices()});
    out.push_back({"lamp emission", [](SceneGradients& g) -> GradSlot& { return g.meshes[4].emission; }, 12});
    out.push_back({"lamp spot", [](SceneGradients& g) -> GradSlot& { return g.meshes[4].spot; }, kSpotParams});
    out.push_back({"floor diffuse", [](SceneGradients& g) -> GradSlot& { return g.materials[0].diffuse; }, 48});
    out.push_back({"floor specular", [](SceneGradients& g) -> GradSlot& { return g.materials[0].specular; }, 3});
    out.push_back({"floor roughness", [](SceneGradients& g) -> GradSlot& { return g.materials[0].roughness; }, 4});
    out.push_back({"floor normal map", [](SceneGradients& g) -> GradSlot& { return g.materials[0].normal_map; }, 48});
    out.push_back({"plastic diffuse", [](SceneGradients& g) -> GradSlot& { return g.materials[1].diffuse; }, 48});
    out.push_back({"plastic specular", [](SceneGradients& g) -> GradSlot& { return g.materials[1].specular; }, 3});
    out.push_back({"plastic roughness", [](SceneGradients& g) -> GradSlot& { return g.materials[1].roughness; }, 1});
    out.push_back({"plastic ior", [](SceneGradients& g) -> GradSlot& { return g.materials[1].ior; }, 1});
    out.push_back({"mirror specular", [](SceneGradients& g) -> GradSlot& { return g.materials[2].specular; }, 3});
    out.push_back({"glass roughness", [](SceneGradients& g) -> GradSlot& { return g.materials[3].roughness; }, 1});
    out.push_back({"glass ior", [](SceneGradients& g) -> GradSlot& { return g.materials[3].ior; }, 1});
    out.push_back({"point light position", [](SceneGradients& g) -> GradSlot& { return g.point_lights[0].position; }, 3});
    out.push_back({"point light intensity", [](SceneGradients& g) -> GradSlot& { return g.point_lights[0].intensity; }, 3});
    out.push_back({"point light spot", [](SceneGradients& g) -> GradSlot& { return g.point_lights[0].spot; }, kSpotParams});
    out.push_back({"envmap texels", [](SceneGradients& g) -> GradSlot& { return g.envmap; }, 96});
    out.push_back({"envmap rotation", [](SceneGradients& g) -> GradSlot& { return g.envmap_rotation; }, 9});
    out.push_back({"camera", [](SceneGradients& g) -> GradSlot& { return g.camera; }, kCameraParams});
    return out;
}

}  // namespace edgepath
