// Warps from the unit square to common domains, with their densities.
#pragma once
#include <cmath>
#include <limits>
#include "math/vec.h"

namespace edgepath {

constexpr float kPi = 3.14159265358979323846f;
constexpr float kInvPi = 0.31830988618379067154f;

// Concentric map of the square onto the unit disk (Shirley and Chiu).
inline Vec2f square_to_disk(float u1, float u2) {
    float a = 2.f * u1 - 1.f, b = 2.f * u2 - 1.f;
    if (a == 0.f && b == 0.f) return {0.f, 0.f};
    float r, phi;
    if (std::abs(a) > std::abs(b)) {
        r = a;
        phi = (kPi / 4.f) * (b / a);
    } else {
        r = b;
        phi = (kPi / 2.f) - (kPi / 4.f) * (a / b);
    }
    return {r * std::cos(phi), r * std::sin(phi)};
}

// Cosine-weighted hemisphere around +z; density cos(theta) / pi.
inline Vec3f square_to_cosine_hemisphere(float u1, float u2) {
    Vec2f d = square_to_disk(u1, u2);
    float z = std::sqrt(std::max(0.f, 1.f - d.x * d.x - d.y * d.y));
    return {d.x, d.y, z};
}
inline float cosine_hemisphere_pdf(const Vec3f& w) { return w.z > 0.f ? w.z * kInvPi : 0.f; }

// Uniform point on a triangle as barycentrics (b1, b2) of vertices 1 and 2.
inline Vec2f square_to_triangle(float u1, float u2) {
    float s = std::sqrt(u1);
    return {1.f - s, u2 * s};
}

// Uniform direction on the sphere; density 1 / (4 pi).
inline Vec3f square_to_sphere(float u1, float u2) {
    float z = 1.f - 2.f * u1;
    float r = std::sqrt(std::max(0.f, 1.f - z * z));
    float phi = 2.f * kPi * u2;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

// mis_power where the sum of the squares overflows or underflows (a, b > 0, one of them past
// about 1.8e19, as a far light seen edge-on has, or both below about 1e-22): the same weight
// from the ratio of the smaller density to the larger, which stays in range (Inf / Inf or
// 0 / 0 would be NaN, a finite square over Inf 0).
inline float mis_power_ratio(float a, float b) {
    if (a == b) return 0.5f;
    if (a > b) {
        const float r = b / a;
        return 1.f / (1.f + r * r);
    }
    const float r = a / b, r2 = r * r;
    return r2 / (1.f + r2);
}

// Power heuristic with exponent 2 (Veach): a^2 / (a^2 + b^2), 0 where a is not positive.
inline float mis_power(float a, float b) {
    if (!(a > 0.f)) return 0.f;
    const float a2 = a * a, sum = a2 + b * b;
    if (sum > 0.f && sum < std::numeric_limits<float>::infinity()) return a2 / sum;
    return mis_power_ratio(a, b);
}

}  // namespace edgepath
