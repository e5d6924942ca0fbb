// Directions uniform in the solid angle of a triangle seen from a point: the triangle's
// projection onto the unit sphere around the point is a spherical triangle, sampled by Arvo's
// method ("Stratified sampling of spherical triangles", SIGGRAPH 1995). Computed in double:
// its formulas subtract nearly equal angles.
#pragma once
#include <algorithm>
#include <cmath>
#include "math/vec.h"

namespace edgepath {

// Solid angles outside these bounds are left to area sampling: below, the triangle is small
// enough that area sampling is within a few percent of uniform in solid angle (its density
// varies across the triangle by about its angular size, sqrt(omega), relatively, unless seen
// edge-on); above, it
// wraps nearly half the sphere around the point and the construction loses its accuracy.
constexpr double kMinSphericalTriangle = 3e-4;
constexpr double kMaxSphericalTriangle = 6.2;

// The corners of a triangle seen from a point, as unit vectors, and the solid angle they
// span.
struct SphericalTriangle {
    Vec3d a, b, c;
    double solid_angle = 0;  // 0: not to be sampled by solid angle (see usable())

    SphericalTriangle() = default;
    // From the point p and the triangle's corners. Leaves solid_angle at 0 when a corner is
    // at p, or the solid angle is outside the bounds above (which includes p in the
    // triangle's plane and corners in the same direction).
    SphericalTriangle(const Vec3d& p, const Vec3d& v0, const Vec3d& v1, const Vec3d& v2) {
        Vec3d da = v0 - p, db = v1 - p, dc = v2 - p;
        const double la = length(da), lb = length(db), lc = length(dc);
        if (!(la > 0) || !(lb > 0) || !(lc > 0)) return;
        a = da / la;
        b = db / lb;
        c = dc / lc;
        // Van Oosterom and Strackee: tan(omega / 2) = |a . (b x c)| / (1 + a.b + b.c + c.a),
        // accurate for small triangles too.
        const double triple = std::abs(dot(a, cross(b, c)));
        const double omega = 2.0 * std::atan2(triple, 1.0 + dot(a, b) + dot(b, c) + dot(c, a));
        if (omega >= kMinSphericalTriangle && omega <= kMaxSphericalTriangle) solid_angle = omega;
    }
    bool usable() const { return solid_angle > 0; }

    // A direction uniform in the spherical triangle (usable() must hold); u1 sweeps the
    // area from the arc ab, u2 along the arc from b.
    Vec3d sample(double u1, double u2) const {
        // The interior angle at a, between the great circles towards b and towards c (the
        // corners are apart: the solid angle is above its lower bound).
        const Vec3d nab = cross(a, b), nac = cross(a, c);
        const double ln = length(nab) * length(nac);
        const double cos_alpha = dot(nab, nac) / ln, sin_alpha = length(cross(nab, nac)) / ln;
        // The sub-triangle a, b, c' of area u1 * omega: its corner c' on the arc from a to c;
        // s and t are the sine and cosine of its area minus alpha.
        const double sub = u1 * solid_angle;
        const double ss = std::sin(sub), cs = std::cos(sub);
        const double s = ss * cos_alpha - cs * sin_alpha, t = cs * cos_alpha + ss * sin_alpha;
        const double u = t - cos_alpha;
        const double v = s + sin_alpha * dot(a, b);
        const double den = (v * s + u * t) * sin_alpha;
        double q = den != 0 ? ((v * t - u * s) * cos_alpha - v) / den : 1.0;
        q = std::clamp(q, -1.0, 1.0);
        const Vec3d c_off = c - dot(c, a) * a;
        const double lc = length(c_off);
        const Vec3d c_perp = lc > 0 ? c_off / lc : c_off;
        const Vec3d c2 = q * a + std::sqrt(std::max(0.0, 1.0 - q * q)) * c_perp;
        // Then a point on the arc from b to c', uniform in the area it sweeps.
        const double z = std::clamp(1.0 - u2 * (1.0 - dot(c2, b)), -1.0, 1.0);
        const Vec3d ortho = c2 - dot(c2, b) * b;
        const double lo = length(ortho);
        if (!(lo > 0)) return b;
        return normalize(z * b + std::sqrt(std::max(0.0, 1.0 - z * z)) * (ortho / lo));
    }
};

}  // namespace edgepath
