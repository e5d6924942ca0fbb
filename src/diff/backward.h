// The gradient pass over the whole image, in reverse mode (an adjoint image in, gradients added
// into buffers) and in forward mode (derivative images). For each camera sample: the interior
// term, by the adjoint sweep of the re-traced path (diff/backprop.h), with the boundary term of
// the edges seen from its vertices (edges/secondary.h); then the boundary term of the edges
// seen by the camera, by its own pass (edges/primary.h). Part of the public API (edgepath.h).
#pragma once
#include "render/channels.h"
#include "scene/desc.h"
#include "scene/gradients.h"

namespace edgepath {

class Scene;

// The gradient pass: the interior term and the boundary terms of primary and secondary edges
// (those the options switch on). `adjoint` is d loss / d image, shaped like the image; the
// gradients are ADDED into the buffers of `grads` (slots left null are skipped). Uses the same
// random numbers as render() with the same options, so with the same seed it differentiates
// exactly the paths of that image.
void render_gradients(const Scene& scene, const RenderOptions& options, const float* adjoint,
                      const SceneGradients& grads);

// Forward-mode derivative image: out (image_height, image_width, 3) = dI/dtheta along the
// directions in `dirs` (their `dir` slots), computed by the same adjoint code.
void derivative_image(const Scene& scene, const RenderOptions& options, const SceneGradients& dirs, float* out);

// render_gradients for the continuous channels: `adjoint` (H, W, layout.num_values).
void channel_gradients(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                       const float* adjoint, const SceneGradients& grads);

// derivative_image for the continuous channels: out (H, W, layout.num_values).
void channel_derivative_image(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                              const SceneGradients& dirs, float* out);

}  // namespace edgepath
