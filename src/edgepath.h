// The public C++ API of the edgepath core: describe a scene with views over your own memory
// (scene/desc.h), build it once, render into your own buffer.
#pragma once
#include <memory>
#include "diff/gradients.h"
#include "render/channels.h"
#include "scene/desc.h"

namespace edgepath {

class Scene;

// Validates `desc` (throws std::invalid_argument whose message names the offending field and
// value) and builds the acceleration structure and sampling distributions. The returned scene
// keeps pointers into the memory `desc` views: keep that memory alive and unchanged while the
// scene is used.
std::shared_ptr<const Scene> build_scene(const SceneDesc& desc);

// Size of the rendered image (the crop window if one is set).
int image_width(const Scene& scene);
int image_height(const Scene& scene);

// Triangles of meshes[mesh] that the scene skips as degenerate (zero area, or too thin for a
// normal in float: scene/geometry.h). They render as nothing and get zero gradients.
int64_t degenerate_triangles(const Scene& scene, int mesh);

// Renders into `image`, (image_height, image_width, 3) float32, row 0 at the top, linear.
// Deterministic for a given seed whatever the thread count.
RenderStats render(const Scene& scene, const RenderOptions& options, float* image);

// The gradient pass (interior term). `adjoint` is d loss / d image, shaped like the image; the
// gradients are ADDED into the buffers of `grads` (slots left null are skipped). Uses the same
// random numbers as render() with the same options, so with the same seed it differentiates
// exactly the paths of that image.
void render_gradients(const Scene& scene, const RenderOptions& options, const float* adjoint,
                      const SceneGradients& grads);

// Forward-mode derivative image: out (image_height, image_width, 3) = dI/dtheta along the
// directions in `dirs` (their `dir` slots), computed by the same adjoint code.
void derivative_image(const Scene& scene, const RenderOptions& options, const SceneGradients& dirs, float* out);

// Output channels (render/channels.h, docs/conventions.md): renders the layout's continuous
// channels into `values` (image_height, image_width, layout.num_values) float32 and its ids into
// `ids` (image_height, image_width, layout.num_ids) int32 (may be null without ids). The
// radiance channel equals render()'s image for the same options, bit for bit; the other
// continuous channels are filtered over the same camera samples; ids are those of the ray
// through the pixel centre.
RenderStats render_channels(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                            float* values, int32_t* ids);

// render_gradients for the continuous channels: `adjoint` (H, W, layout.num_values).
void channel_gradients(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                       const float* adjoint, const SceneGradients& grads);

// derivative_image for the continuous channels: out (H, W, layout.num_values).
void channel_derivative_image(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                              const SceneGradients& dirs, float* out);

}  // namespace edgepath
