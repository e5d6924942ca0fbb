// The material model evaluated in world space, and its adjoint. Frame-free: an isotropic BSDF
// depends only on the shading normal n and the two directions, so gradients reach the normal
// without differentiating a tangent frame. Same model as scene/bsdf.h (which the sampler uses);
// the test suite checks the two agree.
//
// Each forward line appears as a comment above the lines of its adjoint.
#pragma once
#include <algorithm>
#include <cmath>
#include "math/vec.h"
#include "scene/desc.h"

namespace edgepath {

template <class T>
struct TBsdfParams {
    TVec3<T> diffuse, specular;
    T alpha = T(0.5);
    bool two_sided = false;
    MaterialKind kind = MaterialKind::Standard;  // smooth kinds: zero here (scene/specular.h)
    T eta = T(1.5);
};

template <class T>
struct DBsdf {
    TVec3<T> diffuse, specular, n, wo, wi;
    T alpha = 0;
};

namespace detail {
template <class T> constexpr T pi() { return T(3.14159265358979323846); }

// D(c) = a^2 / (pi d^2), d = c^2 (a^2 - 1) + 1, zero for c <= 0.
template <class T> T ggx_d(T c, T a) {
    if (c <= 0) return 0;
    T d = c * c * (a * a - 1) + 1;
    return a * a / (pi<T>() * d * d);
}
template <class T> void d_ggx_d(T c, T a, T dD, T& dc, T& da) {
    if (c <= 0) return;
    T d = c * c * (a * a - 1) + 1;
    T D = a * a / (pi<T>() * d * d);
    // dD/dd = -2 D / d
    T dd = -2 * D / d * dD;
    dc += dd * 2 * c * (a * a - 1);
    da += dD * 2 * a / (pi<T>() * d * d) + dd * 2 * a * c * c;
}
// G1(c) = 2 / (1 + sqrt(1 + a^2 (1 - c^2) / c^2)) for a direction with cosine c to the normal and
// cosine ch > 0 to the microfacet normal (zero otherwise).
template <class T> T smith_g1(T c, T ch, T a) {
    if (ch * c <= 0) return 0;
    if (c * c >= 1) return 1;
    T t2 = (1 - c * c) / (c * c);
    return 2 / (1 + std::sqrt(1 + a * a * t2));
}
template <class T> void d_smith_g1(T c, T ch, T a, T dG, T& dc, T& da) {
    if (ch * c <= 0 || c * c >= 1) return;
    T t2 = (1 - c * c) / (c * c);
    T q = std::sqrt(1 + a * a * t2);
    // G = 2 / (1 + q)
    T dq = -2 / ((1 + q) * (1 + q)) * dG;
    // q = sqrt(1 + a^2 t2)
    da += dq * a * t2 / q;
    T dt2 = dq * a * a / (2 * q);
    // t2 = 1 / c^2 - 1
    dc += dt2 * (-2 / (c * c * c));
}

// The specular lobe's value F * S at (wo, wi) and its intermediates (the adjoint reuses them).
// False where the half vector vanishes (the lobe is then zero).
template <class T>
struct GgxTerms {
    TVec3<T> h, F;
    T hl, ch, oh, D, Go, Gi, m, m5, S;
};
template <class T>
bool ggx_terms(const TBsdfParams<T>& p, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi, T co, T ci,
               GgxTerms<T>& g) {
    TVec3<T> H = wo + wi;
    g.hl = length(H);
    if (!(g.hl > 0)) return false;
    g.h = H / g.hl;
    g.ch = dot(n, g.h);
    g.oh = dot(wo, g.h);
    g.D = ggx_d(g.ch, p.alpha);
    g.Go = smith_g1(co, g.oh, p.alpha);
    g.Gi = smith_g1(ci, g.oh, p.alpha);
    g.m = std::clamp(1 - g.oh, T(0), T(1));
    g.m5 = g.m * g.m * g.m * g.m * g.m;
    g.F = p.specular + (TVec3<T>(T(1)) - p.specular) * g.m5;
    g.S = g.D * g.Go * g.Gi / (4 * co);
    return true;
}
}  // namespace detail

// The shading normal the BSDF uses, bent towards the viewer where the interpolated normal
// disagrees with the geometric side: with s = sign(wo . ng), any ns with s (wo . ns) < c is
// replaced by normalize(ns + (s c - wo . ns) wo), so that the viewer is never behind the shading
// normal while in front of the face (or the reverse). Without it, one-sided BSDFs would go
// black along curves inside triangles near silhouettes; those curves move with the geometry but
// lie on no edge, so edge sampling cannot account for them. Continuous in ns and wo.
constexpr float kMinShadingCosine = 0.01f;

template <class T>
TVec3<T> bend_normal(const TVec3<T>& ns, const TVec3<T>& ng, const TVec3<T>& wo) {
    const T s = dot(wo, ng) < 0 ? T(-1) : T(1), d = dot(wo, ns);
    if (s * d >= T(kMinShadingCosine)) return ns;
    return normalize(ns + wo * (s * T(kMinShadingCosine) - d));
}

// Adds the adjoint of bend_normal for the output adjoint `dout` to (dns, dwo); ng is a constant.
template <class T>
void d_bend_normal(const TVec3<T>& ns, const TVec3<T>& ng, const TVec3<T>& wo, const TVec3<T>& dout, TVec3<T>& dns,
                   TVec3<T>& dwo) {
    const T s = dot(wo, ng) < 0 ? T(-1) : T(1), d = dot(wo, ns);
    if (s * d >= T(kMinShadingCosine)) {
        dns += dout;
        return;
    }
    // N = ns + k wo, k = s c - wo . ns
    const T k = s * T(kMinShadingCosine) - d;
    const TVec3<T> dN = d_normalize(ns + wo * k, dout);
    const T dk = dot(dN, wo);
    dns += dN - wo * dk;
    dwo += dN * k - ns * dk;
}

// f(wo, wi) * cos(theta_i), world space; n unit shading normal, wo/wi unit.
template <class T>
TVec3<T> bsdf_eval_world(const TBsdfParams<T>& p, TVec3<T> n, const TVec3<T>& wo, const TVec3<T>& wi) {
    if (p.kind != MaterialKind::Standard) return TVec3<T>(T(0));
    T co = dot(n, wo);
    if (p.two_sided && co < 0) {
        n = -n;
        co = -co;
    }
    T ci = dot(n, wi);
    if (co <= 0 || ci <= 0) return TVec3<T>(T(0));
    TVec3<T> result = p.diffuse * (ci / detail::pi<T>());
    detail::GgxTerms<T> g;
    if (!is_black(p.specular) && detail::ggx_terms(p, n, wo, wi, co, ci, g)) result += g.F * g.S;
    return result;
}

// Adds to `d` the adjoint of bsdf_eval_world for the output adjoint `dr`.
template <class T>
void d_bsdf_eval_world(const TBsdfParams<T>& p, TVec3<T> n, const TVec3<T>& wo, const TVec3<T>& wi,
                       const TVec3<T>& dr, DBsdf<T>& d) {
    if (p.kind != MaterialKind::Standard) return;
    T co = dot(n, wo);
    bool flipped = p.two_sided && co < 0;
    if (flipped) {
        n = -n;
        co = -co;
    }
    T ci = dot(n, wi);
    if (co <= 0 || ci <= 0) return;
    TVec3<T> dn(T(0));
    T dco = 0, dci = 0;
    // result = diffuse * ci / pi
    d.diffuse += dr * (ci / detail::pi<T>());
    dci += dot(dr, p.diffuse) / detail::pi<T>();
    detail::GgxTerms<T> g;
    if (!is_black(p.specular) && detail::ggx_terms(p, n, wo, wi, co, ci, g)) {
        // result += F * S
        TVec3<T> dF = dr * g.S;
        T dS = dot(dr, g.F);
        // F = ks + (1 - ks) m^5, m = clamp(1 - oh)
        d.specular += dF * (1 - g.m5);
        T m4 = g.m * g.m * g.m * g.m;
        T dm = (1 - g.oh > 0 && 1 - g.oh < 1) ? dot(dF, TVec3<T>(T(1)) - p.specular) * 5 * m4 : T(0);
        T doh = -dm;
        // S = D Go Gi / (4 co)
        T dD = dS * g.Go * g.Gi / (4 * co);
        T dGo = dS * g.D * g.Gi / (4 * co);
        T dGi = dS * g.D * g.Go / (4 * co);
        dco += -dS * g.S / co;
        T dch = 0;
        detail::d_ggx_d(g.ch, p.alpha, dD, dch, d.alpha);
        detail::d_smith_g1(co, g.oh, p.alpha, dGo, dco, d.alpha);
        detail::d_smith_g1(ci, g.oh, p.alpha, dGi, dci, d.alpha);
        // ch = n.h, oh = wo.h
        TVec3<T> dh = n * dch + wo * doh;
        dn += g.h * dch;
        d.wo += g.h * doh;
        // h = H / |H|, H = wo + wi
        TVec3<T> dH = (dh - g.h * dot(g.h, dh)) / g.hl;
        d.wo += dH;
        d.wi += dH;
    }
    // co = n.wo, ci = n.wi
    dn += wo * dco + wi * dci;
    d.wo += n * dco;
    d.wi += n * dci;
    d.n += flipped ? -dn : dn;
}

}  // namespace edgepath
