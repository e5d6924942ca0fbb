// shade_lanes in SSE2's vectors (math/simd4.h), and the choice of width at run time.
#include "render/shade_lanes.h"

#include <atomic>
#include <stdexcept>

#include "math/simd4.h"
#include "render/shade_kernel.h"
#include "scene/bsdf.h"

namespace edgepath {

// render/shade_lanes_avx2.cpp: whether it was compiled with its AVX2 code, and that code.
bool shade_lanes_avx2_compiled();
void shade_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy);
void shade_plastic_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n, bool mis);
void shade_mirror_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n);

namespace {

bool processor_has_avx2() {
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
    // libgcc's check includes the operating system's support of the 256-bit registers.
    return __builtin_cpu_supports("avx2");
#else
    return false;
#endif
}

ShadeWidth widest() {
    static const ShadeWidth w = shade_lanes_avx2_compiled() && processor_has_avx2() ? ShadeWidth::Avx2 : ShadeWidth::Sse2;
    return w;
}

std::atomic<int> forced{int(ShadeWidth::Auto)};

}  // namespace

bool shade_width_available(ShadeWidth w) {
    return w != ShadeWidth::Avx2 || widest() == ShadeWidth::Avx2;
}

ShadeWidth shade_width() {
    const ShadeWidth f = ShadeWidth(forced.load(std::memory_order_relaxed));
    return f == ShadeWidth::Auto ? widest() : f;
}

void force_shade_width(ShadeWidth w) {
    if (!shade_width_available(w))
        throw std::invalid_argument("force_shade_width: AVX2 is not available on this processor or in this build");
    forced.store(int(w), std::memory_order_relaxed);
}

void shade_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy, ShadeWidth w) {
    if (w == ShadeWidth::Auto) w = shade_width();
    if (w == ShadeWidth::Avx2) {
        if (!shade_width_available(w)) throw std::invalid_argument("shade_lanes: AVX2 is not available");
        shade_lanes_avx2(L, n, mis, glossy);
    } else if (glossy) {
        shade_lanes_kernel<F4, M4, V4, true, false>(L, n, mis);
    } else {
        shade_lanes_kernel<F4, M4, V4, false, false>(L, n, mis);
    }
}

void shade_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy) {
    shade_lanes(L, n, mis, glossy, shade_width());
}

void shade_plastic_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, ShadeWidth w) {
    if (w == ShadeWidth::Auto) w = shade_width();
    if (w == ShadeWidth::Avx2) {
        if (!shade_width_available(w)) throw std::invalid_argument("shade_plastic_lanes: AVX2 is not available");
        shade_plastic_lanes_avx2(L, n, mis);
    } else {
        shade_lanes_kernel<F4, M4, V4, false, true>(L, n, mis);
    }
}

void shade_plastic_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis) {
    shade_plastic_lanes(L, n, mis, shade_width());
}

void shade_mirror_lanes(ShadeLanes<kShadeBatch>& L, int n, ShadeWidth w) {
    if (w == ShadeWidth::Auto) w = shade_width();
    if (w == ShadeWidth::Avx2) {
        if (!shade_width_available(w)) throw std::invalid_argument("shade_mirror_lanes: AVX2 is not available");
        shade_mirror_lanes_avx2(L, n);
    } else {
        shade_mirror_lanes_kernel<F4, M4, V4>(L, n);
    }
}

void shade_mirror_lanes(ShadeLanes<kShadeBatch>& L, int n) { shade_mirror_lanes(L, n, shade_width()); }

// The plastic's table lookups, path by path, with the scalar code's functions themselves (a
// lane past the batch's paths may hold no table, or a rough one a NaN cosine, which has no
// entry: 0 there, never read back).
namespace {
float lane_transmittance(const ShadeLanes<kShadeBatch>& L, int k, float c) {
    const CoatTable* t = L.coat[k];
    return t && (t->smooth || !std::isnan(c)) ? detail::coat_transmittance(*t, c, L.eta[k]) : 0.f;
}
}  // namespace

void plastic_coat_transmittances(const ShadeLanes<kShadeBatch>& L, int k, int count, float* c) {
    for (int j = 0; j < count; ++j) c[j] = lane_transmittance(L, k + j, c[j]);
}

void plastic_coat_probabilities(const ShadeLanes<kShadeBatch>& L, int k, int count, const float* co, float* t_o,
                                float* ps) {
    for (int j = k; j < k + count; ++j) {
        t_o[j] = lane_transmittance(L, j, co[j]);
        ps[j] = plastic_coat_probability(L.ks[j], L.kd[j], t_o[j]);
    }
}

}  // namespace edgepath
