// shade_lanes in SSE2's vectors (math/simd4.h), and the choice of width at run time.
#include "render/shade_lanes.h"

#include <atomic>
#include <stdexcept>

#include "math/simd4.h"
#include "render/shade_kernel.h"

namespace edgepath {

// render/shade_lanes_avx2.cpp: whether it was compiled with its AVX2 code, and that code.
bool shade_lanes_avx2_compiled();
void shade_lanes_avx2(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy);

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
        shade_lanes_kernel<F4, M4, V4, true>(L, n, mis);
    } else {
        shade_lanes_kernel<F4, M4, V4, false>(L, n, mis);
    }
}

void shade_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy) {
    shade_lanes(L, n, mis, glossy, shade_width());
}

}  // namespace edgepath
