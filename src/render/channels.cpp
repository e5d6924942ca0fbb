#include "render/channels.h"

#include <algorithm>
#include <stdexcept>
#include "diff/backprop.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace edgepath {

namespace {

struct ChannelInfo {
    const char* name;
    int width;
    bool id;
};
constexpr ChannelInfo kChannelInfo[kNumChannels] = {
    {"radiance", 3, false},       {"alpha", 1, false},  {"depth", 1, false},   {"position", 3, false},
    {"geometry_normal", 3, false}, {"shading_normal", 3, false}, {"uv", 2, false}, {"albedo", 3, false},
    {"mesh_id", 1, true},          {"triangle_id", 1, true},
};

const ChannelInfo& info(Channel c) { return kChannelInfo[int(c)]; }

void store(float* values, int offset, const Vec3f& v) {
    values[offset] = v.x;
    values[offset + 1] = v.y;
    values[offset + 2] = v.z;
}

}  // namespace

int channel_width(Channel c) { return info(c).width; }
bool channel_is_id(Channel c) { return info(c).id; }
const char* channel_name(Channel c) { return info(c).name; }

Channel channel_from_name(const std::string& name, const std::string& field) {
    std::string known;
    for (int i = 0; i < kNumChannels; ++i) {
        if (name == kChannelInfo[i].name) return Channel(i);
        known += (i ? ", " : "") + std::string(kChannelInfo[i].name);
    }
    throw std::invalid_argument(field + ": unknown channel '" + name + "' (known: " + known + ")");
}

ChannelLayout::ChannelLayout(const std::vector<Channel>& list) : ChannelLayout() {
    if (list.empty()) throw std::invalid_argument("channels: asks for no channel");
    for (Channel c : list) {
        const int i = int(c);
        if (i < 0 || i >= kNumChannels)
            throw std::invalid_argument("channels: unknown channel number " + std::to_string(i));
        if (offset[i] >= 0)
            throw std::invalid_argument(std::string("channels: '") + info(c).name + "' is asked for twice");
        if (info(c).id) {
            offset[i] = num_ids;
            num_ids += 1;
        } else {
            offset[i] = num_values;
            num_values += info(c).width;
        }
        channels.push_back(c);
    }
}

void eval_hit_channels(const Scene& scene, const ChannelLayout& layout, const Ray& ray, bool found, const Hit& hit,
                       float* values) {
    if (!found) {
        for (Channel c : layout.channels)
            if (c != Channel::Radiance && !channel_is_id(c))
                std::fill(values + layout.offset[int(c)], values + layout.offset[int(c)] + channel_width(c), 0.f);
        return;
    }
    const SurfacePoint sp = scene.surface_point(hit);
    for (Channel c : layout.channels) {
        const int o = layout.offset[int(c)];
        switch (c) {
            case Channel::Alpha: values[o] = 1.f; break;
            case Channel::Depth: values[o] = hit.t * length(ray.dir); break;
            case Channel::Position: store(values, o, sp.p); break;
            case Channel::GeometryNormal: store(values, o, sp.ng); break;
            case Channel::ShadingNormal: store(values, o, sp.ns); break;
            case Channel::Uv:
                values[o] = sp.uv.x;
                values[o + 1] = sp.uv.y;
                break;
            case Channel::Albedo:
                store(values, o, eval_texture3(scene.materials[size_t(scene.meshes[size_t(hit.mesh)].material)].diffuse, sp.uv));
                break;
            default: break;  // radiance and ids: elsewhere
        }
    }
}

void eval_hit_ids(const ChannelLayout& layout, bool found, const Hit& hit, int32_t* ids) {
    if (layout.has(Channel::MeshId)) ids[layout.offset[int(Channel::MeshId)]] = found ? int32_t(hit.mesh) : -1;
    if (layout.has(Channel::TriangleId))
        ids[layout.offset[int(Channel::TriangleId)]] = found ? int32_t(hit.prim) : -1;
}

void d_hit_channels(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots, const Vec2f& film,
                    const Ray& ray, const Hit& hit, const float* adjoint, GradSink& sink) {
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
                // albedo = diffuse(uv)
                const int material = g.mesh->material;
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
        d_camera_ray(scene.camera_params, film.x, film.y, d_origin, d_dir, cam);
        for (int i = 0; i < kCameraParams; ++i) sink.add(slots.camera, i, cam[i]);
    }
}

}  // namespace edgepath
