// The arithmetic of shade_lanes (render/shade_lanes.h), written once for any width of vector:
// F a vector of floats with its width F::width, M its lane mask, V three F (a vector of 3-vectors),
// with the operations of math/simd4.h (F4, M4, V4) or math/simd8.h (F8, M8, V8), found by
// argument-dependent lookup. Each lane performs scalar shade_vertex's floating-point operations
// in its order, whatever the width.
//
// Included by the translation units that compile it for one width each (render/shade_lanes.cpp,
// render/shade_lanes_avx2.cpp): the latter includes it after switching its code to AVX2, having
// included the headers below before the switch (their include guards then skip them here), so
// that their inline functions stay compiled for the baseline processor.
#pragma once
#include <cmath>

#include "math/ray.h"
#include "render/shade_lanes.h"
#include "sampling/warp.h"
#include "scene/bsdf_diff.h"

namespace edgepath {

namespace lanes {

template <class V, int N>
inline V load3(const float (&a)[3][N], int k) {
    using F = decltype(V::x);
    return {F::load(a[0] + k), F::load(a[1] + k), F::load(a[2] + k)};
}
template <class V, int N>
inline void store3(float (&a)[3][N], int k, const V& v) {
    v.x.store(a[0] + k);
    v.y.store(a[1] + k);
    v.z.store(a[2] + k);
}

// offset_ray_origin (math/ray.h).
template <class V>
inline V offset_ray_origin(const V& p, const V& p_error, const V& n, const V& w) {
    using F = decltype(V::x);
    const F d = abs(n.x) * p_error.x + abs(n.y) * p_error.y + abs(n.z) * p_error.z;
    const V offset = n * select(dot(w, n) < F(0.f), -d, d);
    const V o = p + offset;
    auto step = [](F off, F c) {
        return select(off > F(0.f), next_float_up(c), select(off < F(0.f), next_float_down(c), c));
    };
    return {step(offset.x, o.x), step(offset.y, o.y), step(offset.z, o.z)};
}

// The Lambertian lobe's f cos (bsdf_eval) and density (bsdf_pdf) for wi, with the two-sided
// material's mirroring (orient); `flip`: two-sided and wo below the surface.
template <class F, class M, class V>
inline void lambert(M flip, F wo_z, F wi_z, const V& diffuse, V& f, F& pdf) {
    const F oz = select(flip, -wo_z, wo_z), iz = select(flip, -wi_z, wi_z);
    const M up = (oz > F(0.f)) & (iz > F(0.f));
    f = select(up, diffuse * (iz * F(kInvPi)), V(F(0.f)));
    // (1 - ps) cos / pi with the specular lobe's probability ps = 0.
    pdf = select(up, F(1.f) * iz * F(kInvPi), F(0.f));
}

template <class F>
inline F mis_power_lanes(F a, F b) {
    a = a * a;
    b = b * b;
    return select(a > F(0.f), a / (a + b), F(0.f));
}

}  // namespace lanes

// Lanes [0, n) of L (n rounded up to whole vectors; the lanes past n are computed and ignored),
// F::width at a time: F a vector of floats, M its mask, V three of them (math/simd4.h's F, M,
// V or math/simd8.h's F8, M8, V8).
template <class F, class M, class V, int N>
inline void shade_lanes_kernel(ShadeLanes<N>& L, int n, bool mis) {
    using namespace lanes;
    constexpr int W = F::width;
    static_assert(N % W == 0, "whole vectors");
    const F zero(0.f), one(1.f);
    // square_to_disk (sampling/warp.h): the radius and angle, their cosine and sine, the point.
    alignas(64) float radius[N], angle[N], cosine[N], sine[N];
    for (int k = 0; k < n; k += W) {
        const F a = F(2.f) * F::load(L.disk[0] + k) - one, b = F(2.f) * F::load(L.disk[1] + k) - one;
        const M wide = abs(a) > abs(b);
        select(wide, a, b).store(radius + k);
        select(wide, F(kPi / 4.f) * (b / a), F(kPi / 2.f) - F(kPi / 4.f) * (a / b)).store(angle + k);
    }
    for (int k = 0; k < n; ++k) {
        cosine[k] = std::cos(angle[k]);
        sine[k] = std::sin(angle[k]);
    }
    for (int k = 0; k < n; k += W) {
        const F a = F(2.f) * F::load(L.disk[0] + k) - one, b = F(2.f) * F::load(L.disk[1] + k) - one;
        const M centre = (a == zero) & (b == zero);
        const F r = F::load(radius + k);
        select(centre, zero, r * F::load(cosine + k)).store(L.disk[0] + k);
        select(centre, zero, r * F::load(sine + k)).store(L.disk[1] + k);
    }
    for (int k = 0; k < n; k += W) {
        const V p = load3<V>(L.p, k), p_error = load3<V>(L.p_error, k), ng = load3<V>(L.ng, k);
        const V dir = load3<V>(L.dir, k), beta = load3<V>(L.beta, k), diffuse = load3<V>(L.diffuse, k);
        const V wo_world = -dir;

        // bend_normal (scene/bsdf_diff.h).
        const V ns0 = load3<V>(L.ns, k);
        const F s = select(dot(wo_world, ng) < zero, F(-1.f), one), d = dot(wo_world, ns0);
        const M keep = s * d >= F(kMinShadingCosine);
        const V ns = select(keep, ns0, normalize(ns0 + wo_world * (s * F(kMinShadingCosine) - d)));
        store3(L.ns, k, ns);

        // Frame (math/frame.h) and wo.
        const F sign = sign_of(ns.z);
        const F a = F(-1.f) / (sign + ns.z);
        const F b = ns.x * ns.y * a;
        const V fs(one + sign * ns.x * ns.x * a, sign * b, -sign * ns.x);
        const V ft(b, sign + ns.y * ns.y * a, -ns.y);
        auto to_local = [&](const V& v) { return V(dot(v, fs), dot(v, ft), dot(v, ns)); };
        const V wo = to_local(wo_world);
        const M flip = M::load(L.two_sided + k) & (wo.z < zero);

        // bsdf_sample: the cosine-weighted hemisphere, mirrored for a two-sided material seen
        // from below.
        {
            const F wo_z = select(flip, -wo.z, wo.z);
            const F dx = F::load(L.disk[0] + k), dy = F::load(L.disk[1] + k);
            const F z = sqrt(max_std(zero, one - dx * dx - dy * dy));
            const F pdf = one * z * F(kInvPi);
            const M ok = M::load(L.reflects + k) & !(wo_z <= zero) & !(z <= zero) & (pdf > zero);
            const V wi(dx, dy, select(flip, -z, z));
            V f;
            F unused;
            lambert(flip, wo.z, wi.z, diffuse, f, unused);
            const V nb = select(ok, beta * (f / pdf), V(zero));
            const M goes_on = ok & !is_black(nb);
            goes_on.store(L.goes_on + k);
            store3(L.next_beta, k, nb);
            pdf.store(L.next_pdf + k);
            const V w = fs * wi.x + ft * wi.y + ns * wi.z;
            store3(L.next_dir, k, w);
            store3(L.next_origin, k, offset_ray_origin(p, p_error, ng, w));
        }

        // One light sample's value and MIS weight (next_event in shade_vertex): `on` cleared
        // where the BSDF is black towards it.
        auto next_event = [&](const V& ldir, F lpdf, const V& radiance, M& on) {
            const V wi = to_local(ldir);
            V f;
            F bpdf;
            lambert(flip, wo.z, wi.z, diffuse, f, bpdf);
            on = on & !is_black(f);
            const F w = mis ? mis_power_lanes(lpdf, bpdf) : one;
            return beta * f * radiance * (w / lpdf);
        };

        // The area light's sample (Scene::sample_light_triangle, by area, or the one given)
        // and its shadow ray (spawn_ray_to), where any path of the vector has one.
        if (M::load(L.light_on + k).bits() != 0) {
            const M light_on = M::load(L.light_on + k), given = M::load(L.light_given + k);
            M on = light_on;
            const F b1 = F::load(L.b1 + k), b2 = F::load(L.b2 + k), b0 = one - b1 - b2;
            const V v0 = load3<V>(L.v0, k), v1 = load3<V>(L.v1, k), v2 = load3<V>(L.v2, k);
            const V qng = select(given, load3<V>(L.given_ng, k), load3<V>(L.light_ng, k));
            const V q = select(given, load3<V>(L.given_p, k), v0 * b0 + v1 * b1 + v2 * b2);
            auto abs3 = [](const V& v) { return V(abs(v.x), abs(v.y), abs(v.z)); };
            const V q_error = select(given, load3<V>(L.given_p_error, k),
                                      (abs3(v0 * b0) + abs3(v1 * b1) + abs3(v2 * b2)) * F(rounding_gamma(7)) +
                                          V(F::load(L.edge + k) * F(rounding_gamma(4))));
            V to = q - p;
            const F dist2 = dot(to, to);
            on = on & (dist2 > zero);
            const F dist = sqrt(dist2);
            to = to / dist;
            const F cos_l = abs(dot(qng, to));
            on = on & (cos_l > zero);
            // Scene::emitted: the side of the face normal only, unless two-sided.
            const M front = !(dot(qng, -to) <= zero);
            on = on & (M::load(L.two_sided_emission + k) | front);
            V radiance = load3<V>(L.emission, k) * one;
            on = on & !is_black(radiance);
            F lpdf = F::load(L.pmf + k) / F::load(L.area + k) * dist2 / cos_l;
            on = on & (lpdf > zero) & is_finite(lpdf);
            // The given samples: their own (gathered only where sample_area_light succeeded).
            on = select(given, light_on, on);
            to = select(given, load3<V>(L.given_dir, k), to);
            lpdf = select(given, F::load(L.given_pdf + k), lpdf);
            radiance = select(given, load3<V>(L.given_radiance, k), radiance);
            const V value = next_event(to, lpdf, radiance, on);
            on.store(L.light_on + k);
            store3(L.light_value, k, value);
            const V origin = offset_ray_origin(p, p_error, ng, q - p);
            const V target = offset_ray_origin(q, q_error, qng, origin - q);
            const V span = target - origin;
            const F len = length(span);
            store3(L.light_origin, k, origin);
            store3(L.light_dir, k, select(len > zero, span / len, normalize(q - p)));
            (len * F(1.f - kShadowEpsilon)).store(L.light_tmax + k);
        }

        // The environment's sample and its shadow ray (spawn_ray), where any path of the vector has one.
        if (M::load(L.env_on + k).bits() != 0) {
            M on = M::load(L.env_on + k);
            const V ldir = load3<V>(L.env_dir, k);
            const V value = next_event(ldir, F::load(L.env_pdf + k), load3<V>(L.env_radiance, k), on);
            on.store(L.env_on + k);
            store3(L.env_value, k, value);
            store3(L.env_origin, k, offset_ray_origin(p, p_error, ng, ldir));
        }
    }
}

}  // namespace edgepath
