#include "diff/channels.h"

#include "diff/backprop.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace edgepath {

void d_hit_channels(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots, const Vec2f& film,
                    const Vec2f& lens, const Ray& ray, const Hit& hit, const float* adjoint, GradSink& sink) {
    const VertexGeometry g(scene, hit, ray.origin, ray.dir);
    const size_t material = size_t(g.mesh->material);
    const Material& mat = scene.materials[material];
    const SceneGradients::MaterialSlots* mats = material < slots.materials.size() ? &slots.materials[material] : nullptr;
    const GradSlot none{};
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
            case Channel::Albedo:
                // albedo = diffuse(uv) colour(b) (zero for a mirror or glass)
                if (mat.kind == MaterialKind::Standard || mat.kind == MaterialKind::Plastic)
                    d_diffuse(scene, g, slots, Vec3f(a[0], a[1], a[2]), sink, ha);
                break;
            case Channel::Barycentrics:
                ha.db.x += a[0];
                ha.db.y += a[1];
                break;
            case Channel::VertexColor: ha.dcolor += Vec3f(a[0], a[1], a[2]); break;
            case Channel::Roughness:
                if (mat.kind != MaterialKind::Conductor)
                    d_texture(mat.roughness, mats ? mats->roughness : none, g.sp.uv, a, sink, &ha.duv);
                break;
            case Channel::Specular:
                if (mat.kind != MaterialKind::Dielectric)
                    d_texture(mat.specular, mats ? mats->specular : none, g.sp.uv, a, sink, &ha.duv);
                break;
            default: break;  // alpha is constant on a surface; radiance and ids: elsewhere
        }
    }
    Vec3f d_origin(0.f), d_dir(0.f);
    d_normal_map(scene, g, slots, sink, ha);
    finish_hit(g, ha, mesh_slots(slots, hit.mesh), sink, ray.origin, ray.dir, d_origin, d_dir);
    if (slots.camera.wanted()) {
        float cam[kCameraParams] = {};
        d_camera_ray(scene.camera_params, film.x, film.y, lens.x, lens.y, d_origin, d_dir, cam);
        for (int i = 0; i < kCameraParams; ++i) sink.add(slots.camera, i, cam[i]);
    }
}

}  // namespace edgepath
