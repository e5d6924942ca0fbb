// Smooth (delta) BSDFs and their adjoint: the mirror (a smooth conductor, Schlick reflectance
// with `specular` at normal incidence), the smooth dielectric (glass: Fresnel reflection
// and refraction with a relative index of refraction eta, inside over outside) and the smooth
// plastic's coating (its reflection only: `specular` times the dielectric's Fresnel
// reflectance, one-sided unless two_sided; its diffuse base has a density, scene/bsdf.h). Each scatters
// a direction wo into one direction; the path tracer picks the dielectric's lobe with the
// Fresnel reflectance as probability and divides by that probability (a constant: the
// gradient differentiates the lobe's value, not the choice). Directions and normal are world
// or local alike: n is the unit shading normal, wo the unit direction towards the viewer.
// The outgoing direction is a function of n, wo and eta, so the adjoint returns derivatives
// with respect to all three (a path through glass moves when the glass or the index does).
//
// Each forward line appears as a comment above the lines of its adjoint.
#pragma once
#include <algorithm>
#include <cmath>
#include "math/vec.h"

namespace edgepath {

// The relative indices of refraction a scene may use (validated when it is built).
constexpr float kMinIor = 0.1f, kMaxIor = 10.f;

template <class T>
struct DeltaParams {
    TVec3<T> specular;        // mirror: reflectance at normal incidence
    T eta = T(1.5);           // dielectric: inside over outside
    bool dielectric = false;  // false: mirror
    bool two_sided = false;   // mirror, coating: reflects on the back too
    bool coat = false;        // the plastic's coating (dielectric false)
};

template <class T>
struct DDelta {
    TVec3<T> specular, n, wo;
    T eta = 0;
};

namespace detail {

// The geometry of one dielectric interaction: s = side of wo (+1 outside), ci = |wo . n|,
// e = eta_transmitted / eta_incident, q = sin^2 of the refracted angle, ct = its cosine.
template <class T>
struct Interface {
    T s, ci, e, q, ct, a, b, rs, rp, F;
    bool tir;
};

template <class T>
Interface<T> dielectric_interface(T eta, const TVec3<T>& n, const TVec3<T>& wo) {
    Interface<T> f{};
    const T c = dot(n, wo);
    f.s = c < 0 ? T(-1) : T(1);
    f.ci = f.s * c;
    f.e = c < 0 ? 1 / eta : eta;
    f.q = (1 - f.ci * f.ci) / (f.e * f.e);
    f.tir = f.q >= 1;
    if (f.tir) {
        f.F = 1;
        return f;
    }
    f.ct = std::sqrt(1 - f.q);
    f.a = f.e * f.ct;
    f.b = f.e * f.ci;
    f.rs = (f.ci - f.a) / (f.ci + f.a);
    f.rp = (f.b - f.ct) / (f.b + f.ct);
    f.F = (f.rs * f.rs + f.rp * f.rp) / 2;
    return f;
}

// Adds the adjoint of the interface's F for its adjoint dF to (dci, de, dct): F = (rs^2 + rp^2) / 2.
template <class T>
void d_interface_fresnel(const Interface<T>& f, T dF, T& dci, T& de, T& dct) {
    const T drs = dF * f.rs, drp = dF * f.rp;
    // rs = (ci - a) / (ci + a), rp = (b - ct) / (b + ct)
    const T ua = (f.ci + f.a) * (f.ci + f.a), ub = (f.b + f.ct) * (f.b + f.ct);
    dci += drs * 2 * f.a / ua;
    const T da = -drs * 2 * f.ci / ua;
    const T db = drp * 2 * f.ct / ub;
    dct += -drp * 2 * f.b / ub;
    // a = e ct, b = e ci
    de += da * f.ct + db * f.ci;
    dct += da * f.e;
    dci += db * f.e;
    // ct = sqrt(1 - q), q = (1 - ci^2) / e^2
    if (f.ct > 0) {
        const T dq = -dct / (2 * f.ct);
        dci += dq * (-2 * f.ci / (f.e * f.e));
        de += dq * (-2 * (1 - f.ci * f.ci) / (f.e * f.e * f.e));
    }
}

}  // namespace detail

// Fresnel reflectance of the dielectric seen from wo: the probability of reflection.
template <class T>
T dielectric_reflectance(T eta, const TVec3<T>& n, const TVec3<T>& wo) {
    return detail::dielectric_interface(eta, n, wo).F;
}

// The direction and weight (value over the choice's probability 1 / inv_prob) of the lobe
// `refract` (dielectrics only) for wo. False where the lobe does not exist: a one-sided
// mirror seen from behind, refraction under total internal reflection, wo in the surface.
template <class T>
bool delta_scatter(const DeltaParams<T>& p, const TVec3<T>& n, const TVec3<T>& wo, bool refract, T inv_prob,
                   TVec3<T>& dir, TVec3<T>& weight) {
    if (p.coat) {
        // The coating from outside (its front, or its back when two-sided): relative index eta.
        const T s = p.two_sided && dot(n, wo) < 0 ? T(-1) : T(1);
        const detail::Interface<T> f = detail::dielectric_interface(p.eta, n * s, wo);
        if (refract || !(f.s > 0 && f.ci > 0)) return false;
        dir = n * (2 * s * f.ci) - wo;
        weight = p.specular * (f.F * inv_prob);
        return true;
    }
    if (!p.dielectric) {
        T c = dot(n, wo);
        const T s = p.two_sided && c < 0 ? T(-1) : T(1);
        c *= s;
        if (refract || !(c > 0)) return false;
        dir = n * (2 * s * c) - wo;
        const T m = std::clamp(1 - c, T(0), T(1));
        const T m5 = m * m * m * m * m;
        weight = p.specular + (TVec3<T>(T(1)) - p.specular) * m5;
        return true;
    }
    const detail::Interface<T> f = detail::dielectric_interface(p.eta, n, wo);
    if (!(f.ci > 0)) return false;
    if (!refract) {
        dir = n * (2 * f.s * f.ci) - wo;
        weight = TVec3<T>(f.F * inv_prob);
        return true;
    }
    if (f.tir) return false;
    dir = n * (f.s * (f.ci / f.e - f.ct)) - wo / f.e;
    // Radiance is scaled by (eta_i / eta_t)^2 across the interface.
    weight = TVec3<T>((1 - f.F) * inv_prob / (f.e * f.e));
    return true;
}

// Adds to `d` the adjoint of delta_scatter for the adjoints `ddir` and `dweight` of its outputs.
template <class T>
void d_delta_scatter(const DeltaParams<T>& p, const TVec3<T>& n, const TVec3<T>& wo, bool refract, T inv_prob,
                     const TVec3<T>& ddir, const TVec3<T>& dweight, DDelta<T>& d) {
    if (p.coat) {
        const T s = p.two_sided && dot(n, wo) < 0 ? T(-1) : T(1);
        const detail::Interface<T> f = detail::dielectric_interface(p.eta, n * s, wo);
        if (refract || !(f.s > 0 && f.ci > 0)) return;
        T dci = 0, de = 0, dct = 0;
        // dir = n (2 s ci) - wo
        d.n += ddir * (2 * s * f.ci);
        dci += 2 * s * dot(ddir, n);
        d.wo -= ddir;
        // weight = ks F inv_prob
        d.specular += dweight * (f.F * inv_prob);
        if (!f.tir) detail::d_interface_fresnel(f, dot(dweight, p.specular) * inv_prob, dci, de, dct);
        // e = eta; ci = (s n) . wo
        d.eta += de;
        d.n += wo * (s * dci);
        d.wo += n * (s * dci);
        return;
    }
    if (!p.dielectric) {
        T c0 = dot(n, wo);
        const T s = p.two_sided && c0 < 0 ? T(-1) : T(1);
        const T c = s * c0;
        if (refract || !(c > 0)) return;
        T dc = 0;
        // dir = n (2 s c) - wo
        d.n += ddir * (2 * s * c);
        dc += 2 * s * dot(ddir, n);
        d.wo -= ddir;
        // weight = F0 + (1 - F0) m^5, m = clamp(1 - c)
        const T m = std::clamp(1 - c, T(0), T(1));
        const T m4 = m * m * m * m;
        d.specular += dweight * (1 - m4 * m);
        if (1 - c > 0 && 1 - c < 1) dc -= dot(dweight, TVec3<T>(T(1)) - p.specular) * 5 * m4;
        // c = s (n . wo)
        d.n += wo * (s * dc);
        d.wo += n * (s * dc);
        return;
    }
    const detail::Interface<T> f = detail::dielectric_interface(p.eta, n, wo);
    if (!(f.ci > 0) || (refract && f.tir)) return;
    T dci = 0, de = 0, dct = 0, dF = 0;
    const T dw = dweight.x + dweight.y + dweight.z;
    if (!refract) {
        // dir = n (2 s ci) - wo
        d.n += ddir * (2 * f.s * f.ci);
        dci += 2 * f.s * dot(ddir, n);
        d.wo -= ddir;
        // weight = F inv_prob
        dF += dw * inv_prob;
    } else {
        // dir = n (s (ci / e - ct)) - wo / e
        const T g = f.s * (f.ci / f.e - f.ct);
        d.n += ddir * g;
        const T dg = f.s * dot(ddir, n);
        dci += dg / f.e;
        de += -dg * f.ci / (f.e * f.e) + dot(ddir, wo) / (f.e * f.e);
        dct -= dg;
        d.wo -= ddir / f.e;
        // weight = (1 - F) inv_prob / e^2
        dF -= dw * inv_prob / (f.e * f.e);
        de += dw * (1 - f.F) * inv_prob * T(-2) / (f.e * f.e * f.e);
    }
    if (!f.tir) detail::d_interface_fresnel(f, dF, dci, de, dct);
    // e = eta (outside) or 1 / eta (inside)
    d.eta += f.s > 0 ? de : -de * f.e * f.e;
    // ci = s (n . wo)
    d.n += wo * (f.s * dci);
    d.wo += n * (f.s * dci);
}

// The side of the face a smooth lobe's direction must leave on. About an interpolated shading
// normal, the mirror direction may point below the face (and a refraction back out of it); such
// a ray used to go on into the mesh (black inside a mirror, trapped inside glass) or out,
// unrefracted: a jump in the image where the direction crosses the face's plane, along curves
// inside triangles that move with the normals and the vertices and lie on no edge, so no
// boundary term could account for it. Mirrored across the face's plane instead (ng the unit
// geometric normal, `side` +1 where dir must have dir . ng >= 0, -1 for the other side),
// the direction is continuous there: the same as before where it was on its side, and
// the reflection of a direction that just grazes the plane grazes it too.
template <class T>
TVec3<T> delta_side(const TVec3<T>& dir, const TVec3<T>& ng, T side) {
    const T t = dot(dir, ng);
    if (side * t >= 0) return dir;
    return dir - ng * (2 * t);
}

// The delta lobe's side: a reflection leaves on wo's side of the face, a refraction on the other.
template <class T>
T delta_side_sign(const TVec3<T>& wo, const TVec3<T>& ng, bool refract) {
    const bool front = dot(wo, ng) >= 0;
    return front != refract ? T(1) : T(-1);
}

// Adds the adjoint of delta_side for the adjoint `dout` of its output to (ddir, dng) and
// returns whether it mirrored dir.
template <class T, class A>
bool d_delta_side(const TVec3<T>& dir, const TVec3<T>& ng, T side, const TVec3<A>& dout, TVec3<A>& ddir,
                  TVec3<A>& dng) {
    const T t = dot(dir, ng);
    if (side * t >= 0) {
        ddir += dout;
        return false;
    }
    // out = dir - 2 t ng, t = dir . ng
    const A g = dot(dout, ng);
    ddir += dout - (ng * g) * T(2);
    dng -= dout * (2 * t) + (dir * g) * T(2);
    return true;
}

}  // namespace edgepath
