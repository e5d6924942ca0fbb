#include "render/channels.h"

#include <algorithm>
#include <stdexcept>
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
    {"mesh_id", 1, true},          {"triangle_id", 1, true},     {"barycentrics", 2, false},
    {"vertex_color", 3, false},    {"roughness", 1, false},      {"specular", 3, false},
    {"material_id", 1, true},
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
    const Mesh& mesh = scene.meshes[size_t(hit.mesh)];
    const Material& m = scene.materials[size_t(mesh.material)];
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
                // The Lambertian reflectance (as the BSDF sees it; a plastic's base under its
                // coating): none for a mirror or glass.
                if (m.kind == MaterialKind::Standard || m.kind == MaterialKind::Plastic)
                    store(values, o, scene.bsdf_params(sp).diffuse);
                else
                    store(values, o, Vec3f(0.f));
                break;
            case Channel::Barycentrics:
                values[o] = sp.b1;
                values[o + 1] = sp.b2;
                break;
            case Channel::VertexColor: store(values, o, mesh.color(hit.prim, sp.b1, sp.b2)); break;
            case Channel::Roughness:
                // GGX alpha as given (the BSDF clamps it below at kMinRoughness); mirrors are smooth,
                // glass where it is 0.
                values[o] = m.kind != MaterialKind::Conductor ? eval_texture1(m.roughness, sp.uv) : 0.f;
                break;
            case Channel::Specular:
                store(values, o, m.kind != MaterialKind::Dielectric ? eval_texture3(m.specular, sp.uv) : Vec3f(0.f));
                break;
            default: break;  // radiance and ids: elsewhere
        }
    }
}

void eval_hit_ids(const Scene& scene, const ChannelLayout& layout, bool found, const Hit& hit, int32_t* ids) {
    if (layout.has(Channel::MeshId)) ids[layout.offset[int(Channel::MeshId)]] = found ? int32_t(hit.mesh) : -1;
    if (layout.has(Channel::TriangleId))
        ids[layout.offset[int(Channel::TriangleId)]] = found ? int32_t(hit.prim) : -1;
    if (layout.has(Channel::MaterialId))
        ids[layout.offset[int(Channel::MaterialId)]] = found ? int32_t(scene.meshes[size_t(hit.mesh)].material) : -1;
}

}  // namespace edgepath
