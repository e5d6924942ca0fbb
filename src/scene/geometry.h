// A triangle's area and normal for any float size, where a fixed ray meets its plane, and their
// adjoints. The gradient pass holds ray directions fixed, so a hit point moves with the ray
// origin and with the triangle it lands on.
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "math/adjoint.h"
#include "math/vec.h"
#include "math/vec_diff.h"

namespace edgepath {

// A triangle too thin for its normal to be computed in float: twice its area (|cross(e1, e2)|,
// in double) at most 1e-6 of the product of the two edge lengths, i.e. the sine of its angle at
// v0 below 1e-6 (zero area, coincident vertices). Relative, so a mesh moved or scaled anywhere
// keeps its triangles. Such triangles are skipped: never hit, not sampled, no edges.
constexpr double kDegenerateSine = 1e-6;

inline bool is_degenerate_triangle(const Vec3f& v0, const Vec3f& v1, const Vec3f& v2) {
    const Vec3d e1 = Vec3d(v1) - Vec3d(v0), e2 = Vec3d(v2) - Vec3d(v0);
    return !(length(cross(e1, e2)) > kDegenerateSine * length(e1) * length(e2));
}

// |cross(e1, e2)| (twice a triangle's area) and normalize(cross(e1, e2)) (its geometric
// normal), bit for bit as those expressions where the squared length is a normal float, and
// from the cross product in double where it is not: edges past about 4e9 units (coordinates go
// to 1e12) would overflow the square to Inf (an area of Inf, a zero normal), edges below about
// 3e-10 underflow it to 0.
constexpr float kCrossLengthLow = 1e-18f, kCrossLengthHigh = 1e18f;

// Whether a cross product's length l computed in float is exact enough (its square in range).
inline bool cross_length_in_range(float l) { return l >= kCrossLengthLow && l <= kCrossLengthHigh; }

inline float cross_length(const Vec3f& e1, const Vec3f& e2) {
    const float l = length(cross(e1, e2));
    if (cross_length_in_range(l)) return l;
    return float(length(cross(Vec3d(e1), Vec3d(e2))));
}

inline Vec3f cross_normal(const Vec3f& e1, const Vec3f& e2) {
    const Vec3f c = cross(e1, e2);
    const float l = length(c);
    if (cross_length_in_range(l)) return c / l;
    const Vec3d cd = cross(Vec3d(e1), Vec3d(e2));
    const double ld = length(cd);
    return ld > 0.0 ? Vec3f(cd / ld) : c;
}

// n = normalize(cross(e1, e2)) as cross_normal computes it: the adjoint of the cross product C,
// from d_normalize(C) where |C| is a normal float and otherwise from d_normalize(C / s) / s,
// s = C's largest component (normalize(C) = normalize(C / s)), which is in range for any C of
// float edges.
template <class A>
TVec3<A> d_cross_normal(const Vec3f& e1, const Vec3f& e2, const TVec3<A>& dn) {
    const Vec3f c = cross(e1, e2);
    const float l = length(c);
    if (cross_length_in_range(l)) return d_normalize(c, dn);
    const Vec3d cd = cross(Vec3d(e1), Vec3d(e2));
    const double s = max_abs_component(cd);
    if (!(s > 0.0)) return TVec3<A>(A(0));
    const TVec3<A> d = d_normalize(Vec3f(cd / s), dn);
    return d * float(1.0 / s);
}

// Barycentrics (b1, b2) moved into the triangle against rounding: each clamped to [0, 1], then
// both scaled down where their sum passes 1.
inline void clamp_into_triangle(double& b1, double& b2) {
    b1 = std::clamp(b1, 0.0, 1.0);
    b2 = std::clamp(b2, 0.0, 1.0);
    if (b1 + b2 > 1.0) {
        const double s = b1 + b2;
        b1 /= s;
        b2 /= s;
    }
}

template <class T>
struct TriangleHit {
    T t = 0, b1 = 0, b2 = 0;
};

// Solves o + t d = v0 + b1 (v1 - v0) + b2 (v2 - v0) (Moeller-Trumbore, no range checks).
template <class T>
bool intersect_triangle(const TVec3<T>& o, const TVec3<T>& d, const TVec3<T>& v0, const TVec3<T>& v1,
                        const TVec3<T>& v2, TriangleHit<T>& h) {
    TVec3<T> e1 = v1 - v0, e2 = v2 - v0;
    TVec3<T> pvec = cross(d, e2);
    T det = dot(e1, pvec);
    if (det == 0) return false;
    T inv = T(1) / det;
    TVec3<T> tvec = o - v0;
    TVec3<T> qvec = cross(tvec, e1);
    h.b1 = dot(tvec, pvec) * inv;
    h.b2 = dot(d, qvec) * inv;
    h.t = dot(e2, qvec) * inv;
    if constexpr (std::is_same_v<T, float>) {
        // dot(e2, qvec) is a product of three lengths: past about 7e12 units it overflows float
        // and t would be Inf (beyond the coordinate bound, 1e12, but this holds for any float
        // input). Solved in double there.
        constexpr float kMax = std::numeric_limits<float>::max();
        if (!(std::abs(h.t) <= kMax && std::abs(h.b1) <= kMax && std::abs(h.b2) <= kMax)) {
            TriangleHit<double> hd;
            if (!intersect_triangle(Vec3d(o), Vec3d(d), Vec3d(v0), Vec3d(v1), Vec3d(v2), hd)) return false;
            h.t = float(hd.t);
            h.b1 = float(hd.b1);
            h.b2 = float(hd.b2);
        }
    }
    return true;
}

template <class A>
struct DTriangle {
    TVec3<A> o, d, v0, v1, v2;
};

// Adjoint of intersect_triangle. With M = [-d, e1, e2] and x = (t, b1, b2), M x = o - v0, so
// lambda = M^-T dx and do = lambda, dv0 = -lambda, dd = lambda t, de1 = -lambda b1, de2 = -lambda b2.
// A: the adjoints' scalar (math/adjoint.h).
template <class T, class A>
void d_intersect_triangle(const TVec3<T>& /*o*/, const TVec3<T>& d, const TVec3<T>& v0, const TVec3<T>& v1,
                          const TVec3<T>& v2, const TriangleHit<T>& h, A dt, A db1, A db2, DTriangle<A>& g) {
    TVec3<T> e1 = v1 - v0, e2 = v2 - v0, nd = -d;
    T det = dot(nd, cross(e1, e2));
    if (det == 0) return;
    // Rows of M^T are (-d, e1, e2); its inverse has columns (e1 x e2, e2 x -d, -d x e1) / det.
    TVec3<A> lambda = (cross(e1, e2) * dt + cross(e2, nd) * db1 + cross(nd, e1) * db2) / det;
    g.o += lambda;
    g.d += lambda * h.t;
    TVec3<A> de1 = -lambda * h.b1, de2 = -lambda * h.b2;
    g.v0 += -lambda - de1 - de2;
    g.v1 += de1;
    g.v2 += de2;
}

}  // namespace edgepath
