// Renders a small scene with the C++ core alone (no Python): a red triangle lit by an emissive
// quad behind the camera, in front of a grey wall. Writes out.png and out.exr, or
// <prefix>.png and <prefix>.exr when a prefix is given:  render_example [prefix] [spp]
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "edgepath.h"
#include "io/image.h"

int main(int argc, char** argv) {
    using namespace edgepath;
    const std::string prefix = argc > 1 ? argv[1] : "out";
    const int spp = argc > 2 ? std::atoi(argv[2]) : 64;
    try {
        // Scene data lives here; the description only points at it.
        const float triangle_vertices[] = {-1.7f, 1.f, 0.f, 1.f, 1.f, 0.f, -0.5f, -1.f, 0.f};
        const int32_t triangle_indices[] = {0, 1, 2};
        // Quad at z = -7 facing +z (towards the triangle), behind the camera.
        const float lamp_vertices[] = {-2, -2, -7, 2, -2, -7, 2, 2, -7, -2, 2, -7};
        const int32_t lamp_indices[] = {0, 1, 2, 0, 2, 3};
        // Wall at z = 2 facing -z (towards the camera).
        const float wall_vertices[] = {-4, -4, 2, -4, 4, 2, 4, 4, 2, 4, -4, 2};
        const int32_t wall_indices[] = {0, 1, 2, 0, 2, 3};
        const float red[] = {0.8f, 0.2f, 0.2f}, grey[] = {0.5f, 0.5f, 0.5f},
                    black[] = {0, 0, 0}, roughness[] = {0.5f}, lamp_radiance[] = {20, 20, 20};

        auto constant = [](const float* value, int channels) {
            TextureDesc t;
            t.data = value;
            t.height = t.width = 1;
            t.channels = channels;
            return t;
        };
        auto material = [&](const float* diffuse) {
            MaterialDesc m;
            m.diffuse = constant(diffuse, 3);
            m.specular = constant(black, 3);
            m.roughness = constant(roughness, 1);
            return m;
        };
        auto mesh = [](const float* vertices, int64_t num_vertices, const int32_t* indices,
                       int64_t num_triangles, int material) {
            MeshDesc m;
            m.vertices = vertices;
            m.num_vertices = num_vertices;
            m.indices = indices;
            m.num_triangles = num_triangles;
            m.material = material;
            return m;
        };

        SceneDesc desc;
        desc.camera.position[2] = -5.f;
        desc.camera.look_at[2] = 0.f;
        desc.camera.fov = 45.f;
        desc.camera.width = 256;
        desc.camera.height = 256;
        desc.materials = {material(red), material(grey), material(black)};
        desc.meshes.push_back(mesh(triangle_vertices, 3, triangle_indices, 1, 0));
        desc.meshes.push_back(mesh(wall_vertices, 4, wall_indices, 2, 1));
        MeshDesc lamp = mesh(lamp_vertices, 4, lamp_indices, 2, 2);
        lamp.emission = constant(lamp_radiance, 3);
        desc.meshes.push_back(lamp);

        std::shared_ptr<const Scene> scene = build_scene(desc);
        const int height = image_height(*scene), width = image_width(*scene);
        std::vector<float> image(static_cast<size_t>(height) * width * 3);
        RenderOptions options;
        options.spp = spp;
        options.max_bounces = 2;
        const RenderStats stats = render(*scene, options, image.data());

        write_image(prefix + ".png", image.data(), height, width, 3);
        write_image(prefix + ".exr", image.data(), height, width, 3);
        std::printf("wrote %s.png and %s.exr (%dx%d, %d spp; %llu camera rays, %llu shadow rays)\n",
                    prefix.c_str(), prefix.c_str(), width, height, spp,
                    static_cast<unsigned long long>(stats.camera_rays),
                    static_cast<unsigned long long>(stats.shadow_rays));
    } catch (const std::exception& e) {
        std::fprintf(stderr, "render_example: %s\n", e.what());
        return 1;
    }
    return 0;
}
