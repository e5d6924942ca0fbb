// Adjoints of the vector helpers of math/vec.h that the gradient pass needs.
#pragma once
#include "math/vec.h"

namespace edgepath {

// n = v / |v|
template <class T>
TVec3<T> d_normalize(const TVec3<T>& v, const TVec3<T>& dn) {
    T l = length(v);
    if (!(l > 0)) return TVec3<T>(T(0));
    TVec3<T> n = v / l;
    return (dn - n * dot(n, dn)) / l;
}

// c = cross(a, b): da = cross(b, dc), db = cross(dc, a)
template <class T>
void d_cross(const TVec3<T>& a, const TVec3<T>& b, const TVec3<T>& dc, TVec3<T>& da, TVec3<T>& db) {
    da += cross(b, dc);
    db += cross(dc, a);
}

}  // namespace edgepath
