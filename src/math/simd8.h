// Eight floats at once (AVX2): math/simd4.h's operations on 256-bit vectors, for the forward
// pass's batched shading on processors that have AVX2 (render/shade_lanes_avx2.cpp, chosen at
// run time). As with SSE2, AVX's add, subtract, multiply, divide and square root round each lane
// as the scalar instructions do, and nothing here is fused (no FMA), so a lane's result is the
// scalar code's bit for bit as long as the same operations run in the same order; the
// comparisons and selections follow C++'s semantics as simd4.h's do.
//
// Only a translation unit that compiles its code for AVX2 includes this header: every function
// here needs AVX2, so it must be included after `#pragma GCC target("avx2")` (or the clang
// equivalent), with <immintrin.h> and every other header included before it, so that the
// inline functions those headers define stay compiled for the baseline processor.
#pragma once

namespace edgepath {
namespace avx2 {

struct F8 {
    static constexpr int width = 8;
    __m256 v;
    F8() = default;
    F8(__m256 x) : v(x) {}
    F8(float s) : v(_mm256_set1_ps(s)) {}
    static F8 load(const float* p) { return _mm256_load_ps(p); }  // 32-byte aligned
    void store(float* p) const { _mm256_store_ps(p, v); }
};

// A lane mask: all bits set where true.
struct M8 {
    __m256 v;
    M8() = default;
    M8(__m256 x) : v(x) {}
    static M8 load(const float* p) { return _mm256_load_ps(p); }
    void store(float* p) const { _mm256_store_ps(p, v); }
    int bits() const { return _mm256_movemask_ps(v); }  // bit i: lane i
};

inline F8 operator+(F8 a, F8 b) { return _mm256_add_ps(a.v, b.v); }
inline F8 operator-(F8 a, F8 b) { return _mm256_sub_ps(a.v, b.v); }
inline F8 operator*(F8 a, F8 b) { return _mm256_mul_ps(a.v, b.v); }
inline F8 operator/(F8 a, F8 b) { return _mm256_div_ps(a.v, b.v); }
inline F8 operator-(F8 a) { return _mm256_xor_ps(a.v, _mm256_set1_ps(-0.f)); }
inline F8 sqrt(F8 a) { return _mm256_sqrt_ps(a.v); }
inline F8 abs(F8 a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.f), a.v); }
// std::copysign(1, a).
inline F8 sign_of(F8 a) { return _mm256_or_ps(_mm256_and_ps(a.v, _mm256_set1_ps(-0.f)), _mm256_set1_ps(1.f)); }

// The ordered predicates are false where either side is NaN, as C++'s <, <=, >, >=, ==.
inline M8 operator<(F8 a, F8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ); }
inline M8 operator<=(F8 a, F8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ); }
inline M8 operator>(F8 a, F8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ); }
inline M8 operator>=(F8 a, F8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ); }
inline M8 operator==(F8 a, F8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_EQ_OQ); }
// !(a > b): true for NaN.
inline M8 not_greater(F8 a, F8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_NGT_UQ); }
inline M8 operator&(M8 a, M8 b) { return _mm256_and_ps(a.v, b.v); }
inline M8 operator|(M8 a, M8 b) { return _mm256_or_ps(a.v, b.v); }
inline M8 operator!(M8 a) { return _mm256_xor_ps(a.v, _mm256_castsi256_ps(_mm256_set1_epi32(-1))); }
inline M8 and_not(M8 a, M8 b) { return _mm256_andnot_ps(b.v, a.v); }  // a && !b

// m ? a : b, lane by lane (the masks have every bit of a lane set or none).
inline F8 select(M8 m, F8 a, F8 b) { return _mm256_blendv_ps(b.v, a.v, m.v); }
inline M8 select(M8 m, M8 a, M8 b) { return _mm256_blendv_ps(b.v, a.v, m.v); }
// std::max(a, b) (a unless a < b), std::min(a, b) (a unless b < a).
inline F8 max_std(F8 a, F8 b) { return select(a < b, b, a); }
inline F8 min_std(F8 a, F8 b) { return select(b < a, b, a); }
// std::isfinite.
inline M8 is_finite(F8 a) { return abs(a) < F8(std::numeric_limits<float>::infinity()); }

// next_float_up (math/ray.h), lane by lane: +inf and NaN stay, zeros become the smallest
// subnormal, otherwise one step of the bits.
inline F8 next_float_up(F8 x) {
    const __m256i b = _mm256_castps_si256(x.v);
    const __m256i one = _mm256_set1_epi32(1);
    const M8 pos = x > F8(0.f);
    const F8 stepped = select(pos, F8(_mm256_castsi256_ps(_mm256_add_epi32(b, one))),
                              F8(_mm256_castsi256_ps(_mm256_sub_epi32(b, one))));
    const F8 r = select(x == F8(0.f), F8(_mm256_castsi256_ps(one)), stepped);
    const M8 finite_or_neg = x < F8(std::numeric_limits<float>::infinity());
    return select(finite_or_neg, r, x);
}
inline F8 next_float_down(F8 x) { return -next_float_up(-x); }

// Three lanes' vectors (simd4.h's V4).
struct V8 {
    F8 x, y, z;
    V8() = default;
    V8(F8 x_, F8 y_, F8 z_) : x(x_), y(y_), z(z_) {}
    explicit V8(F8 s) : x(s), y(s), z(s) {}
};

inline V8 operator+(const V8& a, const V8& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V8 operator-(const V8& a, const V8& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V8 operator*(const V8& a, const V8& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
inline V8 operator*(const V8& a, F8 s) { return {a.x * s, a.y * s, a.z * s}; }
// As Vec3f's operator/: a times the reciprocal of s.
inline V8 operator/(const V8& a, F8 s) { return a * (F8(1.f) / s); }
inline V8 operator-(const V8& a) { return {-a.x, -a.y, -a.z}; }
inline F8 dot(const V8& a, const V8& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline F8 length(const V8& a) { return sqrt(dot(a, a)); }
// normalize (math/vec.h): a / |a|, a itself where |a| is not positive.
inline V8 normalize(const V8& a) {
    const F8 l = length(a);
    const V8 n = a / l;
    const M8 ok = l > F8(0.f);
    return {select(ok, n.x, a.x), select(ok, n.y, a.y), select(ok, n.z, a.z)};
}
inline V8 select(M8 m, const V8& a, const V8& b) { return {select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z)}; }
inline M8 is_black(const V8& c) { return (c.x == F8(0.f)) & (c.y == F8(0.f)) & (c.z == F8(0.f)); }

}  // namespace avx2
}  // namespace edgepath
