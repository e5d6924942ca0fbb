#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include "math/vec.h"

namespace edgepath {

struct Ray {
    Vec3f origin, dir;
    float tmin = 0.f;
    float tmax = std::numeric_limits<float>::infinity();
};

// Leaving a surface without hitting it again. A point computed on a triangle carries a bound on
// its rounding error (per component); a ray leaves from the point pushed along the geometric
// normal, to the side it travels to, just past the box of that size around it, so the surface
// lies wholly behind the origin (the method of pbrt-v4, "Robust Spawned Ray Origins").
// Offsets are thus a few ulps of the coordinates: a scene renders the same wherever it is
// placed and whatever its size.

// Bound on the relative error of n float operations: gamma(n) = n u / (1 - n u), u = 2^-24.
constexpr float rounding_gamma(int n) {
    constexpr float u = std::numeric_limits<float>::epsilon() * 0.5f;
    return float(n) * u / (1.f - float(n) * u);
}

// Bound on the error of a point p = b0 v0 + b1 v1 + b2 v2 (b0 = 1 - b1 - b2) on a triangle, per
// component, as a ray test sees it: the rounding of the interpolation, gamma(7) (|b0 v0| +
// |b1 v1| + |b2 v2|) (pbrt-v4's bound), plus gamma(4) of the triangle's largest edge component.
// The second term is Embree's: its test works with the vertices relative to the ray origin, so
// a point the interpolation puts exactly in the triangle's plane (a floor at y = 0) would meet
// its own triangle at t = 0, whose rounding is of the order of the edges.
// The triangle's largest edge component, for the second term.
inline float triangle_largest_edge(const Vec3f& v0, const Vec3f& v1, const Vec3f& v2) {
    return std::max(max_abs_component(v1 - v0), std::max(max_abs_component(v2 - v0), max_abs_component(v2 - v1)));
}
// The same with the triangle's largest edge component `edge` given (triangle_largest_edge).
inline Vec3f triangle_point_error(const Vec3f& v0, const Vec3f& v1, const Vec3f& v2, float b0, float b1, float b2,
                                  float edge) {
    auto a = [](const Vec3f& v, float b) { return Vec3f(std::abs(v.x * b), std::abs(v.y * b), std::abs(v.z * b)); };
    return (a(v0, b0) + a(v1, b1) + a(v2, b2)) * rounding_gamma(7) + Vec3f(edge * rounding_gamma(4));
}
inline Vec3f triangle_point_error(const Vec3f& v0, const Vec3f& v1, const Vec3f& v2, float b0, float b1, float b2) {
    return triangle_point_error(v0, v1, v2, b0, b1, b2, triangle_largest_edge(v0, v1, v2));
}

// The next float above x (towards +infinity), as std::nextafter(x, +inf) gives it, inline: by
// its bits (one up for a positive x, one down for a negative one; both zeros go to the smallest
// positive subnormal; infinity and NaN stay).
inline float next_float_up(float x) {
    if (!(x < std::numeric_limits<float>::infinity())) return x;  // +inf, NaN
    if (x == 0.f) return std::numeric_limits<float>::denorm_min();
    uint32_t b;
    std::memcpy(&b, &x, sizeof b);
    b = x > 0.f ? b + 1 : b - 1;
    std::memcpy(&x, &b, sizeof b);
    return x;
}
// The next float below x (towards -infinity): next_float_up mirrored.
inline float next_float_down(float x) { return -next_float_up(-x); }

// p (error bound p_error, geometric normal n) moved along n, to the side of w, past its error
// box: by dot(|n|, p_error), then each moved component one more float away from p (the sum
// itself rounds).
inline Vec3f offset_ray_origin(const Vec3f& p, const Vec3f& p_error, const Vec3f& n, const Vec3f& w) {
    const float d = std::abs(n.x) * p_error.x + std::abs(n.y) * p_error.y + std::abs(n.z) * p_error.z;
    Vec3f offset = n * (dot(w, n) < 0.f ? -d : d);
    Vec3f o = p + offset;
    for (int i = 0; i < 3; ++i) {
        if (offset[i] > 0.f)
            o[i] = next_float_up(o[i]);
        else if (offset[i] < 0.f)
            o[i] = next_float_down(o[i]);
    }
    return o;
}

// A ray leaving point p (error bound p_error, geometric normal n) in direction d.
inline Ray spawn_ray(const Vec3f& p, const Vec3f& p_error, const Vec3f& n, const Vec3f& d) {
    Ray r;
    r.origin = offset_ray_origin(p, p_error, n, d);
    r.dir = d;
    return r;
}

// Shadow rays stop this fraction short of their (offset) target.
constexpr float kShadowEpsilon = 1e-4f;

// A shadow ray from surface point p towards surface point q (each with its error bound and
// geometric normal): both ends offset towards each other off their surfaces, the direction
// normalised, stopping kShadowEpsilon short of q's offset point.
inline Ray spawn_ray_to(const Vec3f& p, const Vec3f& p_error, const Vec3f& n, const Vec3f& q, const Vec3f& q_error,
                        const Vec3f& nq) {
    Ray r;
    r.origin = offset_ray_origin(p, p_error, n, q - p);
    const Vec3f target = offset_ray_origin(q, q_error, nq, r.origin - q);
    const Vec3f to = target - r.origin;
    const float len = length(to);
    r.dir = len > 0.f ? to / len : normalize(q - p);
    r.tmax = len * (1.f - kShadowEpsilon);
    return r;
}

}  // namespace edgepath
