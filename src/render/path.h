// The path tracer: one camera sample's radiance, with next-event estimation on area lights and
// the environment combined with BSDF sampling by multiple importance sampling.
#pragma once
#include <algorithm>
#include <cmath>
#include "sampling/rng.h"
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

// With `hide_emitters`, area lights are transparent to the camera ray (Mitsuba's
// hide_emitters skips them): the first intersection past them, its t along the same ray.
inline FirstHit first_hit(const Scene& scene, const Ray& ray, bool hide_emitters = false) {
    FirstHit f;
    f.found = scene.intersect(ray, f.hit);
    Ray past = ray;
    while (hide_emitters && f.found && scene.meshes[size_t(f.hit.mesh)].is_emitter()) {
        past.tmin = std::max(std::nextafter(f.hit.t, INFINITY), f.hit.t * (1.f + kHiddenEmitterSkip));
        f.found = scene.intersect(past, f.hit);
    }
    return f;
}

// Whether two rays meet the same triangle, or both leave the scene (the two sides of an edge
// sample that sees no discontinuity).
inline bool same_surface(const FirstHit& a, const FirstHit& b) {
    return a.found == b.found && (!a.found || (a.hit.mesh == b.hit.mesh && a.hit.prim == b.hit.prim));
}

// Point light `light` seen from sp: the unit direction towards it, the squared distance, and
// whether it lights sp (in front of it, within its spot profile, nothing in between).
// `counters` counts the shadow ray, if one is traced.
inline bool see_point_light(const Scene& scene, const SurfacePoint& sp, const PointLightDesc& light, Vec3f& dir,
                            float& dist2, RayCounters* counters = nullptr) {
    const Vec3f to = Vec3f::load(light.position) - sp.p;
    dist2 = length_squared(to);
    if (!(dist2 > 0.f)) return false;
    const float dist = std::sqrt(dist2);
    dir = to / dist;
    if (!(Scene::spot_scale(light.spot, light.spot_profile, -dir) > 0.f)) return false;
    Ray shadow = spawn_ray(sp, dir);
    shadow.tmax = length(Vec3f::load(light.position) - shadow.origin) * (1.f - kShadowEpsilon);
    if (counters) ++counters->shadow;
    return !scene.occluded(shadow);
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
