// The adjoint of the output channels' first-hit values (render/channels.h): what the gradient
// pass adds for a loss on depth, position, normals, uv, albedo, barycentrics, vertex colour,
// roughness or specular. It lives here rather than beside eval_hit_channels because it reuses
// the adjoint sweep's pieces (diff/backprop.h).
#pragma once
#include "math/ray.h"
#include "render/channels.h"
#include "scene/gradients.h"

namespace edgepath {

class Scene;
struct Hit;

// Adjoint of eval_hit_channels: `adjoint` holds d loss / d value at the same offsets; the
// derivatives go into the mesh and material slots, and (through the ray) into the camera's,
// for the camera ray of film point `film` and lens sample `lens`. Alpha and the ids have no
// interior derivative.
void d_hit_channels(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots, const Vec2f& film,
                    const Vec2f& lens, const Ray& ray, const Hit& hit, const float* adjoint, GradSink& sink);

}  // namespace edgepath
