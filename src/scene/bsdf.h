// The material model: a Lambertian lobe plus a GGX microfacet lobe (Smith shadowing, separable,
// Schlick Fresnel with `specular` as the reflectance at normal incidence). Directions are in the
// local shading frame (z = shading normal), `wo` towards the viewer, `wi` towards the light.
// One-sided unless `two_sided`: black when either direction is below the shading surface.
// The rough dielectric (Walter et al. 2007; scene/bsdf_diff.h holds its value) reflects and
// transmits, from either side. The plastic (scene/plastic.h) is a diffuse base under a
// dielectric coating, rough or smooth; the smooth coating's reflection is a delta lobe, sampled
// beside the base's density. The smooth materials (mirror, glass: scene/specular.h) have no density: their eval and pdf
// are zero, and bsdf_sample returns their one direction with its weight.
#pragma once
#include <algorithm>
#include <cmath>
#include "math/vec.h"
#include "sampling/warp.h"
#include "scene/bsdf_diff.h"
#include "scene/desc.h"
#include "scene/specular.h"

namespace edgepath {

// Smallest GGX alpha; below it the lobe is numerically a mirror in float.
constexpr float kMinRoughness = 1e-3f;

// The GGX alpha of a material's roughness value (Scene::bsdf_params; the forward batches'
// vectors take the same).
inline float ggx_alpha(float roughness) { return std::max(roughness, kMinRoughness); }

struct BsdfParams {
    Vec3f diffuse;
    Vec3f specular;
    float alpha = 0.5f;
    bool two_sided = false;
    MaterialKind kind = MaterialKind::Standard;
    float eta = 1.5f;  // Dielectric: relative index of refraction
    bool rough = false;  // Dielectric, Plastic: rough (GGX with `alpha`) rather than smooth
    const CoatTable* coat = nullptr;  // Plastic: its coating
    bool nonlinear = false;           // Plastic
};

inline bool is_delta(const BsdfParams& p) { return is_delta_kind(p.kind, p.rough); }
inline bool is_rough_dielectric(const BsdfParams& p) { return p.kind == MaterialKind::Dielectric && p.rough; }

// The smooth-scattering parameters of a material's values (BsdfParams or TBsdfParams<float>).
template <class Params>
DeltaParams<float> delta_params(const Params& p) {
    return DeltaParams<float>{p.specular, p.eta, p.kind == MaterialKind::Dielectric, p.two_sided,
                              p.kind == MaterialKind::Plastic};
}

inline TBsdfParams<float> world_params(const BsdfParams& p) {
    return TBsdfParams<float>{p.diffuse, p.specular, p.alpha, p.two_sided, p.kind, p.eta, p.rough, p.coat,
                              p.nonlinear};
}

struct BsdfSample {
    Vec3f wi;
    float pdf = 0.f;  // solid angle, of the whole mixture; smooth materials: the lobe's probability
    // Smooth materials: the direction is the only one (no density, no light sampling), with
    // this weight (value over probability); `refract`: the dielectric's transmission.
    bool delta = false, refract = false;
    Vec3f weight;
};

inline float ggx_D(const Vec3f& h, float a) {
    if (h.z <= 0.f) return 0.f;
    float a2 = a * a;
    float c2 = h.z * h.z;
    float d = c2 * (a2 - 1.f) + 1.f;
    return a2 / (kPi * d * d);
}

inline float ggx_G1(const Vec3f& w, const Vec3f& h, float a) {
    if (dot(w, h) * w.z <= 0.f) return 0.f;
    float c2 = w.z * w.z;
    if (c2 >= 1.f) return 1.f;
    float tan2 = (1.f - c2) / c2;
    return 2.f / (1.f + std::sqrt(1.f + a * a * tan2));
}

inline Vec3f fresnel_schlick(const Vec3f& f0, float cos_theta) {
    float m = std::clamp(1.f - cos_theta, 0.f, 1.f);
    float m5 = (m * m) * (m * m) * m;
    return f0 + (Vec3f(1.f) - f0) * m5;
}

// Probability of choosing the plastic's coating (its reflection) when sampling, for wo at cosine
// co > 0: the coating's reflectance 1 - T(co) weighted by the mean specular reflectance, against
// the light it transmits weighted by the mean diffuse one (Mitsuba's choice).
// The means ks, kd of the reflectances, and from T(co) = t the probability itself (the
// forward batches' plastic lanes compute the same, render/shade_lanes.h).
inline float plastic_mean(const Vec3f& c) { return (c.x + c.y + c.z) / 3.f; }
inline float plastic_coat_probability(float ks, float kd, float t) {
    if (!(ks + kd > 0.f)) return 0.f;
    const float s = (1.f - t) * ks, d = t * kd;
    return s + d > 0.f ? s / (s + d) : 0.f;
}
inline float plastic_coat_probability(const BsdfParams& p, float co) {
    const float ks = plastic_mean(p.specular), kd = plastic_mean(p.diffuse);
    if (!(ks + kd > 0.f)) return 0.f;
    return plastic_coat_probability(ks, kd, detail::coat_transmittance(*p.coat, co, p.eta));
}

// Probability of choosing the specular lobe when sampling.
inline float specular_lobe_probability(const BsdfParams& p) {
    float d = luminance(p.diffuse), s = luminance(p.specular);
    if (d + s <= 0.f) return 0.f;
    return s / (d + s);
}

// Mirrors both directions to the front side of a two-sided material. False if the pair is
// not in the upper hemisphere (the BSDF is zero).
inline bool orient(const BsdfParams& p, Vec3f& wo, Vec3f& wi) {
    if (p.two_sided && wo.z < 0.f) {
        wo.z = -wo.z;
        wi.z = -wi.z;
    }
    return wo.z > 0.f && wi.z > 0.f;
}

// f(wo, wi) * cos(theta_i).
inline Vec3f bsdf_eval(const BsdfParams& p, Vec3f wo, Vec3f wi) {
    if (is_rough_dielectric(p)) {
        detail::RoughDielectricTerms<float> r;
        return Vec3f(detail::rough_dielectric_terms(p.alpha, p.eta, Vec3f(0.f, 0.f, 1.f), wo, wi, r) ? r.v : 0.f);
    }
    if (is_delta(p)) return Vec3f(0.f);
    if (!orient(p, wo, wi)) return Vec3f(0.f);
    if (p.kind == MaterialKind::Plastic) {
        detail::PlasticTerms<float> t;
        return detail::plastic_terms(world_params(p), Vec3f(0.f, 0.f, 1.f), wo, wi, wo.z, wi.z, t);
    }
    Vec3f result = p.diffuse * (wi.z * kInvPi);
    if (!is_black(p.specular)) {
        Vec3f h = normalize(wo + wi);
        float D = ggx_D(h, p.alpha);
        float G = ggx_G1(wo, h, p.alpha) * ggx_G1(wi, h, p.alpha);
        Vec3f F = fresnel_schlick(p.specular, dot(wi, h));
        result += F * (D * G / (4.f * wo.z));
    }
    return result;
}

// Density of the GGX visible-normal sampling of wi (solid angle).
inline float ggx_pdf(const Vec3f& wo, const Vec3f& wi, float a) {
    Vec3f h = normalize(wo + wi);
    float woh = dot(wo, h);
    if (woh <= 0.f) return 0.f;
    return ggx_G1(wo, h, a) * ggx_D(h, a) / (4.f * wo.z);
}

// Density of the rough dielectric's sampling (bsdf_sample): a visible normal h for wo turned to
// its side, then reflection with probability F(wo . h), else refraction through h.
inline float rough_dielectric_pdf(const BsdfParams& p, Vec3f wo, Vec3f wi) {
    if (wo.z == 0.f || wi.z == 0.f) return 0.f;
    const float e = wo.z < 0.f ? 1.f / p.eta : p.eta;
    if (wo.z < 0.f) {
        wo.z = -wo.z;
        wi.z = -wi.z;
    }
    const bool reflect = wi.z > 0.f;
    const Vec3f H = reflect ? wo + wi : wo + wi * e;
    const float hl = length(H);
    if (!(hl > 0.f)) return 0.f;
    Vec3f h = H / hl;
    if (h.z < 0.f) h = -h;
    const float oh = dot(wo, h), ih = dot(wi, h);
    if (!(oh > 0.f) || (reflect ? !(ih > 0.f) : !(ih < 0.f))) return 0.f;
    const float F = detail::fresnel_dielectric(oh, e);
    const float visible = ggx_G1(wo, h, p.alpha) * ggx_D(h, p.alpha) * oh / wo.z;
    if (reflect) return F * visible / (4.f * oh);
    const float den = oh + e * ih;
    return (1.f - F) * visible * e * e * -ih / (den * den);
}

inline float bsdf_pdf(const BsdfParams& p, Vec3f wo, Vec3f wi) {
    if (is_rough_dielectric(p)) return rough_dielectric_pdf(p, wo, wi);
    if (is_delta(p)) return 0.f;
    if (!orient(p, wo, wi)) return 0.f;
    if (p.kind == MaterialKind::Plastic) {
        const float ps = plastic_coat_probability(p, wo.z);
        float pdf = (1.f - ps) * wi.z * kInvPi;
        if (p.rough && ps > 0.f) pdf += ps * ggx_pdf(wo, wi, p.alpha);
        return pdf;
    }
    float ps = specular_lobe_probability(p);
    float pdf = (1.f - ps) * wi.z * kInvPi;
    if (ps > 0.f) pdf += ps * ggx_pdf(wo, wi, p.alpha);
    return pdf;
}

// Visible normal of the GGX distribution (Heitz 2018), for wo in the upper hemisphere.
inline Vec3f ggx_sample_visible_normal(const Vec3f& wo, float a, float u1, float u2) {
    Vec3f vh = normalize(Vec3f(a * wo.x, a * wo.y, wo.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    Vec3f t1 = lensq > 0.f ? Vec3f(-vh.y, vh.x, 0.f) / std::sqrt(lensq) : Vec3f(1.f, 0.f, 0.f);
    Vec3f t2 = cross(vh, t1);
    float r = std::sqrt(u1), phi = 2.f * kPi * u2;
    float p1 = r * std::cos(phi), p2 = r * std::sin(phi);
    float s = 0.5f * (1.f + vh.z);
    p2 = (1.f - s) * std::sqrt(std::max(0.f, 1.f - p1 * p1)) + s * p2;
    Vec3f nh = t1 * p1 + t2 * p2 + vh * std::sqrt(std::max(0.f, 1.f - p1 * p1 - p2 * p2));
    return normalize(Vec3f(a * nh.x, a * nh.y, std::max(1e-7f, nh.z)));
}

// Samples wi. Returns false when no direction could be produced (zero BSDF).
inline bool bsdf_sample(const BsdfParams& p, Vec3f wo, float u_lobe, float u1, float u2, BsdfSample& out) {
    if (is_rough_dielectric(p)) {
        // Mirrored to wo's side (the model is symmetric under it, with 1 / eta from inside).
        if (wo.z == 0.f) return false;
        const float s = wo.z < 0.f ? -1.f : 1.f, e = wo.z < 0.f ? 1.f / p.eta : p.eta;
        const Vec3f wu(wo.x, wo.y, s * wo.z);
        const Vec3f h = ggx_sample_visible_normal(wu, p.alpha, u1, u2);
        const float oh = dot(wu, h);
        if (!(oh > 0.f)) return false;
        const float F = detail::fresnel_dielectric(oh, e);
        Vec3f wi;
        if (u_lobe < F) {
            wi = h * (2.f * oh) - wu;
            if (!(wi.z > 0.f)) return false;
        } else {
            const float q = (1.f - oh * oh) / (e * e);
            if (q >= 1.f) return false;
            wi = h * (oh / e - std::sqrt(1.f - q)) - wu / e;
            if (!(wi.z < 0.f)) return false;
            out.refract = true;
        }
        wi = normalize(Vec3f(wi.x, wi.y, s * wi.z));
        out.wi = wi;
        out.pdf = rough_dielectric_pdf(p, wo, wi);
        return out.pdf > 0.f;
    }
    if (is_delta(p)) {
        const DeltaParams<float> d = delta_params(p);
        const Vec3f n(0.f, 0.f, 1.f);
        float prob = 1.f;
        if (d.dielectric) {
            const float F = dielectric_reflectance(d.eta, n, wo);
            out.refract = u_lobe >= F;
            prob = out.refract ? 1.f - F : F;
        }
        if (!(prob > 0.f) || !delta_scatter(d, n, wo, out.refract, 1.f / prob, out.wi, out.weight)) return false;
        out.delta = true;
        out.pdf = prob;
        return true;
    }
    bool flipped = p.two_sided && wo.z < 0.f;
    if (flipped) wo.z = -wo.z;
    if (wo.z <= 0.f) return false;
    const bool plastic = p.kind == MaterialKind::Plastic;
    float ps = plastic ? plastic_coat_probability(p, wo.z) : specular_lobe_probability(p);
    if (luminance(p.diffuse) + luminance(p.specular) <= 0.f) return false;
    if (plastic && !p.rough && u_lobe < ps) {
        // The smooth coating's mirror reflection, weight ks F(co) / ps.
        DeltaParams<float> d = delta_params(p);
        d.two_sided = false;  // wo is on the front already
        if (!delta_scatter(d, Vec3f(0.f, 0.f, 1.f), wo, false, 1.f / ps, out.wi, out.weight)) return false;
        if (flipped) out.wi.z = -out.wi.z;
        out.delta = true;
        out.pdf = ps;
        return true;
    }
    Vec3f wi;
    if (u_lobe < ps) {
        Vec3f h = ggx_sample_visible_normal(wo, p.alpha, u1, u2);
        wi = h * (2.f * dot(wo, h)) - wo;
    } else {
        wi = square_to_cosine_hemisphere(u1, u2);
    }
    if (wi.z <= 0.f) return false;
    float pdf = (1.f - ps) * wi.z * kInvPi;
    if (ps > 0.f && (!plastic || p.rough)) pdf += ps * ggx_pdf(wo, wi, p.alpha);
    if (!(pdf > 0.f)) return false;
    if (flipped) wi.z = -wi.z;
    out.wi = wi;
    out.pdf = pdf;
    return true;
}

}  // namespace edgepath
