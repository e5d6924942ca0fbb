// shade_vertex (render/path.h) for the plain case, four paths at a time: a diffuse material
// (MaterialKind::Standard with a black specular: the Lambertian lobe alone). PathBatch
// (render/batch.cpp) gathers such vertices into the arrays of ShadeLanes (one entry a path:
// structure of arrays), with the random numbers and what needs a table or a branch per path
// computed beforehand path by path: the light picked and, for a triangle sampled by area with
// a constant emission and no spot, its vertices (any other light's sample is taken there by
// Scene::sample_area_light and handed over whole), the numbers of the cosine-weighted sample,
// the environment's sample. Then shade_lanes does the arithmetic over all of them in SSE2
// vectors: the disk point (its cosine and sine per path), the bent shading normal, the frame,
// the BSDF sample, its ray, the light sample's point, both light samples' values, MIS weights
// and shadow rays. (The point lights are left to the gathering code, path by path.) Every lane
// performs scalar shade_vertex's floating-point operations in its order (math/simd4.h), so the
// samples are the same bit for bit (Render.BatchedPlainPathsMatchTracePath).
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "math/ray.h"
#include "math/simd4.h"
#include "sampling/warp.h"
#include "scene/bsdf_diff.h"

namespace edgepath {

template <int N>
struct ShadeLanes {
    static_assert(N % 4 == 0, "whole vectors");
    // In: the vertex (p, its error bound, the geometric and the shading normal), the direction
    // of the ray that found it, the path's throughput, the diffuse reflectance; masks (all bits
    // set: true) of a two-sided material and of a reflectance with luminance above 0.
    alignas(16) float p[3][N], p_error[3][N], ng[3][N], ns[3][N], dir[3][N], beta[3][N], diffuse[3][N];
    alignas(16) float two_sided[N], reflects[N];
    // The BSDF sample's two numbers, made by shade_lanes into the cosine-weighted sample's point
    // on the unit disk (square_to_disk; its cosine and sine per path, the rest in vectors).
    alignas(16) float disk[2][N];
    // The area light's sample (mask light_on): the barycentrics on the triangle picked, its
    // vertices, unit normal and largest edge component, the probability of its pick and its
    // area, its emission (constant) and whether it emits on both sides.
    alignas(16) float light_on[N], b1[N], b2[N], v0[3][N], v1[3][N], v2[3][N], light_ng[3][N], edge[N];
    alignas(16) float pmf[N], area[N], emission[3][N], two_sided_emission[N];
    // Or (mask light_given) a light sample taken by Scene::sample_area_light: its direction,
    // density, radiance, and its point with the point's error bound and normal.
    alignas(16) float light_given[N], given_dir[3][N], given_pdf[N], given_radiance[3][N];
    alignas(16) float given_p[3][N], given_p_error[3][N], given_ng[3][N];
    // The environment's sample (mask env_on): its direction, value and density.
    alignas(16) float env_on[N], env_dir[3][N], env_radiance[3][N], env_pdf[N];

    // Out: the bent shading normal (into ns); the continuation (mask goes_on), its ray and
    // throughput past it and the BSDF sample's density; the area light's shadow ray (mask
    // light_on), what it adds if nothing hides it; the environment's likewise (mask env_on, its
    // direction env_dir, its tmax infinite).
    alignas(16) float goes_on[N], next_origin[3][N], next_dir[3][N], next_beta[3][N], next_pdf[N];
    alignas(16) float light_origin[3][N], light_dir[3][N], light_tmax[N], light_value[3][N];
    alignas(16) float env_origin[3][N], env_value[3][N];

    ShadeLanes() {
        // The lanes past the last path of a block compute on whatever is there: zeros, then
        // earlier paths' values (never read back).
        float* all = reinterpret_cast<float*>(this);
        for (size_t i = 0; i < sizeof(*this) / sizeof(float); ++i) all[i] = 0.f;
    }
};

// A mask lane's float (all bits set: true), and whether lane k of a mask array is set.
inline float lane_mask(bool b) {
    float f;
    const uint32_t bits = b ? ~0u : 0u;
    std::memcpy(&f, &bits, sizeof f);
    return f;
}
inline bool lane_set(const float* mask, int k) {
    uint32_t bits;
    std::memcpy(&bits, mask + k, sizeof bits);
    return bits != 0;
}

namespace lanes {

template <int N>
inline V4 load3(const float (&a)[3][N], int k) {
    return {F4::load(a[0] + k), F4::load(a[1] + k), F4::load(a[2] + k)};
}
template <int N>
inline void store3(float (&a)[3][N], int k, const V4& v) {
    v.x.store(a[0] + k);
    v.y.store(a[1] + k);
    v.z.store(a[2] + k);
}

// offset_ray_origin (math/ray.h).
inline V4 offset_ray_origin(const V4& p, const V4& p_error, const V4& n, const V4& w) {
    const F4 d = abs(n.x) * p_error.x + abs(n.y) * p_error.y + abs(n.z) * p_error.z;
    const V4 offset = n * select(dot(w, n) < F4(0.f), -d, d);
    const V4 o = p + offset;
    auto step = [](F4 off, F4 c) {
        return select(off > F4(0.f), next_float_up(c), select(off < F4(0.f), next_float_down(c), c));
    };
    return {step(offset.x, o.x), step(offset.y, o.y), step(offset.z, o.z)};
}

// The Lambertian lobe's f cos (bsdf_eval) and density (bsdf_pdf) for wi, with the two-sided
// material's mirroring (orient); `flip`: two-sided and wo below the surface.
inline void lambert(M4 flip, F4 wo_z, F4 wi_z, const V4& diffuse, V4& f, F4& pdf) {
    const F4 oz = select(flip, -wo_z, wo_z), iz = select(flip, -wi_z, wi_z);
    const M4 up = (oz > F4(0.f)) & (iz > F4(0.f));
    f = select(up, diffuse * (iz * F4(kInvPi)), V4(F4(0.f)));
    // (1 - ps) cos / pi with the specular lobe's probability ps = 0.
    pdf = select(up, F4(1.f) * iz * F4(kInvPi), F4(0.f));
}

inline F4 mis_power(F4 a, F4 b) {
    a = a * a;
    b = b * b;
    return select(a > F4(0.f), a / (a + b), F4(0.f));
}

}  // namespace lanes

// Lanes [0, n) of L (n rounded up to whole vectors; the lanes past n are computed and ignored).
template <int N>
inline void shade_lanes(ShadeLanes<N>& L, int n, bool mis) {
    using namespace lanes;
    const F4 zero(0.f), one(1.f);
    // square_to_disk (sampling/warp.h): the radius and angle, their cosine and sine, the point.
    alignas(16) float radius[N], angle[N], cosine[N], sine[N];
    for (int k = 0; k < n; k += 4) {
        const F4 a = F4(2.f) * F4::load(L.disk[0] + k) - one, b = F4(2.f) * F4::load(L.disk[1] + k) - one;
        const M4 wide = abs(a) > abs(b);
        select(wide, a, b).store(radius + k);
        select(wide, F4(kPi / 4.f) * (b / a), F4(kPi / 2.f) - F4(kPi / 4.f) * (a / b)).store(angle + k);
    }
    for (int k = 0; k < n; ++k) {
        cosine[k] = std::cos(angle[k]);
        sine[k] = std::sin(angle[k]);
    }
    for (int k = 0; k < n; k += 4) {
        const F4 a = F4(2.f) * F4::load(L.disk[0] + k) - one, b = F4(2.f) * F4::load(L.disk[1] + k) - one;
        const M4 centre = (a == zero) & (b == zero);
        const F4 r = F4::load(radius + k);
        select(centre, zero, r * F4::load(cosine + k)).store(L.disk[0] + k);
        select(centre, zero, r * F4::load(sine + k)).store(L.disk[1] + k);
    }
    for (int k = 0; k < n; k += 4) {
        const V4 p = load3(L.p, k), p_error = load3(L.p_error, k), ng = load3(L.ng, k);
        const V4 dir = load3(L.dir, k), beta = load3(L.beta, k), diffuse = load3(L.diffuse, k);
        const V4 wo_world = -dir;

        // bend_normal (scene/bsdf_diff.h).
        const V4 ns0 = load3(L.ns, k);
        const F4 s = select(dot(wo_world, ng) < zero, F4(-1.f), one), d = dot(wo_world, ns0);
        const M4 keep = s * d >= F4(kMinShadingCosine);
        const V4 ns = select(keep, ns0, normalize(ns0 + wo_world * (s * F4(kMinShadingCosine) - d)));
        store3(L.ns, k, ns);

        // Frame (math/frame.h) and wo.
        const F4 sign = sign_of(ns.z);
        const F4 a = F4(-1.f) / (sign + ns.z);
        const F4 b = ns.x * ns.y * a;
        const V4 fs(one + sign * ns.x * ns.x * a, sign * b, -sign * ns.x);
        const V4 ft(b, sign + ns.y * ns.y * a, -ns.y);
        auto to_local = [&](const V4& v) { return V4(dot(v, fs), dot(v, ft), dot(v, ns)); };
        const V4 wo = to_local(wo_world);
        const M4 flip = M4::load(L.two_sided + k) & (wo.z < zero);

        // bsdf_sample: the cosine-weighted hemisphere, mirrored for a two-sided material seen
        // from below.
        {
            const F4 wo_z = select(flip, -wo.z, wo.z);
            const F4 dx = F4::load(L.disk[0] + k), dy = F4::load(L.disk[1] + k);
            const F4 z = sqrt(max_std(zero, one - dx * dx - dy * dy));
            const F4 pdf = one * z * F4(kInvPi);
            const M4 ok = M4::load(L.reflects + k) & !(wo_z <= zero) & !(z <= zero) & (pdf > zero);
            const V4 wi(dx, dy, select(flip, -z, z));
            V4 f;
            F4 unused;
            lambert(flip, wo.z, wi.z, diffuse, f, unused);
            const V4 nb = select(ok, beta * (f / pdf), V4(zero));
            const M4 goes_on = ok & !is_black(nb);
            goes_on.store(L.goes_on + k);
            store3(L.next_beta, k, nb);
            pdf.store(L.next_pdf + k);
            const V4 w = fs * wi.x + ft * wi.y + ns * wi.z;
            store3(L.next_dir, k, w);
            store3(L.next_origin, k, offset_ray_origin(p, p_error, ng, w));
        }

        // One light sample's value and MIS weight (next_event in shade_vertex): `on` cleared
        // where the BSDF is black towards it.
        auto next_event = [&](const V4& ldir, F4 lpdf, const V4& radiance, M4& on) {
            const V4 wi = to_local(ldir);
            V4 f;
            F4 bpdf;
            lambert(flip, wo.z, wi.z, diffuse, f, bpdf);
            on = on & !is_black(f);
            const F4 w = mis ? mis_power(lpdf, bpdf) : one;
            return beta * f * radiance * (w / lpdf);
        };

        // The area light's sample (Scene::sample_light_triangle, by area, or the one given)
        // and its shadow ray (spawn_ray_to), where any of the four has one.
        if (M4::load(L.light_on + k).bits() != 0) {
            const M4 light_on = M4::load(L.light_on + k), given = M4::load(L.light_given + k);
            M4 on = light_on;
            const F4 b1 = F4::load(L.b1 + k), b2 = F4::load(L.b2 + k), b0 = one - b1 - b2;
            const V4 v0 = load3(L.v0, k), v1 = load3(L.v1, k), v2 = load3(L.v2, k);
            const V4 qng = select(given, load3(L.given_ng, k), load3(L.light_ng, k));
            const V4 q = select(given, load3(L.given_p, k), v0 * b0 + v1 * b1 + v2 * b2);
            auto abs3 = [](const V4& v) { return V4(abs(v.x), abs(v.y), abs(v.z)); };
            const V4 q_error = select(given, load3(L.given_p_error, k),
                                      (abs3(v0 * b0) + abs3(v1 * b1) + abs3(v2 * b2)) * F4(rounding_gamma(7)) +
                                          V4(F4::load(L.edge + k) * F4(rounding_gamma(4))));
            V4 to = q - p;
            const F4 dist2 = dot(to, to);
            on = on & (dist2 > zero);
            const F4 dist = sqrt(dist2);
            to = to / dist;
            const F4 cos_l = abs(dot(qng, to));
            on = on & (cos_l > zero);
            // Scene::emitted: the side of the face normal only, unless two-sided.
            const M4 front = !(dot(qng, -to) <= zero);
            on = on & (M4::load(L.two_sided_emission + k) | front);
            V4 radiance = load3(L.emission, k) * one;
            on = on & !is_black(radiance);
            F4 lpdf = F4::load(L.pmf + k) / F4::load(L.area + k) * dist2 / cos_l;
            on = on & (lpdf > zero) & is_finite(lpdf);
            // The given samples: their own (gathered only where sample_area_light succeeded).
            on = select(given, light_on, on);
            to = select(given, load3(L.given_dir, k), to);
            lpdf = select(given, F4::load(L.given_pdf + k), lpdf);
            radiance = select(given, load3(L.given_radiance, k), radiance);
            const V4 value = next_event(to, lpdf, radiance, on);
            on.store(L.light_on + k);
            store3(L.light_value, k, value);
            const V4 origin = offset_ray_origin(p, p_error, ng, q - p);
            const V4 target = offset_ray_origin(q, q_error, qng, origin - q);
            const V4 span = target - origin;
            const F4 len = length(span);
            store3(L.light_origin, k, origin);
            store3(L.light_dir, k, select(len > zero, span / len, normalize(q - p)));
            (len * F4(1.f - kShadowEpsilon)).store(L.light_tmax + k);
        }

        // The environment's sample and its shadow ray (spawn_ray), where any of the four has one.
        if (M4::load(L.env_on + k).bits() != 0) {
            M4 on = M4::load(L.env_on + k);
            const V4 ldir = load3(L.env_dir, k);
            const V4 value = next_event(ldir, F4::load(L.env_pdf + k), load3(L.env_radiance, k), on);
            on.store(L.env_on + k);
            store3(L.env_value, k, value);
            store3(L.env_origin, k, offset_ray_origin(p, p_error, ng, ldir));
        }
    }
}

}  // namespace edgepath
