// The path tracer: one camera sample's radiance, with next-event estimation on area lights and
// the environment combined with BSDF sampling by multiple importance sampling.
#pragma once
#include "sampling/rng.h"
#include "scene/desc.h"
#include "scene/scene.h"

namespace edgepath {

struct RayCounters {
    uint64_t camera = 0, shadow = 0, bounce = 0;
};

// Radiance arriving along `ray` (a camera ray). Consumes random numbers from `rng`.
Vec3f trace_path(const Scene& scene, const RenderOptions& opt, Ray ray, Rng& rng, RayCounters& counters);

// Film point of sample `s` of film pixel (x, y), and its random stream.
inline Vec2f sample_film_point(const Scene& scene, int x, int y, Rng& rng) {
    float fx = scene.filter.sample(rng.next_float());
    float fy = scene.filter.sample(rng.next_float());
    return {float(x) + 0.5f + fx, float(y) + 0.5f + fy};
}

}  // namespace edgepath
