// Renders a grey triangle lit by an area light behind the camera with the installed core, and
// differentiates the image sum with respect to the triangle's diffuse colour: exits 0 only when
// the image is lit where the triangle is and the gradient is positive.
#include <cstdio>
#include <vector>

#include "edgepath.h"

int main() {
    using namespace edgepath;
    const float tri[] = {-1, 1, 0, 1, 1, 0, 0, -1, 0};
    const float lamp[] = {-2, -2, -7, 2, -2, -7, 2, 2, -7, -2, 2, -7};
    const int32_t tri_indices[] = {0, 1, 2}, lamp_indices[] = {0, 1, 2, 0, 2, 3};
    const float grey[] = {0.5f, 0.5f, 0.5f}, black[] = {0, 0, 0}, rough[] = {0.5f},
                radiance[] = {10, 10, 10};
    auto constant = [](const float* v, int channels) {
        TextureDesc t;
        t.data = v;
        t.height = t.width = 1;
        t.channels = channels;
        return t;
    };
    SceneDesc desc;
    desc.camera.position[2] = -5.f;
    desc.camera.width = desc.camera.height = 16;
    for (const float* diffuse : {grey, black}) {
        MaterialDesc m;
        m.diffuse = constant(diffuse, 3);
        m.specular = constant(black, 3);
        m.roughness = constant(rough, 1);
        desc.materials.push_back(m);
    }
    MeshDesc t, l;
    t.vertices = tri, t.num_vertices = 3, t.indices = tri_indices, t.num_triangles = 1, t.material = 0;
    l.vertices = lamp, l.num_vertices = 4, l.indices = lamp_indices, l.num_triangles = 2, l.material = 1;
    l.emission = constant(radiance, 3);
    desc.meshes = {t, l};

    auto scene = build_scene(desc);
    RenderOptions options;
    options.spp = 4;
    std::vector<float> image(16 * 16 * 3), adjoint(image.size(), 1.f);
    render(*scene, options, image.data());
    const float centre = image[(8 * 16 + 8) * 3], corner = image[0];

    float d_diffuse[3] = {0, 0, 0};
    SceneGradients grads;
    grads.materials.resize(2);
    grads.materials[0].diffuse.grad = d_diffuse;
    render_gradients(*scene, options, adjoint.data(), grads);
    std::printf("centre %g corner %g d(sum)/d(diffuse) %g %g %g\n", centre, corner, d_diffuse[0],
                d_diffuse[1], d_diffuse[2]);
    return centre > 0.f && corner == 0.f && d_diffuse[0] > 0.f ? 0 : 1;
}
