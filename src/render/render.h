// The forward pass over the whole image: every camera sample of every pixel traced by the path
// tracer of render/path.h, its paths advanced in batches (render/batch.h), in tiles on oneTBB
// threads (render/tiles.h). Part of the public API (edgepath.h).
#pragma once
#include <cstdint>
#include "render/channels.h"
#include "scene/desc.h"

namespace edgepath {

class Scene;

// Renders into `image`, (image_height, image_width, 3) float32, row 0 at the top, linear.
// Deterministic for a given seed whatever the thread count. (render_channels with the radiance
// channel alone.)
RenderStats render(const Scene& scene, const RenderOptions& options, float* image);

// Output channels (render/channels.h, docs/conventions.md): renders the layout's continuous
// channels into `values` (image_height, image_width, layout.num_values) float32 and its ids into
// `ids` (image_height, image_width, layout.num_ids) int32 (may be null without ids). The
// radiance channel equals render()'s image for the same options, bit for bit; the other
// continuous channels are filtered over the same camera samples; ids are those of the ray
// through the pixel centre.
RenderStats render_channels(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                            float* values, int32_t* ids);

}  // namespace edgepath
