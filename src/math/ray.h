#pragma once
#include <algorithm>
#include <cmath>
#include <limits>
#include "math/vec.h"

namespace edgepath {

struct Ray {
    Vec3f origin, dir;
    float tmin = 0.f;
    float tmax = std::numeric_limits<float>::infinity();
};

// Relative offset used to leave a surface without hitting it again: scaled by the magnitude of
// the point's coordinates, so scenes of any size behave the same.
constexpr float kRayEpsilon = 1e-4f;
// Shadow rays stop this fraction short of their target.
constexpr float kShadowEpsilon = 1e-3f;

inline float ray_offset_scale(const Vec3f& p) { return kRayEpsilon * (1.f + max_abs_component(p)); }

// A ray leaving point p (geometric normal ng) in direction d.
inline Ray spawn_ray(const Vec3f& p, const Vec3f& ng, const Vec3f& d) {
    float side = dot(ng, d) >= 0.f ? 1.f : -1.f;
    Ray r;
    r.origin = p + ng * (side * ray_offset_scale(p));
    r.dir = d;
    return r;
}

// A shadow ray from point p (geometric normal ng) towards the point at distance `dist` along the
// unit direction d (infinite: a direction only). It leaves from the lifted origin spawn_ray
// uses and is aimed and measured from there, stopping short of the target by both the relative
// shadow epsilon and the target's own ray offset, so that far from the origin the lift cannot
// carry it into the target's surface.
inline Ray shadow_ray(const Vec3f& p, const Vec3f& ng, const Vec3f& d, float dist) {
    Ray r = spawn_ray(p, ng, d);
    if (!std::isfinite(dist)) return r;
    Vec3f target = p + d * dist;
    Vec3f to = target - r.origin;
    float len = length(to);
    if (len > 0.f) r.dir = to / len;
    r.tmax = std::max(len * (1.f - kShadowEpsilon) - ray_offset_scale(target), 0.f);
    return r;
}

}  // namespace edgepath
