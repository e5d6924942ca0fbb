#include "diff/channels.h"

#include "diff/backprop.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace edgepath {

void d_hit_channels(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots, const Vec2f& film,
                    const Vec2f& lens, const Ray& ray, const Hit& hit, const float* adjoint, GradSink& sink) {
    const VertexGeometry g(scene, hit, ray.origin, ray.dir);
    HitAdjoint ha;
    for (Channel c : layout.channels) {
        const float* a = adjoint + layout.offset[int(c)];
        switch (c) {
            // depth = t |d|, the ray's direction held fixed
            case Channel::Depth: ha.dt += a[0] * length(ray.dir); break;
            // position = sum b_i v_i
            case Channel::Position: ha.dp += Vec3f(a[0], a[1], a[2]); break;
            case Channel::GeometryNormal: ha.dng += Vec3f(a[0], a[1], a[2]); break;
            case Channel::ShadingNormal: ha.dn += Vec3f(a[0], a[1], a[2]); break;
            case Channel::Uv:
                ha.duv.x += a[0];
                ha.duv.y += a[1];
                break;
            case Channel::Albedo: {
                // albedo = diffuse(uv) (zero for a mirror or glass)
                const int material = g.mesh->material;
                if (scene.materials[size_t(material)].kind != MaterialKind::Standard) break;
                const GradSlot none{};
                const GradSlot& slot =
                    size_t(material) < slots.materials.size() ? slots.materials[size_t(material)].diffuse : none;
                d_texture(scene.materials[size_t(material)].diffuse, slot, g.sp.uv, a, sink, &ha.duv);
                break;
            }
            default: break;  // alpha is constant on a surface; radiance and ids: elsewhere
        }
    }
    Vec3f d_origin(0.f), d_dir(0.f);
    finish_hit(g, ha, mesh_slots(slots, hit.mesh), sink, ray.origin, ray.dir, d_origin, d_dir);
    if (slots.camera.wanted()) {
        float cam[kCameraParams] = {};
        d_camera_ray(scene.camera_params, film.x, film.y, lens.x, lens.y, d_origin, d_dir, cam);
        for (int i = 0; i < kCameraParams; ++i) sink.add(slots.camera, i, cam[i]);
    }
}

}  // namespace edgepath
