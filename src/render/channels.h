// Output channels: besides radiance, what the camera ray of each sample meets first (coverage,
// depth, position, normals, uv, barycentrics, material values, ids). Continuous channels are filtered like radiance
// (the mean over the pixel's camera samples, each drawn from the pixel filter) and are
// differentiable (diff/channels.h); ids are those of the ray through the pixel centre. Units
// and conventions: docs/conventions.md, "Output channels".
#pragma once
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>
#include "math/ray.h"
#include "scene/desc.h"

namespace edgepath {

class Scene;
struct Hit;

enum class Channel : int {
    Radiance = 0,    // 3: linear radiance (what render() writes)
    Alpha,           // 1: 1 where the camera ray meets a surface, 0 where it leaves the scene
    Depth,           // 1: distance along the camera ray to the hit (0 on a miss)
    Position,        // 3: world position of the hit (0 on a miss)
    GeometryNormal,  // 3: unit face normal, by the triangle's winding (0 on a miss)
    ShadingNormal,   // 3: unit interpolated normal (the face normal without normals; 0 on a miss)
    Uv,              // 2: interpolated uv, or the barycentrics (b1, b2) without uvs (0 on a miss)
    Albedo,          // 3: the diffuse reflectance at the hit, texture times vertex colour (0 on a miss)
    MeshId,          // 1, int32: mesh index, -1 on a miss
    TriangleId,      // 1, int32: triangle index within its mesh, -1 on a miss
    Barycentrics,    // 2: (b1, b2) of vertices 1 and 2 in the triangle hit (0 on a miss)
    VertexColor,     // 3: interpolated vertex colour, 1 on a mesh without colours (0 on a miss)
    Roughness,       // 1: the material's roughness (GGX alpha) at the hit; 0 for a mirror or glass
    Specular,        // 3: the material's specular reflectance at the hit; 0 for glass
    MaterialId,      // 1, int32: the mesh's material index, -1 on a miss
};
constexpr int kNumChannels = 15;
// Floats per pixel when every continuous channel is asked for.
constexpr int kMaxChannelValues = 28;

int channel_width(Channel c);
bool channel_is_id(Channel c);
const char* channel_name(Channel c);
// The channel called `name` (as channel_name); throws std::invalid_argument naming `field`.
Channel channel_from_name(const std::string& name, const std::string& field);

// The requested channels in order: continuous channels packed in that order into a float image
// (H, W, num_values), ids into an int32 image (H, W, num_ids).
struct ChannelLayout {
    std::vector<Channel> channels;
    int offset[kNumChannels];  // within its image; -1: not requested
    int num_values = 0, num_ids = 0;

    ChannelLayout() { std::fill(offset, offset + kNumChannels, -1); }
    // Throws std::invalid_argument (field "channels") on an empty list or a repeated channel.
    explicit ChannelLayout(const std::vector<Channel>& list);
    static ChannelLayout radiance() { return ChannelLayout({Channel::Radiance}); }

    bool has(Channel c) const { return offset[int(c)] >= 0; }
    // Whether a continuous channel other than radiance is requested (the first hit is needed).
    bool has_hit_values() const { return num_values > (has(Channel::Radiance) ? 3 : 0); }
};

// Writes the continuous channels of the layout other than radiance for a camera ray (o, d) whose
// first intersection is `hit` (found) or none, at their offsets in `values`.
void eval_hit_channels(const Scene& scene, const ChannelLayout& layout, const Ray& ray, bool found, const Hit& hit,
                       float* values);

// The ids of the ray's first intersection, at their offsets in `ids`.
void eval_hit_ids(const Scene& scene, const ChannelLayout& layout, bool found, const Hit& hit, int32_t* ids);

}  // namespace edgepath
