// Adjoint types of the gradient pass's sweep (diff/backprop.h). The sweep is linear in its
// adjoint; its colour operations are component-wise (throughputs, reflectances, emission), so the
// adjoint of an RGB quantity with the unit adjoint of colour c stays zero outside channel c. Only
// the scalar adjoints (positions, normals, directions, roughness, uvs: anything the forward pass
// computes from a reduction over colours) mix the colours. A derivative image (three outputs per
// pixel) therefore sweeps once with the adjoint (1, 1, 1): its RGB adjoints stay Vec3f, channel c
// belonging to colour c, and its scalar adjoints are Adj3, one lane per output colour. The
// gradient pass (one output, the loss) sweeps with float scalar adjoints; the helpers below then
// reduce to the float expressions (dot, sums) that the sweep always had.
#pragma once
#include <type_traits>
#include "math/vec.h"

#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

namespace edgepath {

// A scalar adjoint for each of the three output colours.
struct Adj3 {
    float v[3] = {0.f, 0.f, 0.f};
    Adj3() = default;
    explicit Adj3(float s) : v{s, s, s} {}
    Adj3(float a, float b, float c) : v{a, b, c} {}
    Adj3& operator+=(const Adj3& o) {
        v[0] += o.v[0];
        v[1] += o.v[1];
        v[2] += o.v[2];
        return *this;
    }
    Adj3& operator-=(const Adj3& o) {
        v[0] -= o.v[0];
        v[1] -= o.v[1];
        v[2] -= o.v[2];
        return *this;
    }
};

inline Adj3 operator+(Adj3 a, const Adj3& b) { return a += b; }
inline Adj3 operator-(Adj3 a, const Adj3& b) { return a -= b; }
inline Adj3 operator-(const Adj3& a) { return {-a.v[0], -a.v[1], -a.v[2]}; }
inline Adj3 operator*(const Adj3& a, float s) { return {a.v[0] * s, a.v[1] * s, a.v[2] * s}; }
inline Adj3 operator*(float s, const Adj3& a) { return {s * a.v[0], s * a.v[1], s * a.v[2]}; }
inline Adj3 operator/(const Adj3& a, float s) { return {a.v[0] / s, a.v[1] / s, a.v[2] / s}; }
inline bool is_zero(const Adj3& a) { return a.v[0] == 0.f && a.v[1] == 0.f && a.v[2] == 0.f; }
inline bool is_zero(float a) { return a == 0.f; }

// Geometric vectors of Adj3 (one vector per colour) against float vectors, mirroring the
// expressions of math/vec.h lane by lane.
using AVec3 = TVec3<Adj3>;
using AVec2 = TVec2<Adj3>;

inline AVec3 operator*(const Vec3f& a, const Adj3& s) { return {a.x * s, a.y * s, a.z * s}; }
inline AVec3 operator*(const Adj3& s, const Vec3f& a) { return {a.x * s, a.y * s, a.z * s}; }
inline AVec3 operator*(const AVec3& a, float s) { return {a.x * s, a.y * s, a.z * s}; }
inline AVec3 operator*(float s, const AVec3& a) { return {a.x * s, a.y * s, a.z * s}; }
// As TVec3::operator/=: a multiplication by the reciprocal.
inline AVec3 operator/(const AVec3& a, float s) {
    const float r = 1.f / s;
    return {a.x * r, a.y * r, a.z * r};
}
inline Adj3 dot(const Vec3f& a, const AVec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Adj3 dot(const AVec3& a, const Vec3f& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline AVec3 cross(const Vec3f& a, const AVec3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline AVec3 cross(const AVec3& a, const Vec3f& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline bool is_black(const AVec3& a) { return is_zero(a.x) && is_zero(a.y) && is_zero(a.z); }

// A scalar adjoint for each of N output values (the output channels' values of a derivative
// image, diff/channels.h): lane j is what a sweep with the unit adjoint of value j alone would
// compute, by the same float operations (those of Adj3, lane by lane).
template <int N>
struct AdjN {
    static_assert(N % 4 == 0, "lanes in fours");
    alignas(16) float v[N];
    AdjN() { fill(0.f); }
    explicit AdjN(float s) { fill(s); }
    // Four lanes at a time (SSE2: each lane rounds as the scalar instruction does). The value
    // passes through an empty asm statement so that the compiler cannot see a zero fill: it
    // would make that a memset ('rep stos'), several times slower at these sizes.
    void fill(float s) {
#if defined(__SSE2__)
        __m128 x = _mm_set1_ps(s);
        __asm__("" : "+x"(x));
        for (int k = 0; k < N; k += 4) _mm_store_ps(v + k, x);
#else
        for (int j = 0; j < N; ++j) v[j] = s;
#endif
    }
    AdjN& operator+=(const AdjN& o) {
#if defined(__SSE2__)
        for (int k = 0; k < N; k += 4) _mm_store_ps(v + k, _mm_add_ps(_mm_load_ps(v + k), _mm_load_ps(o.v + k)));
#else
        for (int j = 0; j < N; ++j) v[j] += o.v[j];
#endif
        return *this;
    }
    AdjN& operator-=(const AdjN& o) {
#if defined(__SSE2__)
        for (int k = 0; k < N; k += 4) _mm_store_ps(v + k, _mm_sub_ps(_mm_load_ps(v + k), _mm_load_ps(o.v + k)));
#else
        for (int j = 0; j < N; ++j) v[j] -= o.v[j];
#endif
        return *this;
    }
    AdjN& operator*=(float s) {
#if defined(__SSE2__)
        const __m128 x = _mm_set1_ps(s);
        for (int k = 0; k < N; k += 4) _mm_store_ps(v + k, _mm_mul_ps(_mm_load_ps(v + k), x));
#else
        for (int j = 0; j < N; ++j) v[j] *= s;
#endif
        return *this;
    }
    AdjN& operator/=(float s) {
#if defined(__SSE2__)
        const __m128 x = _mm_set1_ps(s);
        for (int k = 0; k < N; k += 4) _mm_store_ps(v + k, _mm_div_ps(_mm_load_ps(v + k), x));
#else
        for (int j = 0; j < N; ++j) v[j] /= s;
#endif
        return *this;
    }
    // -x flips the sign bit, as the scalar negation does (zeros included).
    AdjN negated() const {
        AdjN r(*this);
#if defined(__SSE2__)
        const __m128 sign = _mm_set1_ps(-0.f);
        for (int k = 0; k < N; k += 4) _mm_store_ps(r.v + k, _mm_xor_ps(_mm_load_ps(v + k), sign));
#else
        for (int j = 0; j < N; ++j) r.v[j] = -v[j];
#endif
        return r;
    }
};
// The most lanes a GradSink projects (at least every continuous value of the output channels,
// render/channels.h).
constexpr int kMaxAdjLanes = 32;

template <int N> inline AdjN<N> operator+(AdjN<N> a, const AdjN<N>& b) { return a += b; }
template <int N> inline AdjN<N> operator-(AdjN<N> a, const AdjN<N>& b) { return a -= b; }
template <int N> inline AdjN<N> operator-(const AdjN<N>& a) { return a.negated(); }
template <int N> inline AdjN<N> operator*(AdjN<N> a, float s) { return a *= s; }
// s * a: multiplication commutes exactly in IEEE arithmetic.
template <int N> inline AdjN<N> operator*(float s, AdjN<N> a) { return a *= s; }
template <int N> inline AdjN<N> operator/(AdjN<N> a, float s) { return a /= s; }
template <int N> inline bool is_zero(const AdjN<N>& a) {
    for (int j = 0; j < N; ++j)
        if (a.v[j] != 0.f) return false;
    return true;
}

template <int N> inline TVec3<AdjN<N>> operator*(const Vec3f& a, const AdjN<N>& s) { return {a.x * s, a.y * s, a.z * s}; }
template <int N> inline TVec3<AdjN<N>> operator*(const AdjN<N>& s, const Vec3f& a) { return {a.x * s, a.y * s, a.z * s}; }
template <int N> inline TVec3<AdjN<N>> operator*(const TVec3<AdjN<N>>& a, float s) { return {a.x * s, a.y * s, a.z * s}; }
template <int N> inline TVec3<AdjN<N>> operator*(float s, const TVec3<AdjN<N>>& a) { return {a.x * s, a.y * s, a.z * s}; }
// As TVec3::operator/=: a multiplication by the reciprocal.
template <int N> inline TVec3<AdjN<N>> operator/(const TVec3<AdjN<N>>& a, float s) {
    const float r = 1.f / s;
    return {a.x * r, a.y * r, a.z * r};
}
template <int N> inline AdjN<N> dot(const Vec3f& a, const TVec3<AdjN<N>>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <int N> inline AdjN<N> dot(const TVec3<AdjN<N>>& a, const Vec3f& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <int N> inline TVec3<AdjN<N>> cross(const Vec3f& a, const TVec3<AdjN<N>>& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <int N> inline TVec3<AdjN<N>> cross(const TVec3<AdjN<N>>& a, const Vec3f& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <int N> inline bool is_black(const TVec3<AdjN<N>>& a) { return is_zero(a.x) && is_zero(a.y) && is_zero(a.z); }
template <int N> inline Vec3f lane(const TVec3<AdjN<N>>& a, int j) { return {a.x.v[j], a.y.v[j], a.z.v[j]}; }
template <int N> inline void set_lane(TVec3<AdjN<N>>& a, int j, const Vec3f& v) {
    a.x.v[j] = v.x;
    a.y.v[j] = v.y;
    a.z.v[j] = v.z;
}

template <class A> struct is_adj_n : std::false_type {};
template <int N> struct is_adj_n<AdjN<N>> : std::true_type {};

// The number of lanes of a lane type (Adj3: 3, AdjN<N>: N).
template <class A> constexpr int kAdjLanes = 3;
template <int N> constexpr int kAdjLanes<AdjN<N>> = N;

// ---- the reductions over colours, per adjoint type ---------------------------------------------

// The scalar adjoint of s where the RGB quantity v s has the RGB adjoint `a`: dot(a, v), or for
// Adj3 the colours' own products.
template <class A, class T>
A colour_dot(const TVec3<T>& a, const TVec3<T>& v) {
    if constexpr (std::is_same_v<A, Adj3>)
        return {a.x * v.x, a.y * v.y, a.z * v.z};
    else
        return dot(a, v);
}
// The scalar adjoint of s where the RGB quantity is (s, s, s).
template <class A, class T>
A colour_sum(const TVec3<T>& a) {
    if constexpr (std::is_same_v<A, Adj3>)
        return {a.x, a.y, a.z};
    else
        return a.x + a.y + a.z;
}
// Channel c's part x of an RGB adjoint as a scalar adjoint.
template <class A, class T>
A one_colour(int c, T x) {
    if constexpr (std::is_same_v<A, Adj3>) {
        Adj3 r;
        r.v[c] = x;
        return r;
    } else {
        (void)c;
        return x;
    }
}

// Lanes: colour c's vector, and the way back (for the few adjoints computed lane by lane).
inline Vec3f lane(const AVec3& a, int c) { return {a.x.v[c], a.y.v[c], a.z.v[c]}; }
inline void set_lane(AVec3& a, int c, const Vec3f& v) {
    a.x.v[c] = v.x;
    a.y.v[c] = v.y;
    a.z.v[c] = v.z;
}
// Channel c of an RGB vector (the others zero).
inline Vec3f channel(const Vec3f& a, int c) {
    Vec3f r(0.f);
    r[c] = a[c];
    return r;
}

}  // namespace edgepath
