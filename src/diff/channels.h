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

// Forward mode, every value of the layout at once: out[j] (j < layout.num_values) = the
// projection on the directions of `slots` that d_hit_channels would give `sink` for the adjoint w
// at value j and zero elsewhere (the same float operations, lane by lane: math/adjoint.h, AdjN);
// zero for radiance's values. The hit's geometry and everything that does not depend on the
// adjoint is computed once for all the values.
void d_hit_channel_values(const Scene& scene, const ChannelLayout& layout, const SceneGradients& slots,
                          const Vec2f& film, const Vec2f& lens, const Ray& ray, const Hit& hit, float w,
                          GradSink& sink, double* out);

}  // namespace edgepath
