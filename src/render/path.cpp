#include "render/path.h"

#include "scene/bsdf_diff.h"

namespace edgepath {

Vec3f trace_path(const Scene& scene, const RenderOptions& opt, Ray ray, Rng& rng, RayCounters& counters,
                 PathRecord* record, const FirstHit* first) {
    const bool use_nee = opt.sampling != LightSampling::BSDFOnly && scene.has_lights();
    const bool use_hits = opt.sampling != LightSampling::LightOnly;
    const bool mis = opt.sampling == LightSampling::MIS;
    const bool both_lights = scene.light_distribution.valid() && scene.env_sampled;

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
        traced = first_hit(scene, ray, opt.hide_emitters);
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
        BsdfParams bp = scene.bsdf_params(sp);
        sp.ns = bend_normal(sp.ns, sp.ng, -ray.dir);
        Frame frame(sp.ns);
        Vec3f wo = frame.to_local(-ray.dir);

        // Next-event estimation: one sample on the area lights and one on the environment
        // (the latter's two random numbers are drawn only when the scene has both).
        float ul0 = rng.next_float(), ul1 = rng.next_float(), ul2 = rng.next_float();
        float ue1 = ul1, ue2 = ul2;
        if (both_lights) {
            ue1 = rng.next_float();
            ue2 = rng.next_float();
        }
        // BSDF sampling. Its ray is traced before the shadow rays, and the surface it meets
        // fetched while they are: they do not depend on it, and the memory latency of a random
        // triangle's data is hidden behind their traversal.
        float ub0 = rng.next_float(), ub1 = rng.next_float(), ub2 = rng.next_float();
        BsdfSample bs;
        Vec3f next_beta(0.f);
        if (bsdf_sample(bp, wo, ub0, ub1, ub2, bs)) next_beta = beta * (bs.delta ? bs.weight : bsdf_eval(bp, wo, bs.wi) / bs.pdf);
        const bool goes_on = !is_black(next_beta);
        Vec3f dir;
        Ray next_ray;
        Hit next_hit;
        bool found = false;
        if (goes_on) {
            dir = frame.to_world(bs.wi);
            next_ray = spawn_ray(sp, dir);
            ++counters.bounce;
            found = scene.intersect(next_ray, next_hit);
            if (found) scene.prefetch(next_hit);
        }

        auto next_event = [&](const LightSample& ls, NeeRecord* nr) {
            Vec3f wi = frame.to_local(ls.dir);
            Vec3f f = bsdf_eval(bp, wo, wi);
            if (is_black(f)) return;
            Ray shadow = shadow_ray(sp, ls);
            ++counters.shadow;
            if (scene.occluded(shadow)) return;
            float w = mis ? mis_power(ls.pdf, bsdf_pdf(bp, wo, wi)) : 1.f;
            L += beta * f * ls.radiance * (w / ls.pdf);
            if (nr) {
                nr->used = true;
                nr->dir = ls.dir;
                nr->scale = w / ls.pdf;
                nr->hit = ls.hit;
            }
        };
        // A smooth material reflects light from one direction only: nothing to sample.
        const bool nee_here = use_nee && !is_delta(bp);
        LightSample ls;
        if (nee_here && scene.sample_area_light(sp.p, ul0, ul1, ul2, ls)) next_event(ls, rv ? &rv->nee_area : nullptr);
        if (nee_here && scene.sample_env(ue1, ue2, ls)) next_event(ls, rv ? &rv->nee_env : nullptr);
        // Point lights, each at every vertex, whatever the sampling strategy: no other way
        // finds them. Their contribution f I s(-w) / r^2 has no random numbers.
        if (rv) rv->point_lights = !is_delta(bp);
        if (!is_delta(bp))
            for (const PointLightDesc& pl : scene.point_lights) {
                Vec3f wl;
                float dist2;
                if (!see_point_light(scene, sp, pl, wl, dist2, &counters)) continue;
                const float s = Scene::spot_scale(pl.spot, pl.spot_profile, -wl);
                L += beta * bsdf_eval(bp, wo, frame.to_local(wl)) * Vec3f::load(pl.intensity) * (s / dist2);
            }

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
        // Light met after a smooth bounce could not have been sampled: full weight, whatever
        // the sampling strategy.
        const bool counted = use_hits || bs.delta;
        const bool weighted = mis && use_nee && !bs.delta;
        ray = next_ray;
        hit = next_hit;
        if (!found) {
            if (scene.has_envmap && counted) {
                // The value and, for the weight, the density (as scene.env_pdf gives it) from
                // one lookup of the direction.
                float env_pdf = 0.f;
                const Vec3f Le = weighted && scene.env_sampled ? scene.envmap.eval(dir, env_pdf) : scene.envmap.eval(dir);
                float w = weighted ? mis_power(bs.pdf, env_pdf) : 1.f;
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
        if (counted && scene.meshes[size_t(hit.mesh)].is_emitter()) {
            Vec3f Le = scene.emitted(sp, -dir);
            if (!is_black(Le)) {
                emission_weight = weighted ? mis_power(bs.pdf, scene.light_pdf(prev_p, sp)) : 1.f;
                L += beta * Le * emission_weight;
            }
        }
        push_vertex(ray, emission_weight);
    }
    return L;
}

}  // namespace edgepath
