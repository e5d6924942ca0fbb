// Four floats at once (SSE2, part of every x86-64 processor): the operations the forward pass's
// batched shading (render/shade_lanes.h) needs, each lane computed as the scalar float code
// computes it. SSE2's add, subtract, multiply, divide and square root round as the scalar
// instructions do (IEEE single precision, round to nearest), so a lane's result is the scalar
// code's bit for bit as long as the same operations run in the same order; the comparisons and
// selections below follow C++'s semantics (NaN compares false; std::max's choice on ties).
// Elsewhere (a processor without SSE2) the same types hold four floats that each operation
// runs through one by one, with the same results.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "math/ray.h"
#include "math/vec.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace edgepath {

#if defined(__SSE2__)

struct F4 {
    static constexpr int width = 4;
    __m128 v;
    F4() = default;
    F4(__m128 x) : v(x) {}
    F4(float s) : v(_mm_set1_ps(s)) {}
    static F4 load(const float* p) { return _mm_load_ps(p); }  // 16-byte aligned
    static F4 loadu(const float* p) { return _mm_loadu_ps(p); }  // any alignment
    void store(float* p) const { _mm_store_ps(p, v); }
};

// A lane mask: all bits set where true.
struct M4 {
    __m128 v;
    M4() = default;
    M4(__m128 x) : v(x) {}
    static M4 load(const float* p) { return _mm_load_ps(p); }
    void store(float* p) const { _mm_store_ps(p, v); }
    int bits() const { return _mm_movemask_ps(v); }  // bit i: lane i
};

inline F4 operator+(F4 a, F4 b) { return _mm_add_ps(a.v, b.v); }
inline F4 operator-(F4 a, F4 b) { return _mm_sub_ps(a.v, b.v); }
inline F4 operator*(F4 a, F4 b) { return _mm_mul_ps(a.v, b.v); }
inline F4 operator/(F4 a, F4 b) { return _mm_div_ps(a.v, b.v); }
inline F4 operator-(F4 a) { return _mm_xor_ps(a.v, _mm_set1_ps(-0.f)); }
inline F4 sqrt(F4 a) { return _mm_sqrt_ps(a.v); }
inline F4 abs(F4 a) { return _mm_andnot_ps(_mm_set1_ps(-0.f), a.v); }
// std::copysign(1, a).
inline F4 sign_of(F4 a) { return _mm_or_ps(_mm_and_ps(a.v, _mm_set1_ps(-0.f)), _mm_set1_ps(1.f)); }

inline M4 operator<(F4 a, F4 b) { return _mm_cmplt_ps(a.v, b.v); }
inline M4 operator<=(F4 a, F4 b) { return _mm_cmple_ps(a.v, b.v); }
inline M4 operator>(F4 a, F4 b) { return _mm_cmpgt_ps(a.v, b.v); }
inline M4 operator>=(F4 a, F4 b) { return _mm_cmpge_ps(a.v, b.v); }
inline M4 operator==(F4 a, F4 b) { return _mm_cmpeq_ps(a.v, b.v); }
// !(a > b), !(a < b): true for NaN.
inline M4 not_greater(F4 a, F4 b) { return _mm_cmpngt_ps(a.v, b.v); }
inline M4 operator&(M4 a, M4 b) { return _mm_and_ps(a.v, b.v); }
inline M4 operator|(M4 a, M4 b) { return _mm_or_ps(a.v, b.v); }
inline M4 operator!(M4 a) { return _mm_xor_ps(a.v, _mm_castsi128_ps(_mm_set1_epi32(-1))); }
inline M4 and_not(M4 a, M4 b) { return _mm_andnot_ps(b.v, a.v); }  // a && !b

// m ? a : b, lane by lane.
inline F4 select(M4 m, F4 a, F4 b) { return _mm_or_ps(_mm_and_ps(m.v, a.v), _mm_andnot_ps(m.v, b.v)); }
inline M4 select(M4 m, M4 a, M4 b) { return _mm_or_ps(_mm_and_ps(m.v, a.v), _mm_andnot_ps(m.v, b.v)); }
// std::max(a, b) (a unless a < b), std::min(a, b) (a unless b < a).
inline F4 max_std(F4 a, F4 b) { return select(a < b, b, a); }
inline F4 min_std(F4 a, F4 b) { return select(b < a, b, a); }
// std::isfinite.
inline M4 is_finite(F4 a) { return abs(a) < F4(std::numeric_limits<float>::infinity()); }

// next_float_up (math/ray.h), lane by lane: +inf and NaN stay, zeros become the smallest
// subnormal, otherwise one step of the bits.
inline F4 next_float_up(F4 x) {
    const __m128i b = _mm_castps_si128(x.v);
    const __m128i one = _mm_set1_epi32(1);
    const M4 pos = x > F4(0.f);
    __m128i r = _mm_castps_si128(select(pos, F4(_mm_castsi128_ps(_mm_add_epi32(b, one))),
                                        F4(_mm_castsi128_ps(_mm_sub_epi32(b, one))))
                                     .v);
    r = _mm_castps_si128(select(x == F4(0.f), F4(_mm_castsi128_ps(one)), F4(_mm_castsi128_ps(r))).v);
    const M4 finite_or_neg = x < F4(std::numeric_limits<float>::infinity());
    return select(finite_or_neg, F4(_mm_castsi128_ps(r)), x);
}
inline F4 next_float_down(F4 x) { return -next_float_up(-x); }

#else  // no SSE2: lane by lane

struct F4 {
    static constexpr int width = 4;
    float v[4];
    F4() = default;
    F4(float s) : v{s, s, s, s} {}
    static F4 load(const float* p) {
        F4 r;
        std::memcpy(r.v, p, sizeof r.v);
        return r;
    }
    static F4 loadu(const float* p) { return load(p); }
    void store(float* p) const { std::memcpy(p, v, sizeof v); }
};

struct M4 {
    uint32_t v[4];  // all bits set where true
    static M4 load(const float* p) {
        M4 r;
        std::memcpy(r.v, p, sizeof r.v);
        return r;
    }
    void store(float* p) const { std::memcpy(p, v, sizeof v); }
    int bits() const { return int((v[0] >> 31) | ((v[1] >> 31) << 1) | ((v[2] >> 31) << 2) | ((v[3] >> 31) << 3)); }
};

template <class Op>
inline F4 lanes_of(Op op) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = op(i);
    return r;
}
template <class Op>
inline M4 mask_of(Op op) {
    M4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = op(i) ? ~0u : 0u;
    return r;
}

inline F4 operator+(F4 a, F4 b) { return lanes_of([&](int i) { return a.v[i] + b.v[i]; }); }
inline F4 operator-(F4 a, F4 b) { return lanes_of([&](int i) { return a.v[i] - b.v[i]; }); }
inline F4 operator*(F4 a, F4 b) { return lanes_of([&](int i) { return a.v[i] * b.v[i]; }); }
inline F4 operator/(F4 a, F4 b) { return lanes_of([&](int i) { return a.v[i] / b.v[i]; }); }
inline F4 operator-(F4 a) { return lanes_of([&](int i) { return -a.v[i]; }); }
inline F4 sqrt(F4 a) { return lanes_of([&](int i) { return std::sqrt(a.v[i]); }); }
inline F4 abs(F4 a) { return lanes_of([&](int i) { return std::fabs(a.v[i]); }); }
inline F4 sign_of(F4 a) { return lanes_of([&](int i) { return std::copysign(1.f, a.v[i]); }); }

inline M4 operator<(F4 a, F4 b) { return mask_of([&](int i) { return a.v[i] < b.v[i]; }); }
inline M4 operator<=(F4 a, F4 b) { return mask_of([&](int i) { return a.v[i] <= b.v[i]; }); }
inline M4 operator>(F4 a, F4 b) { return mask_of([&](int i) { return a.v[i] > b.v[i]; }); }
inline M4 operator>=(F4 a, F4 b) { return mask_of([&](int i) { return a.v[i] >= b.v[i]; }); }
inline M4 operator==(F4 a, F4 b) { return mask_of([&](int i) { return a.v[i] == b.v[i]; }); }
inline M4 not_greater(F4 a, F4 b) { return mask_of([&](int i) { return !(a.v[i] > b.v[i]); }); }
inline M4 operator&(M4 a, M4 b) { return mask_of([&](int i) { return (a.v[i] & b.v[i]) != 0; }); }
inline M4 operator|(M4 a, M4 b) { return mask_of([&](int i) { return (a.v[i] | b.v[i]) != 0; }); }
inline M4 operator!(M4 a) { return mask_of([&](int i) { return a.v[i] == 0; }); }
inline M4 and_not(M4 a, M4 b) { return mask_of([&](int i) { return a.v[i] != 0 && b.v[i] == 0; }); }

inline F4 select(M4 m, F4 a, F4 b) { return lanes_of([&](int i) { return m.v[i] ? a.v[i] : b.v[i]; }); }
inline M4 select(M4 m, M4 a, M4 b) { return mask_of([&](int i) { return (m.v[i] ? a.v[i] : b.v[i]) != 0; }); }
inline F4 max_std(F4 a, F4 b) { return lanes_of([&](int i) { return std::max(a.v[i], b.v[i]); }); }
inline F4 min_std(F4 a, F4 b) { return lanes_of([&](int i) { return std::min(a.v[i], b.v[i]); }); }
inline M4 is_finite(F4 a) { return mask_of([&](int i) { return std::isfinite(a.v[i]); }); }
inline F4 next_float_up(F4 x) { return lanes_of([&](int i) { return edgepath::next_float_up(x.v[i]); }); }
inline F4 next_float_down(F4 x) { return lanes_of([&](int i) { return edgepath::next_float_down(x.v[i]); }); }

#endif

// Three lanes' vectors.
struct V4 {
    F4 x, y, z;
    V4() = default;
    V4(F4 x_, F4 y_, F4 z_) : x(x_), y(y_), z(z_) {}
    explicit V4(F4 s) : x(s), y(s), z(s) {}
};

inline V4 operator+(const V4& a, const V4& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V4 operator-(const V4& a, const V4& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V4 operator*(const V4& a, const V4& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
inline V4 operator*(const V4& a, F4 s) { return {a.x * s, a.y * s, a.z * s}; }
// As Vec3f's operator/: a times the reciprocal of s.
inline V4 operator/(const V4& a, F4 s) { return a * (F4(1.f) / s); }
inline V4 operator-(const V4& a) { return {-a.x, -a.y, -a.z}; }
inline F4 dot(const V4& a, const V4& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline F4 length(const V4& a) { return sqrt(dot(a, a)); }
// normalize (math/vec.h): a / |a|, a itself where |a| is not positive.
inline V4 normalize(const V4& a) {
    const F4 l = length(a);
    const V4 n = a / l;
    const M4 ok = l > F4(0.f);
    return {select(ok, n.x, a.x), select(ok, n.y, a.y), select(ok, n.z, a.z)};
}
inline V4 select(M4 m, const V4& a, const V4& b) { return {select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z)}; }
inline M4 is_black(const V4& c) { return (c.x == F4(0.f)) & (c.y == F4(0.f)) & (c.z == F4(0.f)); }

}  // namespace edgepath
