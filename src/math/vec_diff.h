// Adjoints of the vector helpers of math/vec.h that the gradient pass needs.
#pragma once
#include "math/adjoint.h"
#include "math/vec.h"

namespace edgepath {

// n = v / |v|  (A: the adjoint's scalar, math/adjoint.h)
template <class T, class A>
TVec3<A> d_normalize(const TVec3<T>& v, const TVec3<A>& dn) {
    T l = length(v);
    if (!(l > 0)) return TVec3<A>(A(0));
    TVec3<T> n = v / l;
    return (dn - n * dot(n, dn)) / l;
}

// n = normalize(cross(e1, e2)) as cross_normal (scene/geometry.h) computes it: the adjoint of
// the cross product C, from d_normalize(C) where |C| is a normal float and otherwise from
// d_normalize(C / s) / s, s = C's largest component (normalize(C) = normalize(C / s)), which is
// in range for any C of float edges.
template <class A>
TVec3<A> d_cross_normal(const Vec3f& e1, const Vec3f& e2, const TVec3<A>& dn) {
    const Vec3f c = cross(e1, e2);
    const float l = length(c);
    if (l >= 1e-18f && l <= 1e18f) return d_normalize(c, dn);
    const Vec3d cd = cross(Vec3d(e1), Vec3d(e2));
    const double s = max_abs_component(cd);
    if (!(s > 0.0)) return TVec3<A>(A(0));
    const TVec3<A> d = d_normalize(Vec3f(cd / s), dn);
    return d * float(1.0 / s);
}

// c = cross(a, b): da = cross(b, dc), db = cross(dc, a)
template <class T, class A>
void d_cross(const TVec3<T>& a, const TVec3<T>& b, const TVec3<A>& dc, TVec3<A>& da, TVec3<A>& db) {
    da += cross(b, dc);
    db += cross(dc, a);
}

}  // namespace edgepath
