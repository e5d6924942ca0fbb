// shade_lanes in AVX2's vectors, eight paths at a time (math/simd8.h), for processors that have
// AVX2 (render/shade_lanes.cpp checks at run time before calling it). Only the code after the
// target switch below is compiled for AVX2: every header is included before it, so that the
// inline functions they define (which the linker may take from this file for the whole
// program) stay compiled for the baseline processor. No FMA: the products and sums round one by
// one, as the scalar code's do (and the build adds -ffp-contract=off for this file).
#include <cmath>
#include <cstring>
#include <limits>

#include "math/ray.h"
#include "render/shade_lanes.h"
#include "sampling/warp.h"
#include "scene/bsdf_diff.h"

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define EDGEPATH_AVX2 1
#include <immintrin.h>
#pragma GCC push_options
#pragma GCC target("avx2")
#elif defined(__x86_64__) && defined(__clang__)
#define EDGEPATH_AVX2 1
#include <immintrin.h>
#pragma clang attribute push(__attribute__((target("avx2"))), apply_to = function)
#endif

#if EDGEPATH_AVX2
#include "math/simd8.h"
#include "render/shade_kernel.h"

namespace edgepath {

void shade_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy) {
    if (glossy)
        shade_lanes_kernel<avx2::F8, avx2::M8, avx2::V8, true, false>(L, n, mis);
    else
        shade_lanes_kernel<avx2::F8, avx2::M8, avx2::V8, false, false>(L, n, mis);
}
void shade_plastic_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n, bool mis) {
    shade_lanes_kernel<avx2::F8, avx2::M8, avx2::V8, false, true>(L, n, mis);
}
void shade_mirror_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n) {
    shade_mirror_lanes_kernel<avx2::F8, avx2::M8, avx2::V8>(L, n);
}

}  // namespace edgepath

#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif

namespace edgepath {

#if EDGEPATH_AVX2
bool shade_lanes_avx2_compiled() { return true; }
#else
bool shade_lanes_avx2_compiled() { return false; }
void shade_lanes_avx2(ShadeLanes<kShadeBatch>&, int, bool, bool) {}  // never called: not compiled
void shade_plastic_lanes_avx2(ShadeLanes<kShadeBatch>&, int, bool) {}
void shade_mirror_lanes_avx2(ShadeLanes<kShadeBatch>&, int) {}
#endif

}  // namespace edgepath
