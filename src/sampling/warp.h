// Warps from the unit square to common domains, with their densities.
#pragma once
#include <cmath>
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

// Power heuristic with exponent 2 (Veach).
inline float mis_power(float a, float b) {
    a *= a;
    b *= b;
    return a > 0.f ? a / (a + b) : 0.f;
}

}  // namespace edgepath
