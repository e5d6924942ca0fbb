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

// c = cross(a, b): da = cross(b, dc), db = cross(dc, a)
template <class T, class A>
void d_cross(const TVec3<T>& a, const TVec3<T>& b, const TVec3<A>& dc, TVec3<A>& da, TVec3<A>& db) {
    da += cross(b, dc);
    db += cross(dc, a);
}

}  // namespace edgepath
