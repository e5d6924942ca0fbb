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

template <class A>
void d_texture(const Texture& tex, const GradSlot& slot, Vec2f uv, const A* dval, GradSink& sink, TVec2<A>* duv) {
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
                A t = tex.data[f.texel[k] * tex.channels + c] * dval[c];
                duv->x += f.dweight_du[k] * t;
                duv->y += f.dweight_dv[k] * t;
            }
        }
}

template void d_texture<float>(const Texture&, const GradSlot&, Vec2f, const float*, GradSink&, Vec2f*);
template void d_texture<Adj3>(const Texture&, const GradSlot&, Vec2f, const Adj3*, GradSink&, AVec2*);

namespace {

// An RGB adjoint as the scalar adjoints of its three channels (channel c: colour c's lane).
template <class A>
void rgb_adjoint(const Vec3f& v, A out[3]) {
    out[0] = one_colour<A>(0, v.x);
    out[1] = one_colour<A>(1, v.y);
    out[2] = one_colour<A>(2, v.z);
}

// A linear map of float vectors applied to each colour's lane.
template <class F>
AVec3 per_lane(const AVec3& v, F f) {
    AVec3 r;
    for (int c = 0; c < 3; ++c) set_lane(r, c, f(lane(v, c)));
    return r;
}

Vec3f to_world(const Envmap& env, const Vec3f& d) { return env.to_world_dir(d); }
AVec3 to_world(const Envmap& env, const AVec3& d) {
    return per_lane(d, [&](const Vec3f& l) { return env.to_world_dir(l); });
}

// d_spot_falloff (scene/spot.h) for the adjoint d_out: into dp[kSpotParams] and dw.
void spot_adjoint(const float* profile, const Vec3f& w, float d_out, float* dp, Vec3f& dw) {
    d_spot_falloff(profile, w, d_out, dp, dw);
}
void spot_adjoint(const float* profile, const Vec3f& w, const Adj3& d_out, Adj3* dp, AVec3& dw) {
    for (int c = 0; c < 3; ++c) {
        float p[kSpotParams] = {};
        Vec3f d = lane(dw, c);
        d_spot_falloff(profile, w, d_out.v[c], p, d);
        set_lane(dw, c, d);
        for (int i = 0; i < kSpotParams; ++i) dp[i].v[c] += p[i];
    }
}

// Adjoint of Envmap::eval: texels and rotation into their slots; returns d L / d world
// direction (the caller decides whether the direction moves). dL: an RGB adjoint.
template <class A>
TVec3<A> d_envmap(const Envmap& env, const SceneGradients& slots, const Vec3f& dir, const Vec3f& dL, GradSink& sink) {
    Envmap::Footprint f = env.footprint(dir);
    const Vec3f dLs = dL * env.scale;
    TVec3<A> d_local(A(0));
    for (int k = 0; k < 4; ++k) {
        if (slots.envmap.wanted()) sink.add_rgb<A>(slots.envmap, f.texel[k], dLs * f.weight[k]);
        d_local += f.dweight[k] * colour_dot<A>(dLs, env.texel(f.texel[k]));
    }
    // local = R^T world: d local_i / d R_ji = world_j; d local / d world = R^T.
    if (slots.envmap_rotation.wanted())
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) sink.add(slots.envmap_rotation, 3 * j + i, d_local[i] * dir[j]);
    return to_world(env, d_local);
}

// Adjoint of Scene::emitted for mesh m at sp towards w, Le = tex(uv) s(w), given the (RGB)
// adjoint dLe of Le: into the emission texture (and uv, if duv), the spot profile's slot;
// returns the adjoint of w.
template <class A>
TVec3<A> d_emitted(const Mesh& m, const SceneGradients::MeshSlots* ms, const SurfacePoint& sp, const Vec3f& w,
                   const Vec3f& dLe, GradSink& sink, TVec2<A>* duv) {
    const float s = Scene::spot_scale(m.spot, m.spot_profile, w);
    A d3[3];
    rgb_adjoint<A>(Vec3f(dLe.x * s, dLe.y * s, dLe.z * s), d3);
    d_texture(m.emission, ms ? ms->emission : kNoSlot, sp.uv, d3, sink, duv);
    TVec3<A> dw(A(0));
    if (m.spot) {
        A dp[kSpotParams] = {};
        spot_adjoint(m.spot_profile, w, colour_dot<A>(dLe, eval_texture3(m.emission, sp.uv)), dp, dw);
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

template <class A>
void finish_hit(const VertexGeometry& g, const THitAdjoint<A>& a, const SceneGradients::MeshSlots* ms, GradSink& sink,
                const Vec3f& origin, const Vec3f& dir, TVec3<A>& d_origin, TVec3<A>& d_dir, bool positions) {
    const Mesh& m = *g.mesh;
    float b[3] = {1.f - g.th.b1 - g.th.b2, g.th.b1, g.th.b2};
    A db1 = a.db.x, db2 = a.db.y;
    TVec3<A> dv[3] = {a.dtri[0], a.dtri[1], a.dtri[2]};
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
            if (ms && ms->colors.wanted()) sink.add_rgb<A>(ms->colors, g.tri[k], a.dcolor * b[k]);
        }
        if constexpr (is_adj_n<A>::value) {
            db1 += dot(a.dcolor, c[1] - c[0]);
            db2 += dot(a.dcolor, c[2] - c[0]);
        } else {
            db1 += colour_dot<A>(a.dcolor, c[1] - c[0]);
            db2 += colour_dot<A>(a.dcolor, c[2] - c[0]);
        }
    }
    // Shading normal.
    if (m.normals) {
        // ns = normalize(N), N = sum b_i n_i
        const int32_t* ni = m.normal_indices + 3 * (g.tri - m.indices) / 3;
        Vec3f n[3] = {Vec3f::load(m.normals + 3 * ni[0]), Vec3f::load(m.normals + 3 * ni[1]),
                      Vec3f::load(m.normals + 3 * ni[2])};
        Vec3f N = n[0] * b[0] + n[1] * b[1] + n[2] * b[2];
        TVec3<A> dN = d_normalize(N, a.dn);
        if (ms && ms->normals.wanted())
            for (int k = 0; k < 3; ++k) sink.add3(ms->normals, ni[k], dN.x * b[k], dN.y * b[k], dN.z * b[k]);
        db1 += dot(dN, n[1] - n[0]);
        db2 += dot(dN, n[2] - n[0]);
    }
    if (!positions) return;
    // Geometric normal ng = normalize(cross(e1, e2)) (also the shading normal without normals).
    const TVec3<A> dng = m.normals ? a.dng : a.dng + a.dn;
    if (!is_black(dng)) {
        Vec3f e1 = g.v[1] - g.v[0], e2 = g.v[2] - g.v[0];
        TVec3<A> dC = d_cross_normal(e1, e2, dng);
        TVec3<A> de1(A(0)), de2(A(0));
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
    DTriangle<A> dt;
    d_intersect_triangle(origin, dir, g.v[0], g.v[1], g.v[2], g.th, a.dt, db1, db2, dt);
    d_origin += dt.o;
    d_dir += dt.d;
    dv[0] += dt.v0;
    dv[1] += dt.v1;
    dv[2] += dt.v2;
    if (ms && ms->vertices.wanted())
        for (int k = 0; k < 3; ++k) sink.add3(ms->vertices, g.tri[k], dv[k].x, dv[k].y, dv[k].z);
}

template void finish_hit<float>(const VertexGeometry&, const HitAdjoint&, const SceneGradients::MeshSlots*,
                                GradSink&, const Vec3f&, const Vec3f&, Vec3f&, Vec3f&, bool);
#define EDGEPATH_FINISH_HIT_N(N)                                                                                     \
    template void finish_hit<AdjN<N>>(const VertexGeometry&, const THitAdjoint<AdjN<N>>&,                             \
                                      const SceneGradients::MeshSlots*, GradSink&, const Vec3f&, const Vec3f&,        \
                                      TVec3<AdjN<N>>&, TVec3<AdjN<N>>&, bool);                                        \
    template void d_texture<AdjN<N>>(const Texture&, const GradSlot&, Vec2f, const AdjN<N>*, GradSink&,              \
                                     TVec2<AdjN<N>>*);
EDGEPATH_FINISH_HIT_N(4)
EDGEPATH_FINISH_HIT_N(8)
EDGEPATH_FINISH_HIT_N(16)
EDGEPATH_FINISH_HIT_N(28)
#undef EDGEPATH_FINISH_HIT_N

template <class A>
void d_diffuse(const Scene& scene, const VertexGeometry& g, const SceneGradients& slots, const Vec3f& dval,
               GradSink& sink, THitAdjoint<A>& ha) {
    const size_t material = size_t(g.mesh->material);
    const Texture& tex = scene.materials[material].diffuse;
    const GradSlot& slot = material < slots.materials.size() ? slots.materials[material].diffuse : kNoSlot;
    Vec3f d = dval;
    if (g.mesh->colors) {
        // diffuse = T(uv) c: dT = dval c, dc = dval T(uv)
        d = dval * g.mesh->color(g.sp.prim, g.sp.b1, g.sp.b2);
        ha.dcolor += dval * eval_texture3(tex, g.sp.uv);
    }
    A d3[3];
    rgb_adjoint<A>(d, d3);
    d_texture(tex, slot, g.sp.uv, d3, sink, &ha.duv);
}

template void d_diffuse<float>(const Scene&, const VertexGeometry&, const SceneGradients&, const Vec3f&, GradSink&,
                               HitAdjoint&);

namespace {

// d_map_normal and d_triangle_dpdu (scene/normal_map.h) for float adjoints.
void map_normal_adjoint(const Vec3f& n, bool has_dpdu, const Vec3f& dpdu, const Vec3f& v, const Vec3f& d_out,
                        Vec3f& dn, Vec3f& ddpdu, Vec3f& dv) {
    d_map_normal(n, has_dpdu, dpdu, v, d_out, dn, ddpdu, dv);
}
void triangle_dpdu_adjoint(const Vec3f& e1, const Vec3f& e2, const Vec2f& d1, const Vec2f& d2, const Vec3f& ddpdu,
                           Vec3f& de1, Vec3f& de2, Vec2f& dd1, Vec2f& dd2) {
    d_triangle_dpdu(e1, e2, d1, d2, ddpdu, de1, de2, dd1, dd2);
}
// The same lane by lane for Adj3 and AdjN, each lane only where its adjoint is not zero (where a
// sweep with that lane's unit adjoint alone returns before the call).
template <class A>
void map_normal_adjoint(const Vec3f& n, bool has_dpdu, const Vec3f& dpdu, const Vec3f& v, const TVec3<A>& d_out,
                        TVec3<A>& dn, TVec3<A>& ddpdu, TVec3<A>& dv) {
    for (int j = 0; j < kAdjLanes<A>; ++j) {
        const Vec3f d = lane(d_out, j);
        if (is_black(d)) continue;
        Vec3f a = lane(dn, j), b = lane(ddpdu, j), e = lane(dv, j);
        d_map_normal(n, has_dpdu, dpdu, v, d, a, b, e);
        set_lane(dn, j, a);
        set_lane(ddpdu, j, b);
        set_lane(dv, j, e);
    }
}
template <class A>
void triangle_dpdu_adjoint(const Vec3f& e1, const Vec3f& e2, const Vec2f& d1, const Vec2f& d2,
                           const TVec3<A>& ddpdu, TVec3<A>& de1, TVec3<A>& de2, TVec2<A>& dd1, TVec2<A>& dd2) {
    for (int j = 0; j < kAdjLanes<A>; ++j) {
        const Vec3f d = lane(ddpdu, j);
        if (is_black(d)) continue;
        Vec3f a = lane(de1, j), b = lane(de2, j);
        Vec2f p(dd1.x.v[j], dd1.y.v[j]), q(dd2.x.v[j], dd2.y.v[j]);
        d_triangle_dpdu(e1, e2, d1, d2, d, a, b, p, q);
        set_lane(de1, j, a);
        set_lane(de2, j, b);
        dd1.x.v[j] = p.x;
        dd1.y.v[j] = p.y;
        dd2.x.v[j] = q.x;
        dd2.y.v[j] = q.y;
    }
}

}  // namespace

template <class A>
void d_normal_map(const Scene& scene, const VertexGeometry& g, const SceneGradients& slots, GradSink& sink,
                  THitAdjoint<A>& ha) {
    const size_t material = size_t(g.mesh->material);
    const Texture& map = scene.materials[material].normal_map;
    if (map.empty() || is_black(ha.dn)) return;
    const int mesh = g.sp.mesh;
    const int64_t prim = g.sp.prim;
    const Vec3f n = scene.unmapped_normal(mesh, prim, g.sp.b1, g.sp.b2);
    Vec3f dpdu(0.f);
    const bool has_dpdu = scene.triangle_dpdu(mesh, prim, dpdu);
    TVec3<A> dn(A(0)), ddpdu(A(0)), dv(A(0));
    map_normal_adjoint(n, has_dpdu, dpdu, eval_texture3(map, g.sp.uv), ha.dn, dn, ddpdu, dv);
    ha.dn = dn;
    const GradSlot& slot = material < slots.materials.size() ? slots.materials[material].normal_map : kNoSlot;
    const A d3[3] = {dv.x, dv.y, dv.z};
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
    TVec3<A> de1(A(0)), de2(A(0));
    TVec2<A> dd1, dd2;
    triangle_dpdu_adjoint(g.v[1] - g.v[0], g.v[2] - g.v[0], d1, d2, ddpdu, de1, de2, dd1, dd2);
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

template void d_normal_map<float>(const Scene&, const VertexGeometry&, const SceneGradients&, GradSink&, HitAdjoint&);
template void d_normal_map<AdjN<4>>(const Scene&, const VertexGeometry&, const SceneGradients&, GradSink&,
                                    THitAdjoint<AdjN<4>>&);
template void d_normal_map<AdjN<8>>(const Scene&, const VertexGeometry&, const SceneGradients&, GradSink&,
                                    THitAdjoint<AdjN<8>>&);
template void d_normal_map<AdjN<16>>(const Scene&, const VertexGeometry&, const SceneGradients&, GradSink&,
                                     THitAdjoint<AdjN<16>>&);
template void d_normal_map<AdjN<28>>(const Scene&, const VertexGeometry&, const SceneGradients&, GradSink&,
                                     THitAdjoint<AdjN<28>>&);

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

// d_delta_scatter (scene/specular.h) for the RGB adjoint `dweight` of the weight and the
// adjoint `ddir` of the direction: into db (specular, n, wo) and d_eta. Lane by lane for Adj3:
// colour c's sweep sees the channel c of dweight only.
void delta_adjoint(const DeltaParams<float>& p, const Vec3f& n, const Vec3f& wo, bool refract, float inv_pdf,
                   const Vec3f& ddir, const Vec3f& dweight, DBsdf<float>& db, float& d_eta) {
    DDelta<float> dd{Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), 0.f};
    d_delta_scatter(p, n, wo, refract, inv_pdf, ddir, dweight, dd);
    db.specular += dd.specular;
    db.n += dd.n;
    db.wo += dd.wo;
    d_eta += dd.eta;
}
void delta_adjoint(const DeltaParams<float>& p, const Vec3f& n, const Vec3f& wo, bool refract, float inv_pdf,
                   const AVec3& ddir, const Vec3f& dweight, DBsdf<float, Adj3>& db, Adj3& d_eta) {
    AVec3 dn, dwo;
    Adj3 de;
    for (int c = 0; c < 3; ++c) {
        DDelta<float> dd{Vec3f(0.f), Vec3f(0.f), Vec3f(0.f), 0.f};
        d_delta_scatter(p, n, wo, refract, inv_pdf, lane(ddir, c), channel(dweight, c), dd);
        db.specular[c] += dd.specular[c];
        set_lane(dn, c, dd.n);
        set_lane(dwo, c, dd.wo);
        de.v[c] = dd.eta;
    }
    db.n += dn;
    db.wo += dwo;
    d_eta += de;
}

// The sweep, with scalar adjoints of type A (float: backprop_path; Adj3: backprop_path_colours).
template <class A>
void sweep(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, const Vec3f& a, GradSink& sink,
           const SecondaryEdges* secondary, EdgeTermLog* log) {
    constexpr bool colours = std::is_same_v<A, Adj3>;
    const auto& V = rec.vertices;
    const bool env_wanted = slots.envmap.wanted() || slots.envmap_rotation.wanted();
    if (rec.camera_missed) {
        // L = env(d0), d0 = the camera ray's direction.
        if (rec.emitters_hidden || !scene.has_envmap || !(env_wanted || slots.camera.wanted())) return;
        Ray r = scene.camera.generate_ray(rec.film.x, rec.film.y, rec.lens.x, rec.lens.y);
        TVec3<A> d_dir = d_envmap<A>(scene.envmap, slots, r.dir, a, sink);
        d_camera_params(scene, slots, rec.film, rec.lens, TVec3<A>(A(0)), d_dir, sink);
        return;
    }
    const int K = int(V.size());
    if (log && (colours || !log->replaying)) log->start(size_t(K));
    Vec3f A_next(0.f);      // adjoint of the throughput after vertex k
    TVec3<A> dp_next(A(0));  // adjoint of vertex k's position from the ray that leaves it
    TVec3<A> dd_next(A(0));  // adjoint of that ray's direction (used where vertex k is smooth)
    if (rec.escaped) {
        const PathVertexRecord& last = V[K - 1];
        Vec3f Le = scene.envmap.eval(last.next_dir);
        A_next = a * Le * rec.escape_weight;
        if (env_wanted || last.next_delta) {
            // beta after the last vertex = beta_last * T_last
            VertexGeometry g(scene, last.hit, last.origin, last.dir);
            Vec3f T = continuation_weight(bsdf_params_world(scene, g.sp), bend_normal(g.sp.ns, g.sp.ng, -last.dir), last);
            TVec3<A> d_dir = d_envmap<A>(scene.envmap, slots, last.next_dir, a * last.beta * T * rec.escape_weight, sink);
            if (last.next_delta) dd_next = d_dir;
        }
    }
    // Along the path from the camera, two masks that stay set once set at a vertex k:
    // - moves (the edge term's): whether anything wanted moves vertex k: the camera, the vertices
    //   of a mesh the path met up to k, or the index of refraction of glass it passed;
    // - positions: whether the adjoint of vertex k's position and of the direction that found it
    //   reaches anything wanted: the same, or past any smooth bounce before k (its direction
    //   moves with its normal and index, and the vertex after it with that direction). Where it
    //   is clear, finish_hit leaves the positions out (nothing they would add is wanted).
    uint64_t moves = 0, positions = 0;
    {
        bool geometry = slots.camera.wanted(), past_index = false, past_smooth = false;
        for (int k = 0; k < K && k < 64; ++k) {
            const SceneGradients::MeshSlots* ms = mesh_slots(slots, V[k].hit.mesh);
            geometry = geometry || (ms && ms->vertices.wanted());
            if (geometry || past_index) moves |= uint64_t(1) << k;
            if (geometry || past_smooth) positions |= uint64_t(1) << k;
            if (V[k].next_delta) {
                const int mat = scene.meshes[V[k].hit.mesh].material;
                past_index = past_index || (size_t(mat) < slots.materials.size() && slots.materials[mat].ior.wanted());
                past_smooth = true;
            }
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
        THitAdjoint<A> ha;
        ha.dp = dp_next;
        TVec3<A> dwo(A(0));

        // Emission seen at this vertex: E = w Le(uv)
        if (r.emission_weight > 0.f) {
            Vec3f Le = scene.emitted(sp, wo);
            if (!is_black(Le)) {
                A_k += a * Le * r.emission_weight;
                dwo += d_emitted<A>(mesh, ms, sp, wo, ab * r.emission_weight, sink, &ha.duv);
            }
        }

        TBsdfParams<float> bp = bsdf_params_world(scene, sp);
        const bool delta = is_delta_kind(bp.kind, bp.rough);
        const Vec3f ns = bend_normal(sp.ns, sp.ng, wo);
        DBsdf<float, A> db;
        A d_eta = A(0);
        // Next-event estimation: N = f(wo, w_l) Le_l scale, for the area light and the
        // environment samples.
        for (const NeeRecord* nr : {&r.nee_area, &r.nee_env}) {
            if (!nr->used) continue;
            const bool env = nr == &r.nee_env;
            Vec3f f = bsdf_eval_world(bp, ns, wo, nr->dir);
            Vec3f Le;
            if (env) {
                Le = scene.envmap.eval(nr->dir);
                if (env_wanted) d_envmap<A>(scene.envmap, slots, nr->dir, ab * f * nr->scale, sink);
            } else {
                const Mesh& lm = scene.meshes[nr->hit.mesh];
                const SceneGradients::MeshSlots* lms = mesh_slots(slots, nr->hit.mesh);
                VertexGeometry lg(scene, nr->hit, sp.p, nr->dir);
                Le = scene.emitted(lg.sp, -nr->dir);
                THitAdjoint<A> la;
                // The sample's direction is fixed: the profile's own direction does not move.
                d_emitted<A>(lm, lms, lg.sp, -nr->dir, ab * f * nr->scale, sink,
                             lm.emission.is_constant() ? nullptr : &la.duv);
                if (!lm.emission.is_constant()) {
                    TVec3<A> d_dir_unused(A(0));
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
            DBsdf<float, A> dl;
            d_bsdf_eval_world(bp, ns, wo, wl, ab * I * g, dl);
            db.diffuse += dl.diffuse;
            db.specular += dl.specular;
            db.n += dl.n;
            db.wo += dl.wo;
            db.alpha += dl.alpha;
            db.eta += dl.eta;
            TVec3<A> d_wl = dl.wi;
            if (ps && ps->intensity.wanted()) sink.add_rgb<A>(ps->intensity, 0, ab * f * g);
            const A dg = colour_dot<A>(ab * f, I);
            const A d_dist2 = -dg * g / dist2;
            if (pl.spot) {
                A dp[kSpotParams] = {};
                TVec3<A> dw(A(0));
                spot_adjoint(pl.spot_profile, -wl, dg / dist2, dp, dw);
                d_wl -= dw;
                if (ps && ps->spot.wanted())
                    for (int i = 0; i < kSpotParams; ++i) sink.add(ps->spot, i, dp[i]);
            }
            const Vec3f to = Vec3f::load(pl.position) - sp.p;
            const TVec3<A> d_to = d_normalize(to, d_wl) + to * (2.f * d_dist2);
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
                    // w_next = delta_side(dir, ng, side): mirrored across the face where it
                    // left on the wrong side.
                    TVec3<A> d_dir(A(0));
                    d_delta_side(dir, sp.ng, delta_side_sign(wo, sp.ng, r.next_refract), dd_next, d_dir, ha.dng);
                    delta_adjoint(dp, ns, wo, r.next_refract, r.next_inv_pdf, d_dir, r.beta * A_next, db, d_eta);
                }
            } else {
                Vec3f T = bsdf_eval_world(bp, ns, wo, r.next_dir) * r.next_inv_pdf;
                A_k += T * A_next;
                d_bsdf_eval_world(bp, ns, wo, r.next_dir, r.beta * A_next * r.next_inv_pdf, db);
            }
        }
        // Material parameters at uv.
        {
            A ds[3];
            rgb_adjoint<A>(db.specular, ds);
            A dr[1] = {eval_texture1(mat.roughness, sp.uv) > kMinRoughness ? db.alpha : A(0)};
            d_diffuse(scene, g, slots, db.diffuse, sink, ha);
            d_texture(mat.specular, mats ? mats->specular : kNoSlot, sp.uv, ds, sink, &ha.duv);
            d_texture(mat.roughness, mats ? mats->roughness : kNoSlot, sp.uv, dr, sink, &ha.duv);
            if (mat.kind == MaterialKind::Dielectric || mat.kind == MaterialKind::Plastic) {
                A de[1] = {d_eta + db.eta};
                d_texture(mat.ior, mats ? mats->ior : kNoSlot, sp.uv, de, sink, &ha.duv);
            }
        }
        d_bend_normal(sp.ns, sp.ng, wo, db.n, ha.dn, dwo);
        // Edges seen from this vertex (it scatters: k < max_bounces), with the vertex's own
        // random stream, the same for every call on this record. Russian roulette by the
        // throughput: the term is sampled with probability q = min(1, max component of beta)
        // and weighted 1 / q, so that its weight a beta / q stays within the pixel's adjoint
        // (unbiased; at the camera vertex beta = 1 and q = 1). q does not depend on the adjoint:
        // one draw serves every colour (and any sweep that replays the terms).
        // A smooth vertex sees edges along one direction only: no boundary term of its own.
        // And by the vertex's class (its mesh and depth): the probability set from a pilot pass
        // (SecondaryEdges::survival; 1 without one), independent of this term's own samples.
        float q = std::min(1.f, std::max(r.beta.x, std::max(r.beta.y, r.beta.z)));
        if (secondary) q *= secondary->survival(r.hit.mesh, k);
        if (secondary && k < secondary->max_bounces() && !delta && q > 0.f) {
            const Vec3f ab_q = ab / q;
            if constexpr (colours) {
                // Sampled once (a zero weight: recorded, nothing added), then applied to each
                // colour.
                const size_t b = log->terms.size();
                log->begin[size_t(k)] = uint32_t(b);
                Rng rng = Rng::for_sample(rec.stream, uint64_t(k), 0x5ec0);
                if (q >= 1.f || rng.next_float() < q) {
                    SurfacePoint bent = sp;
                    bent.ns = ns;
                    secondary->add(bent, wo, bp, secondary->max_bounces() - k - 1, Vec3f(0.f),
                                   k >= 64 || ((moves >> k) & 1) != 0, rng, sink, &log->terms);
                }
                log->end[size_t(k)] = uint32_t(log->terms.size());
                ha.dp += secondary->replay_colours(log->terms.data() + b, log->terms.size() - b, ab_q, sink);
            } else if (log && log->replaying) {
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

        TVec3<A> d_origin(A(0)), d_dir(A(0));
        d_normal_map(scene, g, slots, sink, ha);
        finish_hit(g, ha, ms, sink, r.origin, r.dir, d_origin, d_dir, k >= 64 || ((positions >> k) & 1) != 0);
        // wo = -d: the adjoint of the direction of the ray that found this vertex.
        d_dir -= dwo;
        dp_next = d_origin;
        dd_next = d_dir;
        A_next = A_k;
        // The camera ray (origin, d0) comes from the camera parameters.
        if (k == 0) d_camera_params(scene, slots, rec.film, rec.lens, d_origin, d_dir, sink);
    }
}

}  // namespace

void backprop_path(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, const Vec3f& a,
                   GradSink& sink, const SecondaryEdges* secondary, EdgeTermLog* log) {
    sweep<float>(scene, slots, rec, a, sink, secondary, log);
}

void backprop_path_colours(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, float w,
                           GradSink& sink, const SecondaryEdges* secondary, EdgeTermLog* log) {
    EdgeTermLog scratch;
    if (secondary && !log) log = &scratch;
    sweep<Adj3>(scene, slots, rec, Vec3f(w), sink, secondary, log);
}

}  // namespace edgepath
