#include "edges/secondary.h"

#include <algorithm>
#include <cmath>
#include "edges/sides.h"
#include "render/path.h"
#include "render/tiles.h"

namespace edgepath {

namespace {
// Where the surface on one side of an edge sample touches the edge, that side is evaluated this
// fraction of the distance off the edge (edges/sides.h). (At 3e-5 of the distance and below,
// rays from there passing the edge's faces were still reported as hitting them.)
constexpr float kTouchStep = 1e-4f;
}  // namespace

void SecondaryEdges::build_set(EdgeSet& set, bool (*keep)(const SecondaryEdges&, int mesh)) {
    const Scene::EdgeMeasures& measures = scene_.edge_measures();
    set.cumulative.assign(1, 0.0);
    if (!by_length_) {  // only whether the set has an edge
        for (size_t m = 0; m < scene_.meshes.size(); ++m)
            if (keep(*this, int(m)) && measures.sampled[m] > 0) set.total = 1.0;
        return;
    }
    const std::vector<Edge>& all = scene_.edges();
    for (size_t i = 0; i < all.size(); ++i) {
        if (all[i].flat || !keep(*this, all[i].mesh)) continue;
        const double len = measures.length[i];
        if (!(len > 0.0)) continue;
        set.edges.push_back(int32_t(i));
        set.cumulative.push_back(set.cumulative.back() + len);
    }
    set.total = set.cumulative.back();
}

SecondaryEdges::SecondaryEdges(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots)
    : scene_(scene), opt_(opt), slots_(slots) {
    if (!opt.secondary_edges || opt.max_bounces < 1) return;
    bool any = slots.camera.wanted(), every = slots.camera.wanted();
    for (size_t i = 0; i < scene.meshes.size(); ++i) {
        any = any || mesh_wanted(int(i));
        every = every && mesh_wanted(int(i));
    }
    // A wanted index of refraction moves the shading points seen through glass.
    bool ior = false;
    for (const SceneGradients::MaterialSlots& m : slots.materials) ior = ior || m.ior.wanted();
    if (!any && !ior) return;
    if (!any) every = true;  // only shading points move: every edge alike
    uniform_ = opt.edge_sampling == EdgeSampling::Uniform;
    // Edges are sampled by length with the uniform sampler, and at a rough dielectric's
    // vertices (add()); otherwise the sets only tell whether there is an edge to sample.
    by_length_ = uniform_;
    for (const Material& m : scene.materials) by_length_ = by_length_ || m.kind == MaterialKind::Dielectric;
    // Each edge's length (kept by the scene).
    const std::vector<Edge>& edges = scene.edges();
    const std::vector<float>& lengths = scene.edge_measures().length;
    // Every edge: an occluder's edges move the shadow it casts, and any edge moves relative to a
    // shading point that moves (with the camera or its own surface).
    build_set(all_, [](const SecondaryEdges&, int) { return true; });
    total_ = all_.total;
    // Where nothing wanted moves the shading point, only the wanted meshes' edges matter.
    if (!every) {
        build_set(wanted_, [](const SecondaryEdges& self, int mesh) { return self.mesh_wanted(mesh); });
        has_wanted_set_ = true;
    }
    if (!uniform_ && all_.total > 0.0) {
        // The wanted meshes' edges first, under a subtree of their own; with the flat edges of
        // a scene whose vertices move (Edge::flat), empty leaves there, so that the same tree
        // is refit while moves turn edges flat and back.
        // The list is a function of the geometry and of which meshes are wanted, its key.
        std::vector<uint8_t> key(1, uint8_t(has_wanted_set_));
        if (has_wanted_set_)
            for (size_t i = 0; i < scene.meshes.size(); ++i) key.push_back(uint8_t(mesh_wanted(int(i))));
        hierarchy_ = scene.edge_hierarchy(key, [&](std::vector<int32_t>& order, size_t& group) {
            order.reserve(edges.size());
            for (int pass = 0; pass < (has_wanted_set_ ? 2 : 1); ++pass) {
                for (size_t i = 0; i < edges.size(); ++i) {
                    if (has_wanted_set_ && mesh_wanted(edges[i].mesh) != (pass == 0)) continue;
                    if (!(lengths[i] > 0.f)) continue;
                    order.push_back(int32_t(i));
                }
                if (pass == 0) group = has_wanted_set_ ? order.size() : 0;
            }
        });
        wanted_root_ = has_wanted_set_ ? hierarchy_->group_root() : 0;
    }
    // A bounding sphere of the area lights: the box's centre, the farthest vertex.
    auto each_light_vertex = [&](auto&& f) {
        for (const Scene::EmissiveTriangle& l : scene.lights) {
            const Mesh& m = scene.meshes[size_t(l.mesh)];
            // A mesh sampled by solid angle (prim -1): all its triangles.
            const int64_t first = l.prim < 0 ? 0 : l.prim, end = l.prim < 0 ? m.num_triangles : l.prim + 1;
            for (int64_t t = first; t < end; ++t)
                for (int k = 0; k < 3; ++k) f(m.vertex(m.indices[3 * t + k]));
        }
    };
    Vec3f lo, hi;
    each_light_vertex([&](const Vec3f& v) {
        lo = has_lights_ ? min(lo, v) : v;
        hi = has_lights_ ? max(hi, v) : v;
        has_lights_ = true;
    });
    if (!has_lights_) return;
    // Few light triangles (no mesh sampled by solid angle): kept to bound the light strategy's
    // point on an edge (LightTriangles).
    bool few = scene.lights.size() <= size_t(LightTriangles::kMax);
    for (const Scene::EmissiveTriangle& l : scene.lights) few = few && l.prim >= 0;
    if (few) {
        for (const Scene::EmissiveTriangle& l : scene.lights) {
            const Mesh& m = scene.meshes[size_t(l.mesh)];
            for (int k = 0; k < 3; ++k) light_corners_[light_count_][k] = m.vertex(m.indices[3 * l.prim + k]);
            ++light_count_;
        }
    }
    lights_center_ = (lo + hi) * 0.5f;
    each_light_vertex([&](const Vec3f& v) { lights_radius_ = std::max(lights_radius_, length(v - lights_center_)); });
}

Vec3f SecondaryEdges::add(const SurfacePoint& sp, const Vec3f& wo, const TBsdfParams<float>& bsdf, int bounces_left,
                          const Vec3f& weight, bool position_matters, Rng rng, GradSink& sink,
                          std::vector<EdgeTerm>* record) const {
    Vec3f d_p(0.f);
    if (!active()) return d_p;
    const EdgeSet& set = (position_matters || !has_wanted_set_) ? all_ : wanted_;
    if (!(set.total > 0.0)) return d_p;
    // The hierarchy's lobe bound covers the side of wo only: a rough dielectric, which also
    // transmits, picks its edges uniformly (unbiased, noisier).
    if (uniform_ || bsdf.kind == MaterialKind::Dielectric) {
        // An edge by length, a point on it uniformly: density 1 / total per unit length.
        const double at = rng.next_double() * set.total;
        const size_t k = std::min(size_t(std::upper_bound(set.cumulative.begin(), set.cumulative.end(), at) -
                                         set.cumulative.begin()) - 1,
                                  set.edges.size() - 1);
        const float t = rng.next_float();
        return evaluate(set.edges[k], t, float(set.total), sp, wo, bsdf, bounces_left, weight, rng, sink, record);
    }
    // The lobe bound of the BSDF, on the side of wo (it is zero for every direction otherwise).
    Vec3f n = sp.ns;
    float co = dot(n, wo);
    if (bsdf.two_sided && co < 0.f) {
        n = -n;
        co = -co;
    }
    if (!(co > 0.f)) return d_p;
    // At a vertex's last bounce, what either side of an edge sees counts only by its emission:
    // with neither an environment nor an area light (point lights have no boundary term), both
    // sides are black and no edge sample can add anything.
    if (bounces_left == 0 && !scene_.has_envmap && !has_lights_) return d_p;
    auto mean = [](const Vec3f& c) { return (c.x + c.y + c.z) / 3.f; };
    EdgeHierarchy::Query q;
    thread_local EdgeHierarchy::Memo memo;
    memo.reset();
    q.memo = &memo;
    // The leaves' arcs and Lights parts as the descent scores them: the point sampler on a
    // chosen edge takes them from there.
    thread_local LeafArcs arcs;
    arcs.reset();
    q.arcs = &arcs;
    q.p = sp.p;
    q.direct_only = bounces_left == 0;
    // The smooth plastic's coating reflects into one direction: no lobe for edges to meet.
    const bool glossy = bsdf.kind != MaterialKind::Plastic || bsdf.rough;
    q.lobe = LobeBound::make(n, wo, mean(bsdf.diffuse), glossy ? mean(bsdf.specular) : 0.f, bsdf.alpha);
    // Strategy All: over all edges; strategy Lights: the edges and the parts of them inside the
    // cone towards the lights. Balance heuristic on the joint density of (edge, t).
    BoundsCone cone;
    // Inside the lights' bounding sphere the cone is everything: one strategy.
    if (has_lights_ && cone.towards(sp.p, lights_center_, lights_radius_)) {
        // Widened by four times the step of a side evaluated off the edge (kTouchStep of the
        // distance), which can carry it onto a light from just outside the cone. The margin also
        // keeps the rare samples at the cone's border weighted by both strategies: without it,
        // translate_occluder_area_light had single pixels off by 1.36-1.52 at some seeds (max
        // err; 0.26-0.33 with it, and with side rays).
        cone.half = std::min(cone.half + 4.f * kTouchStep, kPi);
        cone.cos_half = std::cos(cone.half);
        q.cone = &cone;
    }
    // The light triangles seen from p, with the cone's margin: the directions the light strategy
    // takes towards them, for the edges it picks (a leaf's importance: the part of its edge
    // within the margin of a triangle; a node's: zero for a box outside every triangle's widened
    // wedge) and the point on each (EdgePointSampler, the same part). Every direction where
    // either side of an edge can meet a light's emission (a side moves its ray off by less than
    // the margin) lies in their part, so strategy Lights alone (c_lights = 1 below) stays
    // unbiased: an edge it cannot pick, or a part of one it cannot sample, has no light within
    // the margin behind it.
    LightTriangles tris;
    if (q.cone && light_count_ > 0) {
        tris.set(sp.p, light_corners_, light_count_, 4.f * kTouchStep);
        q.lights = &tris;
    }
    // One descent per vertex: strategy All, or Lights with probability c_lights. One-sample
    // multiple importance sampling: the balance heuristic on the mixture of the two joint
    // densities. A descent may split (up to EdgeHierarchy::kMaxChoices edges); the densities are
    // then the expected numbers of times each strategy picks the edge. (Running both strategies
    // at every vertex cost twice as much for less than half the variance: measured on the
    // benchmark's shadow scene.) c_lights depends on the vertex alone (its BSDF, its lobe, the
    // cone), never on the sample, so the mixture stays unbiased:
    // - at a last bounce without an environment, what either side of an edge sees counts only by
    //   the area lights' emission, which comes from inside the cone: every edge and every part
    //   of an edge outside it adds nothing, and the light strategy alone is taken;
    // - otherwise by the BSDF's mean albedos, kd diffuse and ks glossy: the diffuse part at 0.8
    //   (a shadow's edges cut the lights), the glossy part at 0.95 times its lobe's largest
    //   value inside the cone over its peak (a lobe aimed at a light sees the edges that cut its
    //   highlight there; a lobe aimed elsewhere is served by the lobe-weighted strategy over all
    //   edges). On the benchmark's glossy floor (a GGX plastic, alpha 0.08), where only the
    //   light cut by the cube's edges contributes, all but 0.1% of the samples of strategy All
    //   were zero, and 22% of the light strategy's were not; with the glossy part counted at
    //   0 (as before), the variance of the derivative image was 3.1 times this rule's.
    const float kd = std::max(mean(bsdf.diffuse), 0.f), ks = std::max(mean(bsdf.specular), 0.f);
    float c_lights = 0.f;
    if (q.cone) {
        if (bounces_left == 0 && !scene_.has_envmap) c_lights = 1.f;
        else if (kd + ks > 0.f) c_lights = (0.8f * kd + 0.95f * ks * q.lobe.glossy_share(cone)) / (kd + ks);
    }
    const float c_all = 1.f - c_lights;
    float us = rng.next_float();
    const EdgeHierarchy::Strategy s = us < c_lights ? EdgeHierarchy::Lights : EdgeHierarchy::All;
    us = s == EdgeHierarchy::Lights ? us / c_lights : (us - c_lights) / c_all;
    const Edge* edges = scene_.edges().data();
    EdgeHierarchy::Choice choices[EdgeHierarchy::kMaxChoices];
    const int count = hierarchy_->sample(q, s, std::min(us, 0.99999994f), choices, &set == &wanted_ ? wanted_root_ : 0);
    for (int c = 0; c < count; ++c) {
        const EdgeHierarchy::Choice& choice = choices[c];
        const float ut = rng.next_float();
        const Edge& e = edges[choice.edge];
        const Mesh& m = scene_.meshes[size_t(e.mesh)];
        const Vec3f v0 = m.vertex(e.v0), v1 = m.vertex(e.v1);
        EdgePointSampler points;
        float t;
        // Strategy Lights' density matters only where it can pick the edge (choice.prob[1] > 0;
        // always so where it did): elsewhere the sampler skips the light part.
        const BoundsCone* cone = choice.prob[1] > 0.f ? q.cone : nullptr;
        const ArcPart* known = cone ? arcs.find(choice.edge, v0, v1) : nullptr;
        if (!(known ? points.setup(*known, q.lobe, cone) : points.setup(sp.p, v0, v1, q.lobe, cone, q.lights)) ||
            !points.sample(s, ut, t))
            continue;
        float pdf_all, pdf_lights;
        points.pdfs(t, cone != nullptr, pdf_all, pdf_lights);
        const float joint_all = choice.prob[0] * pdf_all, joint_lights = q.cone ? choice.prob[1] * pdf_lights : 0.f;
        const float mixture = c_all * joint_all + c_lights * joint_lights;
        if (!(mixture > 0.f) || !std::isfinite(mixture)) continue;
        // scale: the inverse of the mixture's density per unit length.
        const float scale = length(v1 - v0) / mixture;
        d_p += evaluate(choice.edge, t, scale, sp, wo, bsdf, bounces_left, weight, rng, sink, record);
    }
    return d_p;
}

Vec3f SecondaryEdges::evaluate(int32_t edge, float t, float scale, const SurfacePoint& sp, const Vec3f& wo,
                               const TBsdfParams<float>& bsdf, int bounces_left, const Vec3f& weight, Rng& rng,
                               GradSink& sink, std::vector<EdgeTerm>* record) const {
    Vec3f d_p(0.f);
    const Edge& e = scene_.edges()[size_t(edge)];
    const Mesh& m = scene_.meshes[size_t(e.mesh)];
    const Vec3f v0 = m.vertex(e.v0), v1 = m.vertex(e.v1);
    const Vec3f x = v0 + (v1 - v0) * t;
    // An edge in the plane of the surface at the shading point (its own triangle's, a coplanar
    // neighbour's) is seen only along grazing directions, where the surface itself is the
    // boundary and nothing changes as the edge moves within the plane: no contribution. (Tested
    // against the lift off the surface: within it, the two sides would see a difference of the
    // order of the lift alone.)
    const float lift = length(offset_ray_origin(sp.p, sp.p_error, sp.ng, sp.ng) - sp.p);
    if (std::abs(dot(v0 - sp.p, sp.ng)) <= lift && std::abs(dot(v1 - sp.p, sp.ng)) <= lift) return d_p;
    // Everything is measured from the origin the rays towards x leave from: p lifted off the
    // surface as spawn_ray lifts it. (Measured from p itself, at grazing angles the lift alone
    // can carry both rays past the same side of the edge.)
    const Vec3f p = spawn_ray(sp, x - sp.p).origin;
    const float dist = length(x - p);
    if (!(dist > 0.f)) return d_p;
    const Vec3f w = (x - p) / dist;
    EdgeEye eye;
    eye.origin = p;
    eye.step = kTouchStep;
    // A smooth edge is a discontinuity where it folds as seen from p, and elsewhere only where
    // the light reaching its faces can differ: the steps where the mesh shadows itself along it,
    // seen after a bounce (not at a last one, which sees emission only).
    if (e.kind == EdgeKind::Smooth && bounces_left == 0 && !is_fold(eye, m, e)) return d_p;
    // The plane through p and the edge, normal N = cross(v0 - p, v1 - p); degenerate when p lies
    // on the edge's line.
    const float n_len = cross_length(v0 - p, v1 - p);  // in range also where |N|^2 is not
    if (!(n_len > 1e-6f * length(v0 - p) * length(v1 - p))) return d_p;

    // The jump is the BSDF's value towards each side times the light arriving from there, both
    // found in the limit at x (w . N > 0: upper; edges/sides.h); none where x is hidden from p.
    // The BSDF is continuous across the edge (p's own surface, its horizon, was left out above).
    const Vec3f f = bsdf_eval_world(bsdf, sp.ns, wo, w);
    if (is_black(f)) return d_p;
    Ray ray;
    ray.origin = p;
    ray.dir = w;
    EdgeSide first_u, first_l;
    if (!edge_sides(scene_, eye, e, ray, t, dist, first_u, first_l)) return d_p;
    // A side evaluated off the edge (its surface touches it) sees the BSDF along its own ray.
    auto bsdf_towards = [&](const EdgeSide& side) {
        return !side.off_edge ? f : bsdf_eval_world(bsdf, sp.ns, wo, side.ray.dir);
    };
    const Vec3f f_u = bsdf_towards(first_u), f_l = bsdf_towards(first_l);
    RenderOptions rest = opt_;
    rest.max_bounces = bounces_left;
    rest.hide_emitters = false;  // these paths start after a bounce
    RayCounters counters;
    // Both sides' paths take the same numbers (their difference is what counts), from a stream
    // of their own: a copy of `rng` would give the next edge sample's paths these numbers
    // again, two places on.
    Rng rng_u = rng.split(), rng_l = rng_u;
    const Vec3f F_u = is_black(f_u) ? Vec3f(0.f) : f_u * trace_path(scene_, rest, first_u.ray, rng_u, counters, nullptr, &first_u);
    const Vec3f F_l = is_black(f_l) ? Vec3f(0.f) : f_l * trace_path(scene_, rest, first_l.ray, rng_l, counters, nullptr, &first_l);
    const Vec3f delta = F_u - F_l;
    // Arc length per unit edge length, over |N| (the side function's rate across the arc),
    // times `scale` (the inverse of the density per unit edge length, and the MIS weight).
    const Vec3f along = v1 - v0;
    const float arc = length(along - w * dot(w, along)) / (dist * length(along));
    EdgeTerm term;
    term.edge = edge;
    term.u = delta * (scale * arc / n_len);
    if (!std::isfinite(term.u.x + term.u.y + term.u.z) || is_black(term.u)) return d_p;
    term.g = edge_side_gradient(v0, v1, p, w);
    if (record) record->push_back(term);
    return apply(term, weight, sink);
}

template <class S>
TVec3<S> SecondaryEdges::send(const EdgeTerm& term, const S& s, GradSink& sink) const {
    const Edge& e = scene_.edges()[size_t(term.edge)];
    const EdgeSideGradient& g = term.g;
    if (size_t(e.mesh) < slots_.meshes.size() && slots_.meshes[size_t(e.mesh)].vertices.wanted()) {
        const GradSlot& vs = slots_.meshes[size_t(e.mesh)].vertices;
        sink.add3(vs, e.v0, s * g.d_e0.x, s * g.d_e0.y, s * g.d_e0.z);
        sink.add3(vs, e.v1, s * g.d_e1.x, s * g.d_e1.y, s * g.d_e1.z);
    }
    return g.d_o * s;
}

Vec3f SecondaryEdges::apply(const EdgeTerm& term, const Vec3f& weight, GradSink& sink) const {
    const float s = dot(weight, term.u);
    if (s == 0.f || !std::isfinite(s)) return Vec3f(0.f);
    return send(term, s, sink);
}

Vec3f SecondaryEdges::replay(const EdgeTerm* terms, size_t count, const Vec3f& weight, GradSink& sink) const {
    Vec3f d_p(0.f);
    for (size_t i = 0; i < count; ++i) d_p += apply(terms[i], weight, sink);
    return d_p;
}

AVec3 SecondaryEdges::replay_colours(const EdgeTerm* terms, size_t count, const Vec3f& weight, GradSink& sink) const {
    AVec3 d_p;
    for (size_t i = 0; i < count; ++i) {
        const EdgeTerm& term = terms[i];
        // As apply: s = weight . u, here one colour's channel at a time.
        Adj3 s(weight.x * term.u.x, weight.y * term.u.y, weight.z * term.u.z);
        for (float& v : s.v)
            if (!std::isfinite(v)) v = 0.f;
        if (!is_zero(s)) d_p += send(term, s, sink);
    }
    return d_p;
}

}  // namespace edgepath
