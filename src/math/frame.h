// Orthonormal frames around a normal.
#pragma once
#include "math/vec.h"

namespace edgepath {

template <class T>
struct TFrame {
    TVec3<T> s, t, n;
    TFrame() = default;
    // Builds tangents from n with the branchless construction of Duff et al. (JCGT 2017).
    explicit TFrame(const TVec3<T>& normal) : n(normal) {
        T sign = std::copysign(T(1), n.z);
        T a = T(-1) / (sign + n.z);
        T b = n.x * n.y * a;
        s = TVec3<T>(T(1) + sign * n.x * n.x * a, sign * b, -sign * n.x);
        t = TVec3<T>(b, sign + n.y * n.y * a, -n.y);
    }
    TVec3<T> to_local(const TVec3<T>& v) const { return {dot(v, s), dot(v, t), dot(v, n)}; }
    TVec3<T> to_world(const TVec3<T>& v) const { return s * v.x + t * v.y + n * v.z; }
};

using Frame = TFrame<float>;

}  // namespace edgepath
