#include "diff/backprop.h"

#include <algorithm>

#include "math/vec_diff.h"
#include "edges/secondary.h"
#include "scene/bsdf_diff.h"
#include "scene/geometry.h"
#include "scene/normal_map.h"
#include "scene/specular.h"

namespace edgepath {

namespace {
const GradSlot kNoSlot{};
}  // namespace

void d_texture(const Texture& tex, const GradSlot& slot, Vec2f uv, const float* dval, GradSink& sink, Vec2f* duv) {
    if (tex.is_constant()) {
        if (slot.wanted())
            for (int c = 0; c < tex.channels; ++c) sink.add(slot, c, dval[c]);
        return;
    }
    TexelFootprint f = bilinear_footprint(tex, uv);
    for (int k = 0; k < 4; ++k)
        for (int c = 0; c < tex.channels; ++c) {
            if (slot.wanted()) sink.add(slot, f.texel[k] * tex.channels + c, f.weight[k] * dval[c]);
            if (duv) {
                float t = tex.data[f.texel[k] * tex.channels + c] * dval[c];
                duv->x += f.dweight_du[k] * t;
                duv->y += f.dweight_dv[k] * t;
            }
        }
}

namespace {

// Adjoint of Envmap::eval: texels and rotation into their slots; returns d L / d world
// direction (the caller decides whether the direction moves).
Vec3f d_envmap(const Envmap& env, const SceneGradients& slots, const Vec3f& dir, const Vec3f& dL, GradSink& sink) {
    Envmap::Footprint f = env.footprint(dir);
    const Vec3f dLs = dL * env.scale;
    Vec3f d_local(0.f);
    for (int k = 0; k < 4; ++k) {
        if (slots.envmap.wanted()) sink.add3(slots.envmap, f.texel[k], dLs.x * f.weight[k], dLs.y * f.weight[k], dLs.z * f.weight[k]);
        d_local += f.dweight[k] * dot(dLs, env.texel(f.texel[k]));
    }
    // local = R^T world: d local_i / d R_ji = world_j; d local / d world = R^T.
    if (slots.envmap_rotation.wanted())
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) sink.add(slots.envmap_rotation, 3 * j + i, d_local[i] * dir[j]);
    return env.to_world_dir(d_local);
}

// Adjoint of Scene::emitted for mesh m at sp towards w, Le = tex(uv) s(w), given the adjoint
// dLe of Le: into the emission texture (and uv, if duv), the spot profile's slot; returns the
// adjoint of w.
Vec3f d_emitted(const Mesh& m, const SceneGradients::MeshSlots* ms, const SurfacePoint& sp, const Vec3f& w,
                const Vec3f& dLe, GradSink& sink, Vec2f* duv) {
    const float s = Scene::spot_scale(m.spot, m.spot_profile, w);
    float d3[3] = {dLe.x * s, dLe.y * s, dLe.z * s};
    d_texture(m.emission, ms ? ms->emission : kNoSlot, sp.uv, d3, sink, duv);
    Vec3f dw(0.f);
    if (m.spot) {
        float dp[kSpotParams] = {};
        d_spot_falloff(m.spot_profile, w, dot(dLe, eval_texture3(m.emission, sp.uv)), dp, dw);
        if (ms && ms->spot.wanted())
            for (int i = 0; i < kSpotParams; ++i) sink.add(ms->spot, i, dp[i]);
    }
    return dw;
}

}  // namespace

VertexGeometry::VertexGeometry(const Scene& scene, const Hit& hit, const Vec3f& origin, const Vec3f& dir) {
    mesh = &scene.meshes[hit.mesh];
    tri = mesh->indices + 3 * hit.prim;
    for (int k = 0; k < 3; ++k) v[k] = mesh->vertex(tri[k]);
    th.b1 = hit.b1;
    th.b2 = hit.b2;
    th.t = hit.t;
    // Re-solve the barycentrics from the ray so that value and adjoint agree exactly.
    TriangleHit<float> h;
    if (intersect_triangle(origin, dir, v[0], v[1], v[2], h)) th = h;
    sp = scene.surface_point(hit.mesh, hit.prim, th.b1, th.b2);
}

void finish_hit(const VertexGeometry& g, const HitAdjoint& a, const SceneGradients::MeshSlots* ms, GradSink& sink,
                const Vec3f& origin, const Vec3f& dir, Vec3f& d_origin, Vec3f& d_dir) {
    const Mesh& m = *g.mesh;
    float b[3] = {1.f - g.th.b1 - g.th.b2, g.th.b1, g.th.b2};
    float db1 = a.db.x, db2 = a.db.y;
    Vec3f dv[3] = {a.dtri[0], a.dtri[1], a.dtri[2]};
    // uv = sum b_i uv_i   (or uv = (b1, b2) without uvs)
    if (m.uvs) {
        const int32_t* ti = m.uv_indices + 3 * (g.tri - m.indices) / 3;
        const float* t[3] = {m.uvs + 2 * ti[0], m.uvs + 2 * ti[1], m.uvs + 2 * ti[2]};
        if (ms && ms->uvs.wanted())
            for (int k = 0; k < 3; ++k) {
                sink.add(ms->uvs, 2 * int64_t(ti[k]), b[k] * a.duv.x + a.dtri_uv[k].x);
                sink.add(ms->uvs, 2 * int64_t(ti[k]) + 1, b[k] * a.duv.y + a.dtri_uv[k].y);
            }
        db1 += a.duv.x * (t[1][0] - t[0][0]) + a.duv.y * (t[1][1] - t[0][1]);
        db2 += a.duv.x * (t[2][0] - t[0][0]) + a.duv.y * (t[2][1] - t[0][1]);
    } else {
        db1 += a.duv.x;
        db2 += a.duv.y;
    }
    // colour = sum b_i c_i
    if (m.colors && !is_black(a.dcolor)) {
        Vec3f c[3];
        for (int k = 0; k < 3; ++k) {
            c[k] = Vec3f::load(m.colors + 3 * int64_t(g.tri[k]));
            if (ms && ms->colors.wanted())
                sink.add3(ms->colors, g.tri[k], a.dcolor.x * b[k], a.dcolor.y * b[k], a.dcolor.z * b[k]);
        }
        db1 += dot(a.dcolor, c[1] - c[0]);
        db2 += dot(a.dcolor, c[2] - c[0]);
    }
    // Shading normal.
    if (m.normals) {
        // ns = normalize(N), N = sum b_i n_i
        const int32_t* ni = m.normal_indices + 3 * (g.tri - m.indices) / 3;
        Vec3f n[3] = {Vec3f::load(m.normals + 3 * ni[0]), Vec3f::load(m.normals + 3 * ni[1]),
                      Vec3f::load(m.normals + 3 * ni[2])};
        Vec3f N = n[0] * b[0] + n[1] * b[1] + n[2] * b[2];
        Vec3f dN = d_normalize(N, a.dn);
        if (ms && ms->normals.wanted())
            for (int k = 0; k < 3; ++k) sink.add3(ms->normals, ni[k], dN.x * b[k], dN.y * b[k], dN.z * b[k]);
        db1 += dot(dN, n[1] - n[0]);
        db2 += dot(dN, n[2] - n[0]);
    }
    // Geometric normal ng = normalize(cross(e1, e2)) (also the shading normal without normals).
    const Vec3f dng = m.normals ? a.dng : a.dng + a.dn;
    if (!is_black(dng)) {
        Vec3f e1 = g.v[1] - g.v[0], e2 = g.v[2] - g.v[0];
        Vec3f dC = d_normalize(cross(e1, e2), dng);
        Vec3f de1(0.f), de2(0.f);
        d_cross(e1, e2, dC, de1, de2);
        dv[1] += de1;
        dv[2] += de2;
        dv[0] -= de1 + de2;
    }
    // p = sum b_i v_i
    for (int k = 0; k < 3; ++k) dv[k] += a.dp * b[k];
    db1 += dot(a.dp, g.v[1] - g.v[0]);
    db2 += dot(a.dp, g.v[2] - g.v[0]);
    // (t, b1, b2) = intersect(origin, dir, v0, v1, v2)
    DTriangle<float> dt{Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), Vec3f(0.f)};
    d_intersect_triangle(origin, dir, g.v[0], g.v[1], g.v[2], g.th, a.dt, db1, db2, dt);
    d_origin += dt.o;
    d_dir += dt.d;
    dv[0] += dt.v0;
    dv[1] += dt.v1;
    dv[2] += dt.v2;
    if (ms && ms->vertices.wanted())
        for (int k = 0; k < 3; ++k) sink.add3(ms->vertices, g.tri[k], dv[k].x, dv[k].y, dv[k].z);
}

void d_diffuse(const Scene& scene, const VertexGeometry& g, const SceneGradients& slots, const Vec3f& dval,
               GradSink& sink, HitAdjoint& ha) {
    const size_t material = size_t(g.mesh->material);
    const Texture& tex = scene.materials[material].diffuse;
    const GradSlot& slot = material < slots.materials.size() ? slots.materials[material].diffuse : kNoSlot;
    Vec3f d = dval;
    if (g.mesh->colors) {
        // diffuse = T(uv) c: dT = dval c, dc = dval T(uv)
        d = dval * g.mesh->color(g.sp.prim, g.sp.b1, g.sp.b2);
        ha.dcolor += dval * eval_texture3(tex, g.sp.uv);
    }
    const float d3[3] = {d.x, d.y, d.z};
    d_texture(tex, slot, g.sp.uv, d3, sink, &ha.duv);
}

void d_normal_map(const Scene& scene, const VertexGeometry& g, const SceneGradients& slots, GradSink& sink,
                  HitAdjoint& ha) {
    const size_t material = size_t(g.mesh->material);
    const Texture& map = scene.materials[material].normal_map;
    if (map.empty() || is_black(ha.dn)) return;
    const int mesh = g.sp.mesh;
    const int64_t prim = g.sp.prim;
    const Vec3f n = scene.unmapped_normal(mesh, prim, g.sp.b1, g.sp.b2);
    Vec3f dpdu(0.f);
    const bool has_dpdu = scene.triangle_dpdu(mesh, prim, dpdu);
    Vec3f dn(0.f), ddpdu(0.f), dv(0.f);
    d_map_normal(n, has_dpdu, dpdu, eval_texture3(map, g.sp.uv), ha.dn, dn, ddpdu, dv);
    ha.dn = dn;
    const GradSlot& slot = material < slots.materials.size() ? slots.materials[material].normal_map : kNoSlot;
    const float d3[3] = {dv.x, dv.y, dv.z};
    d_texture(map, slot, g.sp.uv, d3, sink, &ha.duv);
    if (!has_dpdu || is_black(ddpdu)) return;
    // dp/du from the triangle's edges and uv differences (Scene::triangle_dpdu).
    const Mesh& m = *g.mesh;
    Vec2f d1(1.f, 0.f), d2(0.f, 1.f);
    if (m.uvs) {
        const int32_t* ti = m.uv_indices + 3 * prim;
        const float *t0 = m.uvs + 2 * ti[0], *t1 = m.uvs + 2 * ti[1], *t2 = m.uvs + 2 * ti[2];
        d1 = Vec2f(t1[0] - t0[0], t1[1] - t0[1]);
        d2 = Vec2f(t2[0] - t0[0], t2[1] - t0[1]);
    }
    Vec3f de1(0.f), de2(0.f);
    Vec2f dd1(0.f, 0.f), dd2(0.f, 0.f);
    d_triangle_dpdu(g.v[1] - g.v[0], g.v[2] - g.v[0], d1, d2, ddpdu, de1, de2, dd1, dd2);
    ha.dtri[1] += de1;
    ha.dtri[2] += de2;
    ha.dtri[0] -= de1 + de2;
    if (m.uvs) {
        ha.dtri_uv[1].x += dd1.x;
        ha.dtri_uv[1].y += dd1.y;
        ha.dtri_uv[2].x += dd2.x;
        ha.dtri_uv[2].y += dd2.y;
        ha.dtri_uv[0].x -= dd1.x + dd2.x;
        ha.dtri_uv[0].y -= dd1.y + dd2.y;
    }
}

const SceneGradients::MeshSlots* mesh_slots(const SceneGradients& s, int mesh) {
    return size_t(mesh) < s.meshes.size() ? &s.meshes[mesh] : nullptr;
}

namespace {

TBsdfParams<float> bsdf_params_world(const Scene& scene, const SurfacePoint& sp) {
    return world_params(scene.bsdf_params(sp));
}

// The throughput factor T of vertex r's continuation (beta after = beta T), at the shading
// normal ns: f / pdf, or a smooth material's weight.
Vec3f continuation_weight(const TBsdfParams<float>& bp, const Vec3f& ns, const PathVertexRecord& r) {
    if (!r.next_delta) return bsdf_eval_world(bp, ns, -r.dir, r.next_dir) * r.next_inv_pdf;
    Vec3f dir, T;
    if (!delta_scatter(delta_params(bp), ns, -r.dir, r.next_refract, r.next_inv_pdf, dir, T)) return Vec3f(0.f);
    return T;
}

}  // namespace

void backprop_path(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, const Vec3f& a,
                   GradSink& sink, const SecondaryEdges* secondary, EdgeTermLog* log) {
    const auto& V = rec.vertices;
    const bool env_wanted = slots.envmap.wanted() || slots.envmap_rotation.wanted();
    if (rec.camera_missed) {
        // L = env(d0), d0 = the camera ray's direction.
        if (rec.emitters_hidden || !scene.has_envmap || !(env_wanted || slots.camera.wanted())) return;
        Ray r = scene.camera.generate_ray(rec.film.x, rec.film.y, rec.lens.x, rec.lens.y);
        Vec3f d_dir = d_envmap(scene.envmap, slots, r.dir, a, sink);
        if (slots.camera.wanted()) {
            float cam[kCameraParams] = {};
            d_camera_ray(scene.camera_params, rec.film.x, rec.film.y, rec.lens.x, rec.lens.y, Vec3f(0.f), d_dir, cam);
            for (int i = 0; i < kCameraParams; ++i) sink.add(slots.camera, i, cam[i]);
        }
        return;
    }
    const int K = int(V.size());
    if (log && !log->replaying) log->start(size_t(K));
    Vec3f A_next(0.f);   // adjoint of the throughput after vertex k
    Vec3f dp_next(0.f);  // adjoint of vertex k's position from the ray that leaves it
    Vec3f dd_next(0.f);  // adjoint of that ray's direction (used where vertex k is smooth)
    if (rec.escaped) {
        const PathVertexRecord& last = V[K - 1];
        Vec3f Le = scene.envmap.eval(last.next_dir);
        A_next = a * Le * rec.escape_weight;
        if (env_wanted || last.next_delta) {
            // beta after the last vertex = beta_last * T_last
            VertexGeometry g(scene, last.hit, last.origin, last.dir);
            Vec3f T = continuation_weight(bsdf_params_world(scene, g.sp), bend_normal(g.sp.ns, g.sp.ng, -last.dir), last);
            Vec3f d_dir = d_envmap(scene.envmap, slots, last.next_dir, a * last.beta * T * rec.escape_weight, sink);
            if (last.next_delta) dd_next = d_dir;
        }
    }
    // Whether anything wanted moves vertex k: the camera, a mesh the path met up to k, or the
    // index of refraction of glass it passed.
    uint64_t moves = 0;
    if (secondary) {
        bool m = secondary->camera_wanted();
        for (int k = 0; k < K && k < 64; ++k) {
            m = m || secondary->mesh_wanted(V[k].hit.mesh);
            if (m) moves |= uint64_t(1) << k;
            const int mat = scene.meshes[V[k].hit.mesh].material;
            m = m || (V[k].next_delta && size_t(mat) < slots.materials.size() && slots.materials[mat].ior.wanted());
        }
    }
    for (int k = K - 1; k >= 0; --k) {
        const PathVertexRecord& r = V[k];
        VertexGeometry g(scene, r.hit, r.origin, r.dir);
        const SurfacePoint& sp = g.sp;
        const Mesh& mesh = *g.mesh;
        const SceneGradients::MeshSlots* ms = mesh_slots(slots, r.hit.mesh);
        const Material& mat = scene.materials[mesh.material];
        const SceneGradients::MaterialSlots* mats =
            size_t(mesh.material) < slots.materials.size() ? &slots.materials[mesh.material] : nullptr;
        Vec3f wo = -r.dir;
        Vec3f ab = a * r.beta;  // adjoint of anything added to the radiance at this vertex
        Vec3f A_k(0.f);
        HitAdjoint ha;
        ha.dp = dp_next;
        Vec3f dwo(0.f);

        // Emission seen at this vertex: E = w Le(uv)
        if (r.emission_weight > 0.f) {
            Vec3f Le = scene.emitted(sp, wo);
            if (!is_black(Le)) {
                A_k += a * Le * r.emission_weight;
                dwo += d_emitted(mesh, ms, sp, wo, ab * r.emission_weight, sink, &ha.duv);
            }
        }

        TBsdfParams<float> bp = bsdf_params_world(scene, sp);
        const bool delta = is_delta_kind(bp.kind, bp.rough);
        const Vec3f ns = bend_normal(sp.ns, sp.ng, wo);
        DBsdf<float> db{Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), 0.f};
        float d_eta = 0.f;
        // Next-event estimation: N = f(wo, w_l) Le_l scale, for the area light and the
        // environment samples.
        for (const NeeRecord* nr : {&r.nee_area, &r.nee_env}) {
            if (!nr->used) continue;
            const bool env = nr == &r.nee_env;
            Vec3f f = bsdf_eval_world(bp, ns, wo, nr->dir);
            Vec3f Le;
            if (env) {
                Le = scene.envmap.eval(nr->dir);
                if (env_wanted) d_envmap(scene.envmap, slots, nr->dir, ab * f * nr->scale, sink);
            } else {
                const Mesh& lm = scene.meshes[nr->hit.mesh];
                const SceneGradients::MeshSlots* lms = mesh_slots(slots, nr->hit.mesh);
                VertexGeometry lg(scene, nr->hit, sp.p, nr->dir);
                Le = scene.emitted(lg.sp, -nr->dir);
                HitAdjoint la;
                // The sample's direction is fixed: the profile's own direction does not move.
                d_emitted(lm, lms, lg.sp, -nr->dir, ab * f * nr->scale, sink,
                          lm.emission.is_constant() ? nullptr : &la.duv);
                if (!lm.emission.is_constant()) {
                    Vec3f d_dir_unused(0.f);
                    finish_hit(lg, la, lms, sink, sp.p, nr->dir, ha.dp, d_dir_unused);
                }
            }
            A_k += a * f * Le * nr->scale;
            d_bsdf_eval_world(bp, ns, wo, nr->dir, ab * Le * nr->scale, db);
        }
        // Point lights: N = f(wo, w) I s(-w) / r^2, w = normalize(q - p), r = |q - p|, for
        // each light at q that the forward pass saw (the shadow ray traced again), at the
        // vertices that sampled them.
        for (size_t j = 0; j < scene.point_lights.size() && r.point_lights; ++j) {
            const PointLightDesc& pl = scene.point_lights[j];
            Vec3f wl;
            float dist2;
            if (!see_point_light(scene, sp, pl, wl, dist2)) continue;
            const Vec3f f = bsdf_eval_world(bp, ns, wo, wl);
            if (is_black(f)) continue;
            const SceneGradients::PointLightSlots* ps =
                j < slots.point_lights.size() ? &slots.point_lights[j] : nullptr;
            const Vec3f I = Vec3f::load(pl.intensity);
            const float s = Scene::spot_scale(pl.spot, pl.spot_profile, -wl);
            const float g = s / dist2;
            A_k += a * f * I * g;
            DBsdf<float> dl{Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), 0.f};
            d_bsdf_eval_world(bp, ns, wo, wl, ab * I * g, dl);
            db.diffuse += dl.diffuse;
            db.specular += dl.specular;
            db.n += dl.n;
            db.wo += dl.wo;
            db.alpha += dl.alpha;
            db.eta += dl.eta;
            Vec3f d_wl = dl.wi;
            if (ps && ps->intensity.wanted()) {
                const Vec3f dI = ab * f * g;
                sink.add3(ps->intensity, 0, dI.x, dI.y, dI.z);
            }
            const float dg = dot(ab * f, I);
            const float d_dist2 = -dg * g / dist2;
            if (pl.spot) {
                float dp[kSpotParams] = {};
                Vec3f dw(0.f);
                d_spot_falloff(pl.spot_profile, -wl, dg / dist2, dp, dw);
                d_wl -= dw;
                if (ps && ps->spot.wanted())
                    for (int i = 0; i < kSpotParams; ++i) sink.add(ps->spot, i, dp[i]);
            }
            const Vec3f to = Vec3f::load(pl.position) - sp.p;
            const Vec3f d_to = d_normalize(to, d_wl) + to * (2.f * d_dist2);
            if (ps && ps->position.wanted()) sink.add3(ps->position, 0, d_to.x, d_to.y, d_to.z);
            ha.dp -= d_to;
        }
        // Continuation: beta_next = beta T, T = f(wo, w_next) / pdf
        if (r.next && (k + 1 < K || rec.escaped)) {
            if (r.next_delta) {
                // (w_next, T) = delta_scatter(n, wo, eta): the next vertex moves with them.
                Vec3f dir, T;
                const DeltaParams<float> dp = delta_params(bp);
                if (delta_scatter(dp, ns, wo, r.next_refract, r.next_inv_pdf, dir, T)) {
                    A_k += T * A_next;
                    DDelta<float> dd{Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), 0.f};
                    d_delta_scatter(dp, ns, wo, r.next_refract, r.next_inv_pdf, dd_next, r.beta * A_next, dd);
                    db.specular += dd.specular;
                    db.n += dd.n;
                    db.wo += dd.wo;
                    d_eta += dd.eta;
                }
            } else {
                Vec3f T = bsdf_eval_world(bp, ns, wo, r.next_dir) * r.next_inv_pdf;
                A_k += T * A_next;
                d_bsdf_eval_world(bp, ns, wo, r.next_dir, r.beta * A_next * r.next_inv_pdf, db);
            }
        }
        // Material parameters at uv.
        {
            float ds[3] = {db.specular.x, db.specular.y, db.specular.z};
            float dr[1] = {eval_texture1(mat.roughness, sp.uv) > kMinRoughness ? db.alpha : 0.f};
            d_diffuse(scene, g, slots, db.diffuse, sink, ha);
            d_texture(mat.specular, mats ? mats->specular : kNoSlot, sp.uv, ds, sink, &ha.duv);
            d_texture(mat.roughness, mats ? mats->roughness : kNoSlot, sp.uv, dr, sink, &ha.duv);
            if (mat.kind == MaterialKind::Dielectric || mat.kind == MaterialKind::Plastic) {
                float de[1] = {d_eta + db.eta};
                d_texture(mat.ior, mats ? mats->ior : kNoSlot, sp.uv, de, sink, &ha.duv);
            }
        }
        d_bend_normal(sp.ns, sp.ng, wo, db.n, ha.dn, dwo);
        // Edges seen from this vertex (it scatters: k < max_bounces), with the vertex's own
        // random stream, the same for every call on this record. Russian roulette by the
        // throughput: the term is sampled with probability q = min(1, max component of beta)
        // and weighted 1 / q, so that its weight a beta / q stays within the pixel's adjoint
        // (unbiased; at the camera vertex beta = 1 and q = 1). q does not depend on the adjoint,
        // so the sweeps that replay the terms (one per colour) keep the first sweep's draw.
        // A smooth vertex sees edges along one direction only: no boundary term of its own.
        // And by the vertex's class (its mesh and depth): the probability set from a pilot pass
        // (SecondaryEdges::survival; 1 without one), independent of this term's own samples.
        float q = std::min(1.f, std::max(r.beta.x, std::max(r.beta.y, r.beta.z)));
        if (secondary) q *= secondary->survival(r.hit.mesh, k);
        if (secondary && k < secondary->max_bounces() && !delta && q > 0.f) {
            const Vec3f ab_q = ab / q;
            if (log && log->replaying) {
                const size_t b = log->begin[size_t(k)];
                ha.dp += secondary->replay(log->terms.data() + b, log->end[size_t(k)] - b, ab_q, sink);
            } else {
                if (log) log->begin[size_t(k)] = uint32_t(log->terms.size());
                Rng rng = Rng::for_sample(rec.stream, uint64_t(k), 0x5ec0);
                if (q >= 1.f || rng.next_float() < q) {
                    SurfacePoint bent = sp;
                    bent.ns = ns;
                    ha.dp += secondary->add(bent, wo, bp, secondary->max_bounces() - k - 1, ab_q,
                                            k >= 64 || ((moves >> k) & 1) != 0, rng, sink,
                                            log ? &log->terms : nullptr);
                }
                if (log) log->end[size_t(k)] = uint32_t(log->terms.size());
            }
        }
        dwo += db.wo;

        Vec3f d_origin(0.f), d_dir(0.f);
        d_normal_map(scene, g, slots, sink, ha);
        finish_hit(g, ha, ms, sink, r.origin, r.dir, d_origin, d_dir);
        // wo = -d: the adjoint of the direction of the ray that found this vertex.
        d_dir -= dwo;
        dp_next = d_origin;
        dd_next = d_dir;
        A_next = A_k;
        if (k == 0 && slots.camera.wanted()) {
            // The camera ray (origin, d0) comes from the camera parameters.
            float cam[kCameraParams] = {};
            d_camera_ray(scene.camera_params, rec.film.x, rec.film.y, rec.lens.x, rec.lens.y, d_origin, d_dir, cam);
            for (int i = 0; i < kCameraParams; ++i) sink.add(slots.camera, i, cam[i]);
        }
    }
}

}  // namespace edgepath
