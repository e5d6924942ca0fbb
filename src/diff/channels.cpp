#include "diff/channels.h"

#include <algorithm>

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
    d_camera_params(scene, slots, film, lens, d_origin, d_dir, sink);
}

namespace {

// Whether value j of the layout's nv values has a lane: all but the radiance's three (starting
// at `skip`, -1 without radiance), which the sweep computes.
bool has_lane(int j, int nv, int skip) { return j < nv && !(skip >= 0 && j >= skip && j < skip + 3); }

// Lane j of `d` set to w where value j (the values of channel c start at `off`) is one of the
// lanes, for the adjoints a[0..n) of d_hit_channels that point at the values off..off+n.
template <int N>
void one_hot(AdjN<N>* d, int n, int off, int nv, int skip, float w) {
    for (int c = 0; c < n; ++c) {
        d[c] = AdjN<N>();
        if (has_lane(off + c, nv, skip)) d[c].v[off + c] = w;
    }
}

template <int N>
void d_hit_channel_lanes(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots,
                         const Vec2f& film, const Vec2f& lens, const Ray& ray, const Hit& hit, float w, int skip,
                         GradSink& sink, double* out) {
    using A = AdjN<N>;
    const int nv = layout.num_values;
    const auto on = [&](int j) { return has_lane(j, nv, skip); };
    const VertexGeometry g(scene, hit, ray.origin, ray.dir);
    const size_t material = size_t(g.mesh->material);
    const Material& mat = scene.materials[material];
    const SceneGradients::MaterialSlots* mats = material < slots.materials.size() ? &slots.materials[material] : nullptr;
    const GradSlot none{};
    THitAdjoint<A> ha;
    // What d_hit_channels does with the adjoint w of value j alone, in lane j, channel by
    // channel in the layout's order (the texture adjoints' sink calls in the same order).
    for (Channel c : layout.channels) {
        const int o = layout.offset[int(c)];
        switch (c) {
            case Channel::Depth:
                if (on(o)) ha.dt.v[o] += w * length(ray.dir);
                break;
            case Channel::Position:
            case Channel::GeometryNormal:
            case Channel::ShadingNormal:
            case Channel::VertexColor: {
                TVec3<A>& d = c == Channel::Position         ? ha.dp
                              : c == Channel::GeometryNormal ? ha.dng
                              : c == Channel::ShadingNormal  ? ha.dn
                                                             : ha.dcolor;
                for (int k = 0; k < 3; ++k)
                    if (on(o + k)) d[k].v[o + k] += w;
                break;
            }
            case Channel::Uv:
            case Channel::Barycentrics: {
                TVec2<A>& d = c == Channel::Uv ? ha.duv : ha.db;
                if (on(o)) d.x.v[o] += w;
                if (on(o + 1)) d.y.v[o + 1] += w;
                break;
            }
            case Channel::Albedo:
                // d_diffuse with the RGB adjoint w e_k in lane o + k.
                if (mat.kind == MaterialKind::Standard || mat.kind == MaterialKind::Plastic) {
                    const Texture& tex = mat.diffuse;
                    const GradSlot& slot = mats ? mats->diffuse : none;
                    A d3[3];
                    one_hot(d3, 3, o, nv, skip, w);
                    if (g.mesh->colors) {
                        const Vec3f col = g.mesh->color(g.sp.prim, g.sp.b1, g.sp.b2);
                        const Vec3f T = eval_texture3(tex, g.sp.uv);
                        for (int k = 0; k < 3; ++k)
                            if (on(o + k)) {
                                d3[k].v[o + k] = w * col[k];
                                ha.dcolor[k].v[o + k] += w * T[k];
                            }
                    }
                    d_texture(tex, slot, g.sp.uv, d3, sink, &ha.duv);
                }
                break;
            case Channel::Roughness:
            case Channel::Specular: {
                const bool rough = c == Channel::Roughness;
                if (rough ? mat.kind != MaterialKind::Conductor : mat.kind != MaterialKind::Dielectric) {
                    const Texture& tex = rough ? mat.roughness : mat.specular;
                    A d[4];
                    one_hot(d, std::min(tex.channels, 4), o, nv, skip, w);
                    d_texture(tex, mats ? (rough ? mats->roughness : mats->specular) : none, g.sp.uv, d, sink,
                              &ha.duv);
                }
                break;
            }
            default: break;  // alpha is constant on a surface; radiance and ids: elsewhere
        }
    }
    TVec3<A> d_origin, d_dir;
    d_normal_map(scene, g, slots, sink, ha);
    finish_hit(g, ha, mesh_slots(slots, hit.mesh), sink, ray.origin, ray.dir, d_origin, d_dir);
    d_camera_params(scene, slots, film, lens, d_origin, d_dir, sink);
    double p[N];
    sink.take_lane_projections(p, N);
    for (int j = 0; j < nv; ++j) out[j] = on(j) ? p[j] : 0.0;
}

}  // namespace

void d_hit_channel_values(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots,
                          const Vec2f& film, const Vec2f& lens, const Ray& ray, const Hit& hit, float w,
                          GradSink& sink, double* out) {
    const int skip = layout.offset[int(Channel::Radiance)];
    const int nv = layout.num_values;
    static_assert(kMaxChannelValues <= 28 && kMaxChannelValues <= kMaxAdjLanes, "lanes for every value");
    if (nv <= 4)
        d_hit_channel_lanes<4>(scene, layout, slots, film, lens, ray, hit, w, skip, sink, out);
    else if (nv <= 8)
        d_hit_channel_lanes<8>(scene, layout, slots, film, lens, ray, hit, w, skip, sink, out);
    else if (nv <= 16)
        d_hit_channel_lanes<16>(scene, layout, slots, film, lens, ray, hit, w, skip, sink, out);
    else
        d_hit_channel_lanes<28>(scene, layout, slots, film, lens, ray, hit, w, skip, sink, out);
}

}  // namespace edgepath
