// The material model evaluated in world space, and its adjoint. Frame-free: an isotropic BSDF
// depends only on the shading normal n and the two directions, so gradients reach the normal
// without differentiating a tangent frame. Same model as scene/bsdf.h (which the sampler uses);
// the test suite checks the two agree.
//
// Each forward line appears as a comment above the lines of its adjoint.
#pragma once
#include <algorithm>
#include <cmath>
#include "math/adjoint.h"
#include "math/vec.h"
#include "scene/desc.h"
#include "scene/plastic.h"

namespace edgepath {

template <class T>
struct TBsdfParams {
    TVec3<T> diffuse, specular;
    T alpha = T(0.5);
    bool two_sided = false;
    MaterialKind kind = MaterialKind::Standard;  // smooth kinds: zero here (scene/specular.h)
    T eta = T(1.5);
    bool rough = false;  // Dielectric, Plastic: the rough (GGX) one; otherwise smooth
    const CoatTable* coat = nullptr;  // Plastic: its coating (scene/plastic.h)
    bool nonlinear = false;           // Plastic
};

// Whether the material scatters into isolated directions (scene/specular.h): the conductor,
// and the dielectric unless rough.
inline bool is_delta_kind(MaterialKind kind, bool rough) {
    return kind == MaterialKind::Conductor || (kind == MaterialKind::Dielectric && !rough);
}

// The adjoints of a BSDF's value: diffuse and specular are RGB adjoints (type T); the others
// scalar ones (A: float, or Adj3 for one lane per output colour, math/adjoint.h).
template <class T, class A = T>
struct DBsdf {
    TVec3<T> diffuse, specular;
    TVec3<A> n, wo, wi;
    A alpha = A(0);
    A eta = A(0);  // rough dielectric and plastic only
};

namespace detail {
template <class T> constexpr T pi() { return T(3.14159265358979323846); }

// D(c) = a^2 / (pi d^2), d = c^2 (a^2 - 1) + 1, zero for c <= 0.
template <class T> T ggx_d(T c, T a) {
    if (c <= 0) return 0;
    T d = c * c * (a * a - 1) + 1;
    return a * a / (pi<T>() * d * d);
}
template <class T, class A> void d_ggx_d(T c, T a, A dD, A& dc, A& da) {
    if (c <= 0) return;
    T d = c * c * (a * a - 1) + 1;
    T D = a * a / (pi<T>() * d * d);
    // dD/dd = -2 D / d
    A dd = -2 * D / d * dD;
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
template <class T, class A> void d_smith_g1(T c, T ch, T a, A dG, A& dc, A& da) {
    if (ch * c <= 0 || c * c >= 1) return;
    // With s = sqrt(c^2 + a^2 (1 - c^2)), G = 2 |c| / (|c| + s), so
    //   dG/d|c| = 2 a^2 / (s (|c| + s)^2),  dG/da = -2 a |c| (1 - c^2) / (s (|c| + s)^2),
    // bounded for every c (s >= min(1, a) > 0). (Differentiated through tan^2 = 1 / c^2 - 1,
    // they overflowed for a direction within about 1e-13 of the surface's plane, a light on a
    // floor's plane: zero times infinity, a NaN in every gradient.)
    T ac = std::abs(c);
    T s = std::sqrt(c * c + a * a * (1 - c * c));
    T k = 2 / (s * (ac + s) * (ac + s));
    dc += dG * (c > 0 ? k * a * a : -(k * a * a));
    da += dG * (-(k * a * ac * (1 - c * c)));
}

// The GGX microfacet reflection at (wo, wi) without its Fresnel factor, S = D Go Gi / (4 co),
// and its intermediates (the adjoint reuses them). False where the half vector vanishes.
template <class T>
struct GgxGeometry {
    TVec3<T> h;
    T hl, ch, oh, D, Go, Gi, S;
};
template <class T>
bool ggx_geometry(T alpha, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi, T co, T ci, GgxGeometry<T>& g) {
    const TVec3<T> H = wo + wi;
    g.hl = length(H);
    if (!(g.hl > 0)) return false;
    g.h = H / g.hl;
    g.ch = dot(n, g.h);
    g.oh = dot(wo, g.h);
    g.D = ggx_d(g.ch, alpha);
    g.Go = smith_g1(co, g.oh, alpha);
    g.Gi = smith_g1(ci, g.oh, alpha);
    g.S = g.D * g.Go * g.Gi / (4 * co);
    return true;
}
// Adds the adjoint of ggx_geometry, given the adjoints of S and of oh (through a Fresnel factor),
// to dalpha, dn, dwo, dwi, dco, dci.
template <class T, class A>
void d_ggx_geometry(T alpha, const TVec3<T>& n, const TVec3<T>& wo, T co, T ci, const GgxGeometry<T>& g, A dS, A doh,
                    A& dalpha, TVec3<A>& dn, TVec3<A>& dwo, TVec3<A>& dwi, A& dco, A& dci) {
    // S = D Go Gi / (4 co)
    const A dD = dS * g.Go * g.Gi / (4 * co);
    const A dGo = dS * g.D * g.Gi / (4 * co);
    const A dGi = dS * g.D * g.Go / (4 * co);
    dco += -dS * g.S / co;
    A dch = A(0);
    d_ggx_d(g.ch, alpha, dD, dch, dalpha);
    d_smith_g1(co, g.oh, alpha, dGo, dco, dalpha);
    d_smith_g1(ci, g.oh, alpha, dGi, dci, dalpha);
    // ch = n . h, oh = wo . h, h = H / |H|, H = wo + wi
    const TVec3<A> dh = n * dch + wo * doh;
    dn += g.h * dch;
    dwo += g.h * doh;
    const TVec3<A> dH = (dh - g.h * dot(g.h, dh)) / g.hl;
    dwo += dH;
    dwi += dH;
}

// The specular lobe's value F * S at (wo, wi), F Schlick's (the adjoint reuses the terms).
// False where the half vector vanishes (the lobe is then zero).
template <class T>
struct GgxTerms : GgxGeometry<T> {
    TVec3<T> F;
    T m, m5;
};
template <class T>
bool ggx_terms(const TBsdfParams<T>& p, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi, T co, T ci,
               GgxTerms<T>& g) {
    if (!ggx_geometry(p.alpha, n, wo, wi, co, ci, g)) return false;
    g.m = std::clamp(1 - g.oh, T(0), T(1));
    g.m5 = g.m * g.m * g.m * g.m * g.m;
    g.F = p.specular + (TVec3<T>(T(1)) - p.specular) * g.m5;
    return true;
}

// Fresnel reflectance of a dielectric interface for the cosine c > 0 of incidence and the
// relative index e (the far side's over the near side's); 1 under total internal reflection.
template <class T> T fresnel_dielectric(T c, T e) {
    const T q = (1 - c * c) / (e * e);
    if (q >= 1) return 1;
    const T ct = std::sqrt(1 - q), a = e * ct, b = e * c;
    const T rs = (c - a) / (c + a), rp = (b - ct) / (b + ct);
    return (rs * rs + rp * rp) / 2;
}
template <class T, class A> void d_fresnel_dielectric(T c, T e, A dF, A& dc, A& de) {
    const T q = (1 - c * c) / (e * e);
    if (q >= 1) return;
    const T ct = std::sqrt(1 - q), a = e * ct, b = e * c;
    const T rs = (c - a) / (c + a), rp = (b - ct) / (b + ct);
    // F = (rs^2 + rp^2) / 2
    const A drs = dF * rs, drp = dF * rp;
    // rs = (c - a) / (c + a), rp = (b - ct) / (b + ct)
    const T ua = (c + a) * (c + a), ub = (b + ct) * (b + ct);
    dc += drs * 2 * a / ua;
    const A da = -drs * 2 * c / ua;
    const A db = drp * 2 * ct / ub;
    A dct = -drp * 2 * b / ub;
    // a = e ct, b = e c
    de += da * ct + db * c;
    dct += da * e;
    dc += db * e;
    // ct = sqrt(1 - q), q = (1 - c^2) / e^2
    if (ct > 0) {
        const A dq = -dct / (2 * ct);
        dc += dq * (-2 * c / (e * e));
        de += dq * (-2 * (1 - c * c) / (e * e * e));
    }
}

// The rough dielectric (Walter et al. 2007, GGX with separable Smith shadowing) at (wo, wi),
// world space, and its intermediates. With N = s n the normal on wo's side (s = sign(n . wo)),
// co = N . wo > 0 and ci = N . wi: reflection where ci > 0, transmission where ci < 0. e is the
// index on wi's side over wo's for a transmission (eta or 1 / eta). The microfacet normal h is
// wo + wi (reflection) or wo + e wi (transmission), normalised and turned to N's side; wo must
// see its front (oh = wo . h > 0) and wi its front (reflection) or back (transmission). Value
// (f times |N . wi|, radiance, so scaled by 1 / e^2 across the interface):
//   reflection:   F D Go Gi / (4 co)
//   transmission: oh |ih| (1 - F) D Go Gi / (co (oh + e ih)^2),  ih = wi . h < 0
// with F the Fresnel reflectance at oh. False where it is zero by geometry.
template <class T>
struct RoughDielectricTerms {
    T s, co, ci, e, hl, sg, ch, oh, ih, D, Go, Gi, F, den, v;
    TVec3<T> H, h0, h;
    bool reflect;
};
template <class T>
bool rough_dielectric_terms(T alpha, T eta, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi,
                            RoughDielectricTerms<T>& r) {
    const T c = dot(n, wo);
    if (c == 0) return false;
    r.s = c < 0 ? T(-1) : T(1);
    r.co = r.s * c;
    r.ci = r.s * dot(n, wi);
    if (r.ci == 0) return false;
    r.e = c < 0 ? 1 / eta : eta;
    r.reflect = r.ci > 0;
    r.H = r.reflect ? wo + wi : wo + wi * r.e;
    r.hl = length(r.H);
    if (!(r.hl > 0)) return false;
    r.h0 = r.H / r.hl;
    const T c0 = r.s * dot(n, r.h0);
    r.sg = c0 < 0 ? T(-1) : T(1);
    r.h = r.h0 * r.sg;
    r.ch = r.sg * c0;
    r.oh = dot(wo, r.h);
    r.ih = dot(wi, r.h);
    if (!(r.oh > 0) || (r.reflect ? !(r.ih > 0) : !(r.ih < 0))) return false;
    r.D = ggx_d(r.ch, alpha);
    r.Go = smith_g1(r.co, r.oh, alpha);
    r.Gi = smith_g1(r.ci, r.ih, alpha);
    r.F = fresnel_dielectric(r.oh, r.e);
    if (r.reflect) {
        r.den = 0;
        r.v = r.F * r.D * r.Go * r.Gi / (4 * r.co);
    } else {
        r.den = r.oh + r.e * r.ih;
        r.v = r.oh * -r.ih * (1 - r.F) * r.D * r.Go * r.Gi / (r.co * r.den * r.den);
    }
    return true;
}

// Adds the adjoint of the rough dielectric's value for its adjoint dv to (dn, dwo, dwi, dalpha, deta).
template <class T, class A>
void d_rough_dielectric(T alpha, T eta, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi, A dv,
                        TVec3<A>& dn, TVec3<A>& dwo, TVec3<A>& dwi, A& dalpha, A& deta) {
    RoughDielectricTerms<T> r;
    if (!rough_dielectric_terms(alpha, eta, n, wo, wi, r)) return;
    A dF = A(0), dD = A(0), dGo = A(0), dGi = A(0), dco = A(0), dci = A(0), doh = A(0), dih = A(0), de = A(0),
      dch = A(0);
    if (r.reflect) {
        // v = F D Go Gi / (4 co)
        const A k = dv / (4 * r.co);
        dF = k * r.D * r.Go * r.Gi;
        dD = k * r.F * r.Go * r.Gi;
        dGo = k * r.F * r.D * r.Gi;
        dGi = k * r.F * r.D * r.Go;
        dco = -dv * r.v / r.co;
    } else {
        // v = oh (-ih) (1 - F) D Go Gi / (co den^2)
        const T base = r.oh * -r.ih / (r.co * r.den * r.den);
        dF = -dv * base * r.D * r.Go * r.Gi;
        const A k = dv * base * (1 - r.F);
        dD = k * r.Go * r.Gi;
        dGo = k * r.D * r.Gi;
        dGi = k * r.D * r.Go;
        doh += dv * (-r.ih) * (1 - r.F) * r.D * r.Go * r.Gi / (r.co * r.den * r.den);
        dih += -dv * r.oh * (1 - r.F) * r.D * r.Go * r.Gi / (r.co * r.den * r.den);
        dco = -dv * r.v / r.co;
        const A dden = -2 * dv * r.v / r.den;
        // den = oh + e ih
        doh += dden;
        de += dden * r.ih;
        dih += dden * r.e;
    }
    // F = fresnel(oh, e)
    d_fresnel_dielectric(r.oh, r.e, dF, doh, de);
    // D = D(ch), Go = G1(co, oh), Gi = G1(ci, ih)
    d_ggx_d(r.ch, alpha, dD, dch, dalpha);
    d_smith_g1(r.co, r.oh, alpha, dGo, dco, dalpha);
    d_smith_g1(r.ci, r.ih, alpha, dGi, dci, dalpha);
    // ch = s n . h, oh = wo . h, ih = wi . h
    const TVec3<A> dh = n * (r.s * dch) + wo * doh + wi * dih;
    dn += r.h * (r.s * dch);
    dwo += r.h * doh;
    dwi += r.h * dih;
    // h = sg H / |H|
    const TVec3<A> dh0 = dh * r.sg;
    const TVec3<A> dH = (dh0 - r.h0 * dot(r.h0, dh0)) / r.hl;
    // H = wo + wi, or wo + e wi
    dwo += dH;
    if (r.reflect) {
        dwi += dH;
    } else {
        dwi += dH * r.e;
        de += dot(dH, wi);
    }
    // co = s n . wo, ci = s n . wi
    dn += (wo * dco + wi * dci) * r.s;
    dwo += n * (r.s * dco);
    dwi += n * (r.s * dci);
    // e = eta (wo outside) or 1 / eta
    deta += r.s > 0 ? de : -de * r.e * r.e;
}

// The plastic coating's transmittance T(c) at cosine c > 0 (scene/plastic.h), and its adjoint.
template <class T> T coat_transmittance(const CoatTable& tab, T c, T eta) {
    if (tab.smooth) return 1 - fresnel_dielectric(c, eta);
    const CoatLookup l = coat_lookup(float(c));
    return T(tab.t[l.i]) * (1 - T(l.w)) + T(tab.t[l.i + 1]) * T(l.w);
}
template <class T, class A>
void d_coat_transmittance(const CoatTable& tab, T c, T eta, A dt, A& dc, A& dalpha, A& deta) {
    if (tab.smooth) {
        d_fresnel_dielectric(c, eta, -dt, dc, deta);
        return;
    }
    const CoatLookup l = coat_lookup(float(c));
    const T w = T(l.w);
    if (c > 0 && c < 1) dc += dt * T(tab.t[l.i + 1] - tab.t[l.i]) * T(kCoatResolution - 1);
    dalpha += dt * (T(tab.dt_dalpha[l.i]) * (1 - w) + T(tab.dt_dalpha[l.i + 1]) * w);
    deta += dt * (T(tab.dt_deta[l.i]) * (1 - w) + T(tab.dt_deta[l.i + 1]) * w);
}

// The plastic's f cos(theta_i) at (wo, wi) with co = n . wo > 0, ci = n . wi > 0 (scene/plastic.h).
template <class T>
struct PlasticTerms {
    T to, ti, k;
    TVec3<T> den, diff;
    bool spec = false;  // the rough coating's lobe: F g.S
    GgxGeometry<T> g;
    T F;
};
template <class T>
TVec3<T> plastic_terms(const TBsdfParams<T>& p, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi, T co,
                       T ci, PlasticTerms<T>& t) {
    const CoatTable& tab = *p.coat;
    const T R = T(tab.r);
    // diffuse: kd / den T(co) T(ci) ci / (pi eta^2), den = 1 - R or 1 - kd R
    t.to = coat_transmittance(tab, co, p.eta);
    t.ti = coat_transmittance(tab, ci, p.eta);
    t.k = t.to * t.ti * ci / (pi<T>() * p.eta * p.eta);
    t.den = p.nonlinear ? TVec3<T>(T(1)) - p.diffuse * R : TVec3<T>(1 - R);
    t.diff = TVec3<T>(p.diffuse.x / t.den.x, p.diffuse.y / t.den.y, p.diffuse.z / t.den.z);
    TVec3<T> result = t.diff * t.k;
    t.spec = false;
    if (tab.smooth || is_black(p.specular)) return result;
    // specular: ks F(oh) D Go Gi / (4 co)
    if (!ggx_geometry(p.alpha, n, wo, wi, co, ci, t.g)) return result;
    t.spec = true;
    t.F = t.g.oh > 0 ? fresnel_dielectric(t.g.oh, p.eta) : T(0);
    return result + p.specular * (t.F * t.g.S);
}

// Adds the adjoint of plastic_terms (output adjoint dr) to d, and to dn / dco / dci.
template <class T, class A>
void d_plastic(const TBsdfParams<T>& p, const TVec3<T>& n, const TVec3<T>& wo, const TVec3<T>& wi, T co, T ci,
               const TVec3<T>& dr, DBsdf<T, A>& d, TVec3<A>& dn, A& dco, A& dci) {
    PlasticTerms<T> t;
    plastic_terms(p, n, wo, wi, co, ci, t);
    const CoatTable& tab = *p.coat;
    // result = diff k
    const A dk = colour_dot<A>(dr, t.diff);
    A dR = A(0);
    for (int c = 0; c < 3; ++c) {
        // diff = kd / den, den = 1 - R (linear) or 1 - kd R (nonlinear)
        const T ddiff = dr[c] * t.k, den = t.den[c];
        if (p.nonlinear) {
            d.diffuse[c] += ddiff / (den * den);
            dR += one_colour<A>(c, ddiff * p.diffuse[c] * p.diffuse[c] / (den * den));
        } else {
            d.diffuse[c] += ddiff / den;
            dR += one_colour<A>(c, ddiff * p.diffuse[c] / (den * den));
        }
    }
    d.alpha += dR * T(tab.dr_dalpha);
    d.eta += dR * T(tab.dr_deta);
    // k = to ti ci / (pi eta^2)
    const T g = 1 / (pi<T>() * p.eta * p.eta);
    d_coat_transmittance(tab, co, p.eta, dk * t.ti * ci * g, dco, d.alpha, d.eta);
    d_coat_transmittance(tab, ci, p.eta, dk * t.to * ci * g, dci, d.alpha, d.eta);
    dci += dk * t.to * t.ti * g;
    d.eta += dk * t.k * T(-2) / p.eta;
    if (!t.spec) return;
    // result += ks F g.S
    d.specular += dr * (t.F * t.g.S);
    const A dFS = colour_dot<A>(dr, p.specular);
    A doh = A(0);
    if (t.g.oh > 0) d_fresnel_dielectric(t.g.oh, p.eta, dFS * t.g.S, doh, d.eta);
    d_ggx_geometry(p.alpha, n, wo, co, ci, t.g, dFS * t.F, doh, d.alpha, dn, d.wo, d.wi, dco, dci);
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
template <class T, class A>
void d_bend_normal(const TVec3<T>& ns, const TVec3<T>& ng, const TVec3<T>& wo, const TVec3<A>& dout, TVec3<A>& dns,
                   TVec3<A>& dwo) {
    const T s = dot(wo, ng) < 0 ? T(-1) : T(1), d = dot(wo, ns);
    if (s * d >= T(kMinShadingCosine)) {
        dns += dout;
        return;
    }
    // N = ns + k wo, k = s c - wo . ns
    const T k = s * T(kMinShadingCosine) - d;
    const TVec3<A> dN = d_normalize(ns + wo * k, dout);
    const A dk = dot(dN, wo);
    dns += dN - wo * dk;
    dwo += dN * k - ns * dk;
}

// f(wo, wi) * cos(theta_i), world space; n unit shading normal, wo/wi unit.
template <class T>
TVec3<T> bsdf_eval_world(const TBsdfParams<T>& p, TVec3<T> n, const TVec3<T>& wo, const TVec3<T>& wi) {
    if (p.kind == MaterialKind::Dielectric && p.rough) {
        detail::RoughDielectricTerms<T> r;
        return TVec3<T>(detail::rough_dielectric_terms(p.alpha, p.eta, n, wo, wi, r) ? r.v : T(0));
    }
    if (p.kind != MaterialKind::Standard && p.kind != MaterialKind::Plastic) return TVec3<T>(T(0));
    T co = dot(n, wo);
    if (p.two_sided && co < 0) {
        n = -n;
        co = -co;
    }
    T ci = dot(n, wi);
    if (co <= 0 || ci <= 0) return TVec3<T>(T(0));
    if (p.kind == MaterialKind::Plastic) {
        detail::PlasticTerms<T> t;
        return detail::plastic_terms(p, n, wo, wi, co, ci, t);
    }
    TVec3<T> result = p.diffuse * (ci / detail::pi<T>());
    detail::GgxTerms<T> g;
    if (!is_black(p.specular) && detail::ggx_terms(p, n, wo, wi, co, ci, g)) result += g.F * g.S;
    return result;
}

// Adds to `d` the adjoint of bsdf_eval_world for the output adjoint `dr`.
template <class T, class A>
void d_bsdf_eval_world(const TBsdfParams<T>& p, TVec3<T> n, const TVec3<T>& wo, const TVec3<T>& wi,
                       const TVec3<T>& dr, DBsdf<T, A>& d) {
    if (p.kind == MaterialKind::Dielectric && p.rough) {
        // result = (v, v, v)
        detail::d_rough_dielectric(p.alpha, p.eta, n, wo, wi, colour_sum<A>(dr), d.n, d.wo, d.wi, d.alpha, d.eta);
        return;
    }
    if (p.kind != MaterialKind::Standard && p.kind != MaterialKind::Plastic) return;
    T co = dot(n, wo);
    bool flipped = p.two_sided && co < 0;
    if (flipped) {
        n = -n;
        co = -co;
    }
    T ci = dot(n, wi);
    if (co <= 0 || ci <= 0) return;
    TVec3<A> dn(A(0));
    A dco = A(0), dci = A(0);
    if (p.kind == MaterialKind::Plastic) {
        detail::d_plastic(p, n, wo, wi, co, ci, dr, d, dn, dco, dci);
    } else {
        // result = diffuse * ci / pi
        d.diffuse += dr * (ci / detail::pi<T>());
        dci += colour_dot<A>(dr, p.diffuse) / detail::pi<T>();
        detail::GgxTerms<T> g;
        if (!is_black(p.specular) && detail::ggx_terms(p, n, wo, wi, co, ci, g)) {
            // result += F * S
            TVec3<T> dF = dr * g.S;
            A dS = colour_dot<A>(dr, g.F);
            // F = ks + (1 - ks) m^5, m = clamp(1 - oh)
            d.specular += dF * (1 - g.m5);
            T m4 = g.m * g.m * g.m * g.m;
            A dm = (1 - g.oh > 0 && 1 - g.oh < 1) ? colour_dot<A>(dF, TVec3<T>(T(1)) - p.specular) * 5 * m4 : A(0);
            detail::d_ggx_geometry(p.alpha, n, wo, co, ci, g, dS, -dm, d.alpha, dn, d.wo, d.wi, dco, dci);
        }
    }
    // co = n.wo, ci = n.wi
    dn += wo * dco + wi * dci;
    d.wo += n * dco;
    d.wi += n * dci;
    d.n += flipped ? -dn : dn;
}

}  // namespace edgepath
