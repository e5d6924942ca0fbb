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

// bend_normal (scene/bsdf_diff.h) of the shading normal ns0 at a point of geometric normal ng,
// seen along wo_world = -dir.
template <class V>
inline V bend_normal_lanes(const V& ns0, const V& ng, const V& wo_world) {
    using F = decltype(V::x);
    const F s = select(dot(wo_world, ng) < F(0.f), F(-1.f), F(1.f)), d = dot(wo_world, ns0);
    const auto keep = s * d >= F(kMinShadingCosine);
    return select(keep, ns0, normalize(ns0 + wo_world * (s * F(kMinShadingCosine) - d)));
}

// delta_side (scene/specular.h) of a smooth lobe's reflection w, where `mask`: mirrored across
// the face (geometric normal ng) where it points to the other side of it than wo_world.
template <class V, class M>
inline V reflection_side_lanes(const V& w, const V& ng, const V& wo_world, M mask) {
    using F = decltype(V::x);
    const F zero(0.f), t = dot(w, ng), o = dot(wo_world, ng);
    const M wrong = mask & (((o >= zero) & (t < zero)) | ((o < zero) & (t > zero)));
    return select(wrong, w - ng * (F(2.f) * t), w);
}

// The tangents fs, ft of the frame about ns (math/frame.h).
template <class V>
inline void frame_lanes(const V& ns, V& fs, V& ft) {
    using F = decltype(V::x);
    const F sign = sign_of(ns.z);
    const F a = F(-1.f) / (sign + ns.z);
    const F b = ns.x * ns.y * a;
    fs = V(F(1.f) + sign * ns.x * ns.x * a, sign * b, -sign * ns.x);
    ft = V(b, sign + ns.y * ns.y * a, -ns.y);
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

// The GGX lobe's terms (scene/bsdf.h) for the oriented pair (wo, wi), a the lanes' alpha: the
// half vector h, D(h) (ggx_D) and G1 (ggx_G1) of wo and of wi, each with the scalar code's
// early returns as selects (a NaN compares false there as here).
template <class F, class V>
struct GgxTerms {
    V h;
    F D, G1o, G1i;
};
template <class F>
inline F ggx_D_lanes(F hz, F a) {
    const F a2 = a * a;
    const F c2 = hz * hz;
    const F d = c2 * (a2 - F(1.f)) + F(1.f);
    return select(hz <= F(0.f), F(0.f), a2 / (F(kPi) * d * d));
}
template <class F, class V>
inline F ggx_G1_lanes(const V& w, const V& h, F a) {
    const F c2 = w.z * w.z;
    const F tan2 = (F(1.f) - c2) / c2;
    const F g = F(2.f) / (F(1.f) + sqrt(F(1.f) + a * a * tan2));
    return select(dot(w, h) * w.z <= F(0.f), F(0.f), select(c2 >= F(1.f), F(1.f), g));
}
template <class F, class V>
inline GgxTerms<F, V> ggx_terms(const V& wo, const V& wi, F a) {
    GgxTerms<F, V> t;
    t.h = normalize(wo + wi);
    t.D = ggx_D_lanes(t.h.z, a);
    t.G1o = ggx_G1_lanes(wo, t.h, a);
    t.G1i = ggx_G1_lanes(wi, t.h, a);
    return t;
}
// ggx_pdf from the terms.
template <class F, class V>
inline F ggx_pdf_lanes(const V& wo, const GgxTerms<F, V>& t) {
    return select(dot(wo, t.h) <= F(0.f), F(0.f), t.G1o * t.D / (F(4.f) * wo.z));
}

// The material's f cos (bsdf_eval) and density (bsdf_pdf, and bsdf_sample's) for the pair
// (wo, wi) already oriented (on the front of a two-sided material) and not yet tested to be
// above the surface. `glossy`: whether any lane of the vector has a GGX lobe (has_spec, a
// specular that is not black: specular and alpha are read there only); without one, its
// terms are not computed (each lane would discard them).
template <class F, class M, class V>
inline void bsdf_oriented(const V& o, const V& i, const V& diffuse, M has_spec, const V& specular, F alpha, F lobe_p,
                          bool glossy, V& value, F& density) {
    value = diffuse * (i.z * F(kInvPi));
    density = (F(1.f) - lobe_p) * i.z * F(kInvPi);
    if (glossy) {
        const GgxTerms<F, V> t = ggx_terms(o, i, alpha);
        // fresnel_schlick(specular, wi . h): std::clamp(1 - cos, 0, 1) as min(max(., 0), 1).
        const F m0 = F(1.f) - dot(i, t.h);
        const F m1 = max_std(m0, F(0.f));
        const F m = min_std(m1, F(1.f));
        const F m5 = (m * m) * (m * m) * m;
        const V fresnel = specular + (V(F(1.f)) - specular) * m5;
        const F G = t.G1o * t.G1i;
        const V with = value + fresnel * (t.D * G / (F(4.f) * o.z));
        value = select(has_spec, with, value);
        density = select(lobe_p > F(0.f), density + lobe_p * ggx_pdf_lanes(o, t), density);
    }
}

// bsdf_eval and bsdf_pdf for wi, with the two-sided material's mirroring (orient); `flip`:
// two-sided and wo below the surface.
template <class F, class M, class V>
inline void bsdf_lanes(M flip, const V& wo, const V& wi, const V& diffuse, M has_spec, const V& specular, F alpha,
                       F lobe_p, bool glossy, V& f, F& pdf) {
    const V o(wo.x, wo.y, select(flip, -wo.z, wo.z)), i(wi.x, wi.y, select(flip, -wi.z, wi.z));
    const M up = (o.z > F(0.f)) & (i.z > F(0.f));
    V value;
    F density;
    bsdf_oriented(o, i, diffuse, has_spec, specular, alpha, lobe_p, glossy, value, density);
    f = select(up, value, V(F(0.f)));
    pdf = select(up, density, F(0.f));
}

// ggx_sample_visible_normal(wo, a, u1, u2) with the cosine and sine of 2 pi u2 given.
template <class F, class V>
inline V ggx_visible_normal_lanes(const V& wo, F a, F u1, F cos_phi, F sin_phi) {
    const V vh = normalize(V(a * wo.x, a * wo.y, wo.z));
    const F lensq = vh.x * vh.x + vh.y * vh.y;
    const F inv = F(1.f) / sqrt(lensq);
    const auto has = lensq > F(0.f);
    const V t1(select(has, -vh.y * inv, F(1.f)), select(has, vh.x * inv, F(0.f)), select(has, F(0.f) * inv, F(0.f)));
    const V t2(vh.y * t1.z - vh.z * t1.y, vh.z * t1.x - vh.x * t1.z, vh.x * t1.y - vh.y * t1.x);
    const F r = sqrt(u1);
    const F p1 = r * cos_phi;
    F p2 = r * sin_phi;
    const F s = F(0.5f) * (F(1.f) + vh.z);
    p2 = (F(1.f) - s) * sqrt(max_std(F(0.f), F(1.f) - p1 * p1)) + s * p2;
    const V nh = t1 * p1 + t2 * p2 + vh * sqrt(max_std(F(0.f), F(1.f) - p1 * p1 - p2 * p2));
    return normalize(V(a * nh.x, a * nh.y, max_std(F(1e-7f), nh.z)));
}

// The plastic (scene/bsdf_diff.h's plastic_terms, scene/bsdf.h's bsdf_pdf): fresnel_dielectric
// of the cosine c > 0 and the index e (1 under total internal reflection), and smith_g1 of a
// direction at cosine c to the normal and ch to the microfacet normal.
template <class F>
inline F fresnel_lanes(F c, F e) {
    const F one(1.f);
    const F q = (one - c * c) / (e * e);
    const F ct = sqrt(one - q), a = e * ct, b = e * c;
    const F rs = (c - a) / (c + a), rp = (b - ct) / (b + ct);
    return select(q >= one, one, (rs * rs + rp * rp) / F(2.f));
}
template <class F>
inline F smith_g1_lanes(F c, F ch, F a) {
    const F one(1.f), c2 = c * c;
    const F t2 = (one - c2) / c2;
    const F g = F(2.f) / (one + sqrt(one + a * a * t2));
    return select(ch * c <= F(0.f), F(0.f), select(c2 >= one, one, g));
}
// A vector of plastic lanes' parameters, with T(co) (to) and the coating's probability ps for
// their wo (both of its cosine co, the same for every wi).
template <class F, class M, class V>
struct PlasticLanes {
    V diffuse, specular;
    F alpha, eta, R, to, ps;
    M rough, lobe, nonlinear;
    bool any_rough, any_lobe, smooth;  // smooth: every lane's table smooth
};
// plastic_terms (f cos) for the oriented pair (o, i), co = o.z and ci = i.z, ti = T(ci), and
// bsdf_pdf's density for it (both before the test that the pair is above the surface).
template <class F, class M, class V>
inline void plastic_oriented(const PlasticLanes<F, M, V>& P, const V& o, const V& i, F ti, V& value, F& density) {
    const F zero(0.f), one(1.f);
    const F co = o.z, ci = i.z;
    // The base: kd / den T(co) T(ci) ci / (pi eta^2), den = 1 - R or (nonlinear) 1 - kd R.
    const F k = P.to * ti * ci / (F(kPi) * P.eta * P.eta);
    const V den = select(P.nonlinear, V(one) - P.diffuse * P.R, V(one - P.R));
    const V diff(P.diffuse.x / den.x, P.diffuse.y / den.y, P.diffuse.z / den.z);
    value = diff * k;
    density = (one - P.ps) * ci * F(kInvPi);
    if (!P.any_lobe && !P.any_rough) return;
    const V H = o + i;
    const F hl = length(H);
    const V h = H / hl;
    const M has_h = hl > zero;
    if (P.any_lobe) {
        // ggx_geometry with n = (0, 0, 1), and the coating's Fresnel factor: ks F(oh) S.
        const F ch = zero * h.x + zero * h.y + one * h.z;
        const F oh = dot(o, h);
        const F D = ggx_D_lanes(ch, P.alpha);
        const F Go = smith_g1_lanes(co, oh, P.alpha), Gi = smith_g1_lanes(ci, oh, P.alpha);
        const F S = D * Go * Gi / (F(4.f) * co);
        const F Fr = select(oh > zero, fresnel_lanes(oh, P.eta), zero);
        value = select(P.lobe & has_h, value + P.specular * (Fr * S), value);
    }
    if (P.any_rough) {
        // ggx_pdf: its half vector normalize(o + i), o + i itself where that has no length.
        const V hn = select(has_h, h, H);
        const F g = select(dot(o, hn) <= zero, zero, ggx_G1_lanes(o, hn, P.alpha) * ggx_D_lanes(hn.z, P.alpha) / (F(4.f) * o.z));
        density = select(P.rough & (P.ps > zero), density + P.ps * g, density);
    }
}

// mis_power_lanes's lanes `redo` (a bit each) again, one at a time (rare: out of line).
template <class F>
[[gnu::noinline]] F mis_power_redo(F a, F b, F w, int redo) {
    alignas(32) float av[F::width], bv[F::width], wv[F::width];
    a.store(av);
    b.store(bv);
    w.store(wv);
    for (int i = 0; i < F::width; ++i)
        if ((redo >> i) & 1) wv[i] = mis_power_ratio(av[i], bv[i]);
    return F::load(wv);
}

// mis_power (sampling/warp.h), lane by lane, bit for bit.
template <class F>
inline F mis_power_lanes(F a, F b) {
    const F zero(0.f), a2 = a * a, sum = a2 + b * b;
    const auto positive = a > zero;
    const F w = select(positive, a2 / sum, zero);
    const int redo = and_not(positive, (sum > zero) & (sum < F(std::numeric_limits<float>::infinity()))).bits();
    return redo == 0 ? w : mis_power_redo(a, b, w, redo);
}

}  // namespace lanes

// Lanes [0, n) of L (n rounded up to whole vectors; the lanes past n are computed and ignored),
// F::width at a time: F a vector of floats, M its mask, V three of them (math/simd4.h's F, M,
// V or math/simd8.h's F8, M8, V8). Glossy: whether any lane may have a GGX lobe (if not, the
// Lambertian lobe alone, L.has_specular not read).
//
// Plastic: every lane is a plastic vertex (L.rough, L.coat ... read; Glossy not used): T(co) and
// the coating's probability per path first (a table lookup each, render/shade_lanes.cpp), then
// the sample of the lobe chosen (the GGX visible normal where rough, the mirror where smooth,
// or the cosine-weighted base), the value and density of plastic_terms and bsdf_pdf, T(ci) per
// path.
template <class F, class M, class V, bool Glossy, bool Plastic, int N>
inline void shade_lanes_kernel(ShadeLanes<N>& L, int n, bool mis) {
    using namespace lanes;
    constexpr int W = F::width;
    static_assert(N % W == 0, "whole vectors");
    const F zero(0.f), one(1.f);
    // bend_normal (scene/bsdf_diff.h) of lane k's shading normal, wo_world = -dir.
    auto bent_normal = [&](int k, const V& wo_world) {
        return bend_normal_lanes(load3<V>(L.ns, k), load3<V>(L.ng, k), wo_world);
    };
    // Whether every lane of the vector at lane k has a smooth coating: its T(c) is then
    // 1 - fresnel_dielectric(c, eta) in vectors, otherwise each lane's table's, path by path.
    constexpr int all_lanes = (1 << W) - 1;
    auto all_smooth = [&](int k) { return M::load(L.coat_smooth + k).bits() == all_lanes; };
    auto coat_t = [&](int k, bool smooth, F c) {
        if (smooth) return one - fresnel_lanes(c, F::load(L.eta + k));
        alignas(64) float a[W];
        c.store(a);
        plastic_coat_transmittances(L, k, W, a);
        return F::load(a);
    };
    // The plastic's wo (its cosine co, mirrored for a two-sided one seen from below), T(co)
    // and the coating's probability (plastic_coat_probability's operations).
    alignas(64) float co[N], t_o[N], coat_p[N];
    if constexpr (Plastic) {
        for (int k = 0; k < n; k += W) {
            const V wo_world = -load3<V>(L.dir, k);
            const F z = dot(wo_world, bent_normal(k, wo_world));
            const M flip = M::load(L.two_sided + k) & (z < zero);
            const F c = select(flip, -z, z);
            c.store(co + k);
            if (all_smooth(k)) {
                const F t = coat_t(k, true, c), ks = F::load(L.ks + k), kd = F::load(L.kd + k);
                const F s = (one - t) * ks, d = t * kd;
                t.store(t_o + k);
                select(ks + kd > zero, select(s + d > zero, s / (s + d), zero), zero).store(coat_p + k);
            } else {
                const int count = std::min(W, n - k);
                plastic_coat_probabilities(L, k, count, co, t_o, coat_p);
                for (int j = k + count; j < k + W; ++j) t_o[j] = coat_p[j] = 0.f;
            }
        }
    }
    // The BSDF sample's angle: square_to_disk's (sampling/warp.h) for the cosine-weighted lobe
    // or 2 pi u2 for the GGX visible normal, whichever lobe the path's number chose (u_lobe <
    // lobe_p: the GGX lobe); its cosine and sine; the disk's radius and point.
    alignas(64) float radius[N], angle[N], cosine[N], sine[N], disk_x[N], disk_y[N];
    for (int k = 0; k < n; k += W) {
        const F u2 = F::load(L.disk[1] + k);
        const F a = F(2.f) * F::load(L.disk[0] + k) - one, b = F(2.f) * u2 - one;
        const M wide = abs(a) > abs(b);
        select(wide, a, b).store(radius + k);
        const F disk_angle = select(wide, F(kPi / 4.f) * (b / a), F(kPi / 2.f) - F(kPi / 4.f) * (a / b));
        if constexpr (Plastic) {
            const M ggx = M::load(L.rough + k) & (F::load(L.u_lobe + k) < F::load(coat_p + k));
            select(ggx, F(2.f * kPi) * u2, disk_angle).store(angle + k);
        } else if constexpr (Glossy) {
            const M ggx = M::load(L.has_specular + k) & (F::load(L.u_lobe + k) < F::load(L.lobe_p + k));
            select(ggx, F(2.f * kPi) * u2, disk_angle).store(angle + k);
        } else {
            disk_angle.store(angle + k);
        }
    }
    for (int k = 0; k < n; ++k) {
        cosine[k] = std::cos(angle[k]);
        sine[k] = std::sin(angle[k]);
    }
    for (int k = 0; k < n; k += W) {
        const F a = F(2.f) * F::load(L.disk[0] + k) - one, b = F(2.f) * F::load(L.disk[1] + k) - one;
        const M centre = (a == zero) & (b == zero);
        const F r = F::load(radius + k);
        select(centre, zero, r * F::load(cosine + k)).store(disk_x + k);
        select(centre, zero, r * F::load(sine + k)).store(disk_y + k);
    }
    for (int k = 0; k < n; k += W) {
        const V p = load3<V>(L.p, k), p_error = load3<V>(L.p_error, k), ng = load3<V>(L.ng, k);
        const V dir = load3<V>(L.dir, k), beta = load3<V>(L.beta, k), diffuse = load3<V>(L.diffuse, k);
        const V wo_world = -dir;

        const V ns = bent_normal(k, wo_world);
        store3(L.ns, k, ns);

        // Frame (math/frame.h) and wo.
        V fs, ft;
        frame_lanes(ns, fs, ft);
        auto to_local = [&](const V& v) { return V(dot(v, fs), dot(v, ft), dot(v, ns)); };
        const V wo = to_local(wo_world);
        const M flip = M::load(L.two_sided + k) & (wo.z < zero);

        // The GGX lobe, where any lane of the vector has it (its specular and alpha read there
        // only: elsewhere the lanes' own select them away).
        M has_spec = zero < zero;  // none
        V specular(zero);
        F alpha = zero, lobe_p = zero;
        bool glossy = false;
        PlasticLanes<F, M, V> P;
        if constexpr (Plastic) {
            P.diffuse = diffuse;
            P.specular = load3<V>(L.specular, k);
            P.alpha = F::load(L.alpha + k);
            P.eta = F::load(L.eta + k);
            P.R = F::load(L.coat_r + k);
            P.to = F::load(t_o + k);
            P.ps = F::load(coat_p + k);
            P.rough = M::load(L.rough + k);
            P.lobe = M::load(L.coat_lobe + k);
            P.nonlinear = M::load(L.nonlinear + k);
            P.any_rough = P.rough.bits() != 0;
            P.any_lobe = P.lobe.bits() != 0;
            P.smooth = all_smooth(k);
        } else if constexpr (Glossy) {
            has_spec = M::load(L.has_specular + k);
            lobe_p = select(has_spec, F::load(L.lobe_p + k), zero);
            glossy = has_spec.bits() != 0;
            if (glossy) {
                specular = load3<V>(L.specular, k);
                alpha = F::load(L.alpha + k);
            }
        }

        // bsdf_sample: wo mirrored for a two-sided material seen from below; the GGX lobe's
        // visible normal reflected, or the cosine-weighted hemisphere; the direction's density
        // (both lobes' mixture) and bsdf_eval's value, whose terms are the same (bsdf_eval
        // mirrors the pair back to where the sample made it); the direction mirrored back.
        {
            const V wo_up(wo.x, wo.y, select(flip, -wo.z, wo.z));
            const F dx = F::load(disk_x + k), dy = F::load(disk_y + k);
            V wi(dx, dy, sqrt(max_std(zero, one - dx * dx - dy * dy)));
            V value;
            F pdf;
            M ok = M::load(L.reflects + k) & !(wo_up.z <= zero);
            V nb;
            if constexpr (Plastic) {
                // The coating's lobe where u_lobe < ps: GGX where rough, the mirror where smooth.
                const M chose = F::load(L.u_lobe + k) < P.ps;
                const M ggx = P.rough & chose, mirror = and_not(chose, P.rough);
                if (ggx.bits() != 0) {
                    const V h = ggx_visible_normal_lanes(wo_up, P.alpha, F::load(L.disk[0] + k), F::load(cosine + k),
                                                         F::load(sine + k));
                    wi = select(ggx, h * (F(2.f) * dot(wo_up, h)) - wo_up, wi);
                }
                plastic_oriented(P, wo_up, wi, coat_t(k, P.smooth, wi.z), value, pdf);
                const V f = select((wo_up.z > zero) & (wi.z > zero), value, V(zero));
                ok = select(mirror, ok, ok & !(wi.z <= zero) & (pdf > zero));
                nb = beta * (f / pdf);
                if (mirror.bits() != 0) {
                    // delta_scatter of the coating (n = (0, 0, 1), wo on its front): the mirror
                    // direction, weight ks F(co) / ps, its probability ps.
                    const F c = zero * wo_up.x + zero * wo_up.y + one * wo_up.z;
                    const F m = F(2.f) * c;
                    const V dir(zero * m - wo_up.x, zero * m - wo_up.y, one * m - wo_up.z);
                    const V weight = P.specular * (fresnel_lanes(c, P.eta) * (one / P.ps));
                    wi = select(mirror, dir, wi);
                    nb = select(mirror, beta * weight, nb);
                    pdf = select(mirror, P.ps, pdf);
                }
                (mirror & ok).store(L.next_delta + k);
            } else {
                if (glossy) {
                    const M ggx = has_spec & (F::load(L.u_lobe + k) < lobe_p);
                    const V h = ggx_visible_normal_lanes(wo_up, alpha, F::load(L.disk[0] + k), F::load(cosine + k),
                                                         F::load(sine + k));
                    wi = select(ggx, h * (F(2.f) * dot(wo_up, h)) - wo_up, wi);
                }
                bsdf_oriented(wo_up, wi, diffuse, has_spec, specular, alpha, lobe_p, glossy, value, pdf);
                ok = ok & !(wi.z <= zero) & (pdf > zero);
                const V f = select((wo_up.z > zero) & (wi.z > zero), value, V(zero));
                nb = beta * (f / pdf);
            }
            wi.z = select(flip, -wi.z, wi.z);
            nb = select(ok, nb, V(zero));
            const M goes_on = ok & !is_black(nb);
            goes_on.store(L.goes_on + k);
            store3(L.next_beta, k, nb);
            pdf.store(L.next_pdf + k);
            V w = fs * wi.x + ft * wi.y + ns * wi.z;
            if constexpr (Plastic) w = reflection_side_lanes(w, ng, wo_world, M::load(L.next_delta + k));
            store3(L.next_dir, k, w);
            store3(L.next_origin, k, offset_ray_origin(p, p_error, ng, w));
        }

        // One light sample's value and MIS weight (next_event in shade_vertex): `on` cleared
        // where the BSDF is black towards it.
        auto next_event = [&](const V& ldir, F lpdf, const V& radiance, M& on, float* scale_out) {
            const V wi = to_local(ldir);
            V f;
            F bpdf;
            if constexpr (Plastic) {
                const V o(wo.x, wo.y, select(flip, -wo.z, wo.z)), i(wi.x, wi.y, select(flip, -wi.z, wi.z));
                const M up = (o.z > zero) & (i.z > zero);
                V value;
                F density;
                plastic_oriented(P, o, i, coat_t(k, P.smooth, i.z), value, density);
                f = select(up, value, V(zero));
                bpdf = select(up, density, zero);
            } else {
                bsdf_lanes(flip, wo, wi, diffuse, has_spec, specular, alpha, lobe_p, glossy, f, bpdf);
            }
            on = on & !is_black(f);
            const F w = mis ? mis_power_lanes(lpdf, bpdf) : one;
            const F scale = w / lpdf;
            scale.store(scale_out + k);
            return beta * f * radiance * scale;
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
            const V value = next_event(to, lpdf, radiance, on, L.light_scale);
            store3(L.light_to, k, to);
            dist.store(L.light_dist + k);
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
            const V value = next_event(ldir, F::load(L.env_pdf + k), load3<V>(L.env_radiance, k), on, L.env_scale);
            on.store(L.env_on + k);
            store3(L.env_value, k, value);
            store3(L.env_origin, k, offset_ray_origin(p, p_error, ng, ldir));
        }
    }
}

// The smooth conductor's lanes (shade_mirror_lanes, MaterialKind::Conductor): bsdf_sample's
// delta branch for the mirror (delta_scatter: the mirror direction about the bent shading
// normal, on the back too where two-sided, weight Schlick's reflectance of `specular`), its ray
// and throughput; no light sample (a delta material samples none). Lanes [0, n) of L, L.specular
// and L.two_sided read; next_pdf is the lobe's probability, 1.
template <class F, class M, class V, int N>
inline void shade_mirror_lanes_kernel(ShadeLanes<N>& L, int n) {
    using namespace lanes;
    constexpr int W = F::width;
    static_assert(N % W == 0, "whole vectors");
    const F zero(0.f), one(1.f);
    for (int k = 0; k < n; k += W) {
        const V p = load3<V>(L.p, k), p_error = load3<V>(L.p_error, k), ng = load3<V>(L.ng, k);
        const V beta = load3<V>(L.beta, k), specular = load3<V>(L.specular, k);
        const V wo_world = -load3<V>(L.dir, k);
        const V ns = bend_normal_lanes(load3<V>(L.ns, k), ng, wo_world);
        store3(L.ns, k, ns);
        // Frame (math/frame.h) and wo.
        V fs, ft;
        frame_lanes(ns, fs, ft);
        const V wo(dot(wo_world, fs), dot(wo_world, ft), dot(wo_world, ns));
        // delta_scatter's mirror with n = (0, 0, 1): c = n . wo, turned to wo's side where
        // two-sided; the direction n (2 s c) - wo; Schlick's weight, std::clamp as
        // min(max(1 - c, 0), 1).
        const F c0 = zero * wo.x + zero * wo.y + one * wo.z;
        const F s = select(M::load(L.two_sided + k) & (c0 < zero), F(-1.f), one);
        const F c = c0 * s;
        const M ok = c > zero;
        const F m2 = F(2.f) * s * c;
        const V wi(zero * m2 - wo.x, zero * m2 - wo.y, one * m2 - wo.z);
        const F m = min_std(max_std(one - c, zero), one);
        const F m5 = m * m * m * m * m;
        const V nb = select(ok, beta * (specular + (V(one) - specular) * m5), V(zero));
        const M goes_on = ok & !is_black(nb);
        goes_on.store(L.goes_on + k);
        goes_on.store(L.next_delta + k);
        store3(L.next_beta, k, nb);
        one.store(L.next_pdf + k);
        const V w = reflection_side_lanes(fs * wi.x + ft * wi.y + ns * wi.z, ng, wo_world, ok);
        store3(L.next_dir, k, w);
        store3(L.next_origin, k, offset_ray_origin(p, p_error, ng, w));
    }
}

}  // namespace edgepath
