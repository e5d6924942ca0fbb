// A spot light's angular profile (Mitsuba's `spot`): the factor by which an emitter's radiance or
// intensity is scaled in an outgoing direction w, from the angle theta between w and the axis:
// 1 within the beam width b, 0 beyond the cutoff angle c, and (c - theta) / (c - b) between, so
// that the profile is continuous (its derivatives need no boundary term). Parameters, as the
// five values of its gradient slot: the axis (any length), the cutoff and the beam width in
// radians, 0 <= b < c <= pi. Generic in the scalar: the tests run it in double against finite
// differences.
#pragma once
#include <cmath>
#include "math/vec.h"

namespace edgepath {

constexpr int kSpotParams = 5;

// The profile for the unit direction w; `p` holds the kSpotParams values.
template <class T>
T spot_falloff(const T* p, const TVec3<T>& w) {
    const TVec3<T> a(p[0], p[1], p[2]);
    const T c = std::min(T(1), std::max(T(-1), dot(w, a) / length(a)));
    const T cutoff = p[3], beam = p[4];
    const T theta = std::acos(c);
    if (theta >= cutoff) return T(0);
    if (theta <= beam) return T(1);
    return (cutoff - theta) / (cutoff - beam);
}

// Adjoint: adds d(profile)/d(parameters) * d_out to dp[0..4] and d(profile)/dw * d_out to dw.
template <class T>
void d_spot_falloff(const T* p, const TVec3<T>& w, T d_out, T* dp, TVec3<T>& dw) {
    const TVec3<T> a(p[0], p[1], p[2]);
    const T la = length(a);
    const TVec3<T> u = a / la;
    const T c = dot(w, u);
    const T cutoff = p[3], beam = p[4];
    if (!(c < T(1)) || c <= T(-1)) return;  // theta 0 (inside the beam) or pi: flat
    const T theta = std::acos(c);
    if (theta >= cutoff || theta <= beam) return;
    const T width = cutoff - beam;
    // f = (cutoff - theta) / width
    dp[3] += d_out * (theta - beam) / (width * width);
    dp[4] += d_out * (cutoff - theta) / (width * width);
    const T d_theta = -d_out / width;
    // theta = acos(c), c = dot(w, a) / |a|
    const T d_c = -d_theta / std::sqrt(std::max(T(1) - c * c, T(1e-30)));
    const TVec3<T> da = (w - u * c) * (d_c / la);
    dp[0] += da.x;
    dp[1] += da.y;
    dp[2] += da.z;
    dw += u * d_c;
}

}  // namespace edgepath
