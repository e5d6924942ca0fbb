// The path tracer: one camera sample's radiance, with next-event estimation on area lights and
// the environment combined with BSDF sampling by multiple importance sampling.
#pragma once
#include <algorithm>
#include <cmath>
#include "sampling/rng.h"
#include "sampling/warp.h"
#include "scene/bsdf_diff.h"
#include "scene/desc.h"
#include "scene/scene.h"

namespace edgepath {

struct RayCounters {
    uint64_t camera = 0, shadow = 0, bounce = 0;
};

// One next-event estimate at a path vertex (recorded only when it contributed).
struct NeeRecord {
    bool used = false;
    Vec3f dir;          // towards the light
    float scale = 0.f;  // MIS weight / pdf
    Hit hit;            // the point on the light (area lights)
};

// What the gradient pass needs to replay one path: its vertices with the fixed directions and
// the constant factors (1 / pdf, MIS weights) chosen when it was traced.
struct PathVertexRecord {
    Hit hit;
    Vec3f origin, dir;            // the ray that found this vertex
    Vec3f beta;                   // throughput of the path up to this vertex
    float emission_weight = 0.f;  // MIS weight of the emission seen here (0: not counted)
    // Next-event estimation at this vertex: one sample on the area lights, one on the
    // environment.
    NeeRecord nee_area, nee_env;
    bool point_lights = false;  // the point lights were sampled here (a vertex that scatters)
    // Continuation by BSDF sampling. A smooth material's (next_delta) direction is a function
    // of the vertex, and next_inv_pdf the inverse probability of its lobe (next_refract: the
    // dielectric's transmission).
    bool next = false;
    bool next_delta = false, next_refract = false;
    Vec3f next_dir;
    float next_inv_pdf = 0.f;
};

struct PathRecord {
    Vec2f film;
    Vec2f lens{kLensCentre, kLensCentre};  // the thin lens's sample
    uint64_t stream = 0;         // seeds the random numbers the gradient pass adds to this path
    bool camera_missed = false;  // the camera ray left the scene
    bool emitters_hidden = false;  // RenderOptions::hide_emitters: the first hit's emission not counted
    bool escaped = false;        // the last continuation left the scene
    float escape_weight = 0.f;   // MIS weight of the environment seen by that continuation
    std::vector<PathVertexRecord> vertices;
};

// The camera ray's first intersection, when the caller has it already.
struct FirstHit {
    bool found = false;
    Hit hit;
};

// How far past a hidden emitter (relative to the distance along the ray) the camera ray
// resumes: a surface closer behind it than this is skipped with it.
constexpr float kHiddenEmitterSkip = 1e-5f;

// The BVH the paths of a pass trace (scene.h, Tracing): the fast one for an image no gradient
// pass retraces (RenderOptions::replayable false), the exact one for the rest, and for the
// paths recorded for the adjoint sweep (`recorded`) whatever the options.
inline Tracing tracing_of(const RenderOptions& opt, bool recorded = false) {
    return recorded || opt.replayable ? Tracing::Exact : Tracing::Fast;
}

// With `hide_emitters`, area lights are transparent to the camera ray (Mitsuba's
// hide_emitters skips them): the first intersection past them, its t along the same ray.
inline FirstHit first_hit(const Scene& scene, const Ray& ray, bool hide_emitters = false,
                          Tracing tracing = Tracing::Exact) {
    FirstHit f;
    f.found = scene.intersect(ray, f.hit, tracing);
    Ray past = ray;
    while (hide_emitters && f.found && scene.meshes[size_t(f.hit.mesh)].is_emitter()) {
        past.tmin = std::max(std::nextafter(f.hit.t, INFINITY), f.hit.t * (1.f + kHiddenEmitterSkip));
        f.found = scene.intersect(past, f.hit, tracing);
    }
    return f;
}

// Whether two rays meet the same triangle, or both leave the scene (the two sides of an edge
// sample that sees no discontinuity).
inline bool same_surface(const FirstHit& a, const FirstHit& b) {
    return a.found == b.found && (!a.found || (a.hit.mesh == b.hit.mesh && a.hit.prim == b.hit.prim));
}

// Point light `light` seen from sp: the unit direction towards it, the squared distance and the
// shadow ray towards it; false if it cannot light sp (at sp, or sp outside its spot profile):
// then no ray.
inline bool point_light_ray(const SurfacePoint& sp, const PointLightDesc& light, Vec3f& dir, float& dist2,
                            Ray& shadow) {
    const Vec3f to = Vec3f::load(light.position) - sp.p;
    dist2 = length_squared(to);
    if (!(dist2 > 0.f)) return false;
    const float dist = std::sqrt(dist2);
    dir = to / dist;
    if (!(Scene::spot_scale(light.spot, light.spot_profile, -dir) > 0.f)) return false;
    shadow = spawn_ray(sp, dir);
    shadow.tmax = length(Vec3f::load(light.position) - shadow.origin) * (1.f - kShadowEpsilon);
    return true;
}

// The same, and whether it lights sp (in front of it, within its spot profile, nothing in
// between). `counters` counts the shadow ray, if one is traced.
inline bool see_point_light(const Scene& scene, const SurfacePoint& sp, const PointLightDesc& light, Vec3f& dir,
                            float& dist2, RayCounters* counters = nullptr) {
    Ray shadow;
    if (!point_light_ray(sp, light, dir, dist2, shadow)) return false;
    if (counters) ++counters->shadow;
    return !scene.occluded(shadow);
}

// Whether the vertices sample the environment (next-event estimation) under these options, and
// by which distribution (`compensated`: Envmap::compensated()). When the strategies are combined
// the BSDF's samples, drawn in proportion to the lobe (and traced anyway for the path's next
// bounce), find the environment's light too, and find it well where it is no brighter than its
// mean: an image that no gradient pass retraces (RenderOptions::replayable false) samples only
// the light above the mean ("MIS compensation"), and a constant environment not at all (better
// than a uniform sample, half of whose directions lie below the surface), its escaping BSDF
// samples counting at full weight. That saves a shadow ray a vertex under a uniform sky, and
// lowers the image's variance. The paths recorded for the adjoint sweep (`recorded`) sample
// the environment by its whole radiance: the sweep differentiates a BSDF sample's value over
// its density with the density held, and for a cosine-weighted sample that derivative grows as
// 1 / cos towards grazing directions (its variance is infinite), where a light sample's density
// does not depend on the surface (on a smooth-shaded sphere under a uniform sky, the derivative
// image with respect to the camera's position had 3.9 times the variance with the sky left to
// the BSDF). So do the images a gradient pass may retrace, to have its paths, and light-only
// sampling, which has nothing else to find the environment with.
inline bool env_nee(const Scene& scene, const RenderOptions& opt, bool recorded, bool& compensated) {
    compensated = false;
    if (!scene.env_sampled || opt.sampling == LightSampling::BSDFOnly) return false;
    if (recorded || opt.replayable || opt.sampling != LightSampling::MIS) return true;
    compensated = true;
    return scene.envmap.compensated().valid();
}

// What the path tracer does with the options, once for all its paths (`recorded`: paths
// recorded for the adjoint sweep).
struct PathSettings {
    bool env_compensated, use_env, use_nee, use_hits, mis, both_lights;
    Tracing tracing;
    PathSettings(const Scene& scene, const RenderOptions& opt, bool recorded = false)
        : env_compensated(false),
          use_env(env_nee(scene, opt, recorded, env_compensated)),
          use_nee(opt.sampling != LightSampling::BSDFOnly && (scene.light_distribution.valid() || use_env)),
          use_hits(opt.sampling != LightSampling::LightOnly),
          mis(opt.sampling == LightSampling::MIS),
          both_lights(scene.light_distribution.valid() && use_env),
          tracing(tracing_of(opt, recorded)) {}
};

// Light met by a BSDF-sampled continuation (of density `pdf`, smooth if `delta`), as trace_path
// and PathBatch both count it: the two functions below return whether it counts, and then set
// Le to the light, unweighted, and w to its MIS weight (the caller adds beta * Le * w). Light
// met after a smooth bounce could not have been sampled: full weight, whatever the sampling
// strategy.
inline bool continuation_counts(const PathSettings& ps, bool delta) { return ps.use_hits || delta; }
inline bool continuation_weighted(const PathSettings& ps, bool delta) { return ps.mis && ps.use_nee && !delta; }

// The environment seen along `dir` by a continuation that left the scene: its value and, for
// the weight, its density (as the vertices' sample_env gives it) from one lookup of the
// direction.
inline bool escaped_light(const Scene& scene, const PathSettings& ps, const Vec3f& dir, float pdf, bool delta,
                          Vec3f& Le, float& w) {
    if (!scene.has_envmap || !continuation_counts(ps, delta)) return false;
    const bool weighted = continuation_weighted(ps, delta);
    float env_pdf = 0.f;
    Le = weighted && ps.use_env ? scene.envmap.eval(dir, env_pdf, ps.env_compensated) : scene.envmap.eval(dir);
    w = weighted ? mis_power(pdf, env_pdf) : 1.f;
    return true;
}

// The emission of sp, a point of mesh `mesh`, met along `dir` by a continuation from prev_p
// (counted where it is not black).
inline bool met_emission(const Scene& scene, const PathSettings& ps, int mesh, const Vec3f& prev_p,
                         const SurfacePoint& sp, const Vec3f& dir, float pdf, bool delta, Vec3f& Le, float& w) {
    if (!continuation_counts(ps, delta) || !scene.meshes[size_t(mesh)].is_emitter()) return false;
    Le = scene.emitted(sp, -dir);
    if (is_black(Le)) return false;
    w = continuation_weighted(ps, delta) ? mis_power(pdf, scene.light_pdf(prev_p, sp)) : 1.f;
    return true;
}

// The light sample a shadow ray of shade_vertex tests.
enum class ShadowKind { Area, Env, Point };

// Point lights, each at every vertex that is not smooth, whatever the sampling strategy: no
// other way finds them. Their contribution f I s(-w) / r^2 has no random numbers. For each that
// can light sp, calls on_shadow as shade_vertex does (below); bp, frame and wo are sp's.
template <class OnShadow>
inline void point_light_samples(const Scene& scene, const SurfacePoint& sp, const BsdfParams& bp, const Frame& frame,
                                const Vec3f& wo, const Vec3f& beta, RayCounters& counters, OnShadow&& on_shadow) {
    for (const PointLightDesc& pl : scene.point_lights) {
        Vec3f wl;
        float dist2;
        Ray shadow;
        if (!point_light_ray(sp, pl, wl, dist2, shadow)) continue;
        const float s = Scene::spot_scale(pl.spot, pl.spot_profile, -wl);
        ++counters.shadow;
        on_shadow(ShadowKind::Point, shadow,
                  beta * bsdf_eval(bp, wo, frame.to_local(wl)) * Vec3f::load(pl.intensity) * (s / dist2), nullptr, 0.f);
    }
}

// The world direction of a BSDF sample `bs` (local to `frame`) at a point of geometric normal ng
// reached along `dir`: a smooth lobe's kept on its side of the face (delta_side,
// scene/specular.h).
inline Vec3f continuation_dir(const Frame& frame, const Vec3f& ng, const Vec3f& dir, const BsdfSample& bs) {
    const Vec3f w = frame.to_world(bs.wi);
    return bs.delta ? delta_side(w, ng, delta_side_sign(-dir, ng, bs.refract)) : w;
}

// The scattering at a path's vertex sp, reached by a ray along `dir` with throughput `beta`, as
// trace_path and PathBatch (render/batch.h) both do it: bends sp's shading normal, draws the
// vertex's random numbers from `rng`, samples the BSDF and, if the path goes on, calls
// on_next(ray, bs, next_beta) with the continuation's ray; then, for each light sample that sp
// would see (one on the area lights, one on the environment, every point light), calls
// on_shadow(kind, ray, value, ls, scale): `value` is what it adds to the radiance if nothing
// hides it, `ls` the sample (null for a point light) and `scale` its MIS weight / pdf. Counts
// the rays. Returns whether the BSDF is smooth (nothing sampled towards the lights).
template <class OnNext, class OnShadow>
inline bool shade_vertex(const Scene& scene, const PathSettings& ps, SurfacePoint& sp, const Vec3f& dir,
                         const Vec3f& beta, Rng& rng, RayCounters& counters, OnNext&& on_next, OnShadow&& on_shadow) {
    const BsdfParams bp = scene.bsdf_params(sp);
    sp.ns = bend_normal(sp.ns, sp.ng, -dir);
    const Frame frame(sp.ns);
    const Vec3f wo = frame.to_local(-dir);

    // Next-event estimation: one sample on the area lights and one on the environment (the
    // latter's two random numbers are drawn only when the scene has both).
    const float ul0 = rng.next_float(), ul1 = rng.next_float(), ul2 = rng.next_float();
    float ue1 = ul1, ue2 = ul2;
    if (ps.both_lights) {
        ue1 = rng.next_float();
        ue2 = rng.next_float();
    }
    // BSDF sampling: its ray is handed on first (trace_path traces it before the shadow rays).
    const float ub0 = rng.next_float(), ub1 = rng.next_float(), ub2 = rng.next_float();
    BsdfSample bs;
    Vec3f next_beta(0.f);
    if (bsdf_sample(bp, wo, ub0, ub1, ub2, bs)) next_beta = beta * (bs.delta ? bs.weight : bsdf_eval(bp, wo, bs.wi) / bs.pdf);
    if (!is_black(next_beta)) {
        ++counters.bounce;
        on_next(spawn_ray(sp, continuation_dir(frame, sp.ng, dir, bs)), bs, next_beta);
    }

    // A smooth material reflects light from one direction only: nothing to sample.
    const bool delta = is_delta(bp);
    auto next_event = [&](ShadowKind kind, const LightSample& ls) {
        const Vec3f wi = frame.to_local(ls.dir);
        const Vec3f f = bsdf_eval(bp, wo, wi);
        if (is_black(f)) return;
        const float w = ps.mis ? mis_power(ls.pdf, bsdf_pdf(bp, wo, wi)) : 1.f;
        ++counters.shadow;
        on_shadow(kind, shadow_ray(sp, ls), beta * f * ls.radiance * (w / ls.pdf), &ls, w / ls.pdf);
    };
    const bool nee_here = ps.use_nee && !delta;
    LightSample ls;
    if (nee_here && scene.sample_area_light(sp.p, ul0, ul1, ul2, ls)) next_event(ShadowKind::Area, ls);
    if (nee_here && ps.use_env && scene.sample_env(ue1, ue2, ls, ps.env_compensated)) next_event(ShadowKind::Env, ls);
    if (!delta) point_light_samples(scene, sp, bp, frame, wo, beta, counters, on_shadow);
    return delta;
}

// Radiance arriving along `ray` (a camera ray). Consumes random numbers from `rng`. When
// `record` is given, also records the path for the gradient pass; when `first` is given, it is
// the ray's intersection (not traced again), found by first_hit with opt.hide_emitters.
Vec3f trace_path(const Scene& scene, const RenderOptions& opt, Ray ray, Rng& rng, RayCounters& counters,
                 PathRecord* record = nullptr, const FirstHit* first = nullptr);

// A film point in film pixel (x, y), drawn from the pixel filter with the next two numbers of `rng`.
inline Vec2f sample_film_point(const Scene& scene, int x, int y, Rng& rng) {
    float fx = scene.filter.sample(rng.next_float());
    float fy = scene.filter.sample(rng.next_float());
    return {float(x) + 0.5f + fx, float(y) + 0.5f + fy};
}

// A thin lens camera's lens sample, the next two numbers of `rng`; the aperture's centre (and no
// numbers drawn) for the other cameras.
inline Vec2f sample_lens_point(const Scene& scene, Rng& rng) {
    if (scene.camera.type != CameraType::ThinLens) return {kLensCentre, kLensCentre};
    const float u = rng.next_float();
    return {u, rng.next_float()};
}

}  // namespace edgepath
