#include "render/path.h"

#include "scene/bsdf_diff.h"

namespace edgepath {

Vec3f trace_path(const Scene& scene, const RenderOptions& opt, Ray ray, Rng& rng, RayCounters& counters,
                 PathRecord* record, const FirstHit* first) {
    const PathSettings settings(scene, opt, record != nullptr);

    Vec3f L(0.f), beta(1.f);
    ++counters.camera;
    Hit hit;
    if (record) {
        record->vertices.clear();
        record->camera_missed = record->escaped = false;
        record->emitters_hidden = opt.hide_emitters;
    }
    FirstHit traced;
    if (!first) {
        traced = first_hit(scene, ray, opt.hide_emitters, settings.tracing);
        first = &traced;
    }
    if (!first->found) {
        if (scene.has_envmap && !opt.hide_emitters) L += scene.envmap.eval(ray.dir);
        if (record) record->camera_missed = true;
        return L;
    }
    hit = first->hit;
    // A vertex's surface point serves its emission and, when the path goes on, its scattering:
    // where neither is needed (a path's last vertex on a surface that does not emit) it is not
    // computed (its triangle's data are often not in cache).
    auto needs_point = [&](const Hit& h, int bounce) {
        return bounce < opt.max_bounces || scene.meshes[size_t(h.mesh)].is_emitter();
    };
    SurfacePoint sp;
    if (needs_point(hit, 0)) sp = scene.surface_point(hit);
    if (!opt.hide_emitters && scene.meshes[size_t(hit.mesh)].is_emitter()) L += scene.emitted(sp, -ray.dir);
    PathVertexRecord* rv = nullptr;
    auto push_vertex = [&](const Ray& r, float emission_weight) {
        if (!record) return;
        record->vertices.emplace_back();
        rv = &record->vertices.back();
        rv->hit = hit;
        rv->origin = r.origin;
        rv->dir = r.dir;
        rv->beta = beta;
        rv->emission_weight = emission_weight;
    };
    push_vertex(ray, opt.hide_emitters ? 0.f : 1.f);

    for (int bounce = 0; bounce < opt.max_bounces; ++bounce) {
        // The continuation is traced before the shadow rays, and the surface it meets fetched
        // while they are: they do not depend on it, and the memory latency of a random
        // triangle's data is hidden behind their traversal.
        bool goes_on = false, found = false;
        BsdfSample bs;
        Vec3f next_beta, dir;
        Ray next_ray;
        Hit next_hit;
        auto on_next = [&](const Ray& r, const BsdfSample& s, const Vec3f& nb) {
            goes_on = true;
            bs = s;
            next_beta = nb;
            next_ray = r;
            dir = r.dir;
            found = scene.intersect(next_ray, next_hit, settings.tracing);
            if (found) scene.prefetch(next_hit);
        };
        auto on_shadow = [&](ShadowKind kind, const Ray& shadow, const Vec3f& value, const LightSample* ls, float scale) {
            if (scene.occluded(shadow, settings.tracing)) return;
            L += value;
            if (!rv || kind == ShadowKind::Point) return;
            NeeRecord* nr = kind == ShadowKind::Area ? &rv->nee_area : &rv->nee_env;
            nr->used = true;
            nr->dir = ls->dir;
            nr->scale = scale;
            nr->hit = ls->hit;
        };
        const bool delta = shade_vertex(scene, settings, sp, ray.dir, beta, rng, counters, on_next, on_shadow);
        if (rv) rv->point_lights = !delta;

        // The continuation.
        if (!goes_on) break;
        beta = next_beta;
        Vec3f prev_p = sp.p;
        if (rv) {
            rv->next = true;
            rv->next_delta = bs.delta;
            rv->next_refract = bs.refract;
            rv->next_dir = dir;
            rv->next_inv_pdf = 1.f / bs.pdf;
        }
        ray = next_ray;
        hit = next_hit;
        Vec3f Le;
        float w;
        if (!found) {
            if (escaped_light(scene, settings, dir, bs.pdf, bs.delta, Le, w)) {
                L += beta * Le * w;
                if (record) {
                    record->escaped = true;
                    record->escape_weight = w;
                }
            }
            break;
        }
        if (needs_point(hit, bounce + 1)) sp = scene.surface_point(hit);
        float emission_weight = 0.f;
        if (met_emission(scene, settings, hit.mesh, prev_p, sp, dir, bs.pdf, bs.delta, Le, w)) {
            emission_weight = w;
            L += beta * Le * w;
        }
        push_vertex(ray, emission_weight);
    }
    return L;
}

}  // namespace edgepath
