// Tangent-space normal maps, as Mitsuba 3 renders its `normalmap` (checked against its images):
// a texture value v gives the direction m = 2 v - 1 in the frame (s, t, n) of the shading
// normal n, with s the triangle's dp/du made orthogonal to n and t = cross(n, s) (against dp/dv
// where the uvs are not mirrored: towards the image's upper rows); the shading normal becomes
// normalize(m.x s + m.y t + m.z n).
// dp/du is constant over a triangle (from its positions and uvs), so the mapped normal may jump
// across edges where it changes. With the adjoint, for the gradient pass.
#pragma once
#include "math/frame.h"
#include "math/vec.h"
#include "math/vec_diff.h"

namespace edgepath {

// dp/du of a triangle from its edges e1 = p1 - p0, e2 = p2 - p0 and the uv differences
// d1 = uv1 - uv0, d2 = uv2 - uv0: dp/du = (d2.y e1 - d1.y e2) / det, det = d1.x d2.y - d2.x d1.y.
// False (no tangent) when det is 0.
inline bool triangle_dpdu(const Vec3f& e1, const Vec3f& e2, const Vec2f& d1, const Vec2f& d2, Vec3f& dpdu) {
    const float det = d1.x * d2.y - d2.x * d1.y;
    if (!(det != 0.f) || !std::isfinite(det)) return false;
    dpdu = (e1 * d2.y - e2 * d1.y) / det;
    return std::isfinite(dpdu.x) && std::isfinite(dpdu.y) && std::isfinite(dpdu.z);
}

// The tangent s of the frame: dp/du without its part along n, normalised; false when there is
// none (no dp/du, or dp/du along n), in which case the frame is TFrame(n).
inline bool normal_map_tangent(const Vec3f& n, bool has_dpdu, const Vec3f& dpdu, Vec3f& s) {
    if (!has_dpdu) return false;
    const Vec3f u = dpdu - n * dot(n, dpdu);
    const float l = length(u);
    if (!(l > 1e-12f * length(dpdu))) return false;
    s = u / l;
    return true;
}

// The tangent frame (s, t, n) the texture's values are in: s from dpdu, t = n x s; where there
// is no tangent, Frame(n)'s axes. True when s came from dpdu.
inline bool normal_map_frame(const Vec3f& n, bool has_dpdu, const Vec3f& dpdu, Vec3f& s, Vec3f& t) {
    if (normal_map_tangent(n, has_dpdu, dpdu, s)) {
        t = cross(n, s);
        return true;
    }
    const Frame f(n);
    s = f.s;
    t = f.t;
    return false;
}

// The mapped normal for unit shading normal n and texture value v (n itself when the mapped
// direction is zero).
inline Vec3f map_normal(const Vec3f& n, bool has_dpdu, const Vec3f& dpdu, const Vec3f& v) {
    const Vec3f m = v * 2.f - Vec3f(1.f);
    Vec3f s, t;
    normal_map_frame(n, has_dpdu, dpdu, s, t);
    const Vec3f w = s * m.x + t * m.y + n * m.z;
    const float l = length(w);
    return l > 0.f ? w / l : n;
}

// Adjoint of map_normal: from d_out, adds to dn, ddpdu and dv. Where the frame is TFrame(n)
// (no tangent), its dependence on n is not followed (s and t are held fixed).
inline void d_map_normal(const Vec3f& n, bool has_dpdu, const Vec3f& dpdu, const Vec3f& v, const Vec3f& d_out,
                         Vec3f& dn, Vec3f& ddpdu, Vec3f& dv) {
    const Vec3f m = v * 2.f - Vec3f(1.f);
    Vec3f s, t;
    const bool tangent = normal_map_frame(n, has_dpdu, dpdu, s, t);
    const Vec3f w = s * m.x + t * m.y + n * m.z;
    if (!(length(w) > 0.f)) {
        dn += d_out;
        return;
    }
    const Vec3f dw = d_normalize(w, d_out);
    dv += Vec3f(dot(dw, s), dot(dw, t), dot(dw, n)) * 2.f;
    dn += dw * m.z;
    if (!tangent) return;
    Vec3f ds = dw * m.x;
    // t = cross(n, s)
    d_cross(n, s, dw * m.y, dn, ds);
    // s = normalize(u), u = dpdu - n (n . dpdu)
    const Vec3f du = d_normalize(dpdu - n * dot(n, dpdu), ds);
    ddpdu += du - n * dot(n, du);
    dn -= du * dot(n, dpdu) + dpdu * dot(n, du);
}

// Adjoint of triangle_dpdu (where it returned true): from ddpdu, adds to de1, de2, dd1, dd2.
inline void d_triangle_dpdu(const Vec3f& e1, const Vec3f& e2, const Vec2f& d1, const Vec2f& d2, const Vec3f& ddpdu,
                            Vec3f& de1, Vec3f& de2, Vec2f& dd1, Vec2f& dd2) {
    const float det = d1.x * d2.y - d2.x * d1.y;
    const Vec3f dpdu = (e1 * d2.y - e2 * d1.y) / det;
    de1 += ddpdu * (d2.y / det);
    de2 -= ddpdu * (d1.y / det);
    const float g = dot(ddpdu, dpdu);
    dd1.x -= g * d2.y / det;
    dd2.x += g * d1.y / det;
    dd1.y += dot(ddpdu, dpdu * d2.x - e2) / det;
    dd2.y += dot(ddpdu, e1 - dpdu * d1.x) / det;
}

}  // namespace edgepath
