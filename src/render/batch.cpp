#include "render/batch.h"

#include <limits>
#include <memory>
#include <stdexcept>
#include <type_traits>

#include "render/embree_lanes.h"
#include "render/shade_lanes.h"

#if defined(__GNUC__)
#define EDGEPATH_ALWAYS_INLINE __attribute__((always_inline))
#else
#define EDGEPATH_ALWAYS_INLINE
#endif

namespace edgepath {

namespace {

static_assert(kLanes == lanes_of<RTCRay16>(), "the batches trace RTCRay16 packets");
static_assert(kBatchSize == kShadeBatch, "shade_lanes takes a batch's paths");

// With at most this many emitting meshes, a last vertex's continuation is first tested
// against their boxes (Scene::may_meet_emitter); with more, it is traced whatever its
// direction.
constexpr size_t kMaxEmitterBoxes = 8;

// Embree's packets, each with its lane mask.
struct alignas(64) RayHitPacket {
    RTCRayHit16 rh;
    alignas(64) int valid[kLanes];
};
struct alignas(64) RayPacket {
    RTCRay16 r;
    alignas(64) int valid[kLanes];
};

}  // namespace

// One path of the batch between bounces.
struct PathState {
    SurfacePoint sp;  // its current vertex
    Vec3f beta;       // throughput up to the vertex
    Vec3f dir;        // direction of the ray that found the vertex
    // The continuation chosen by the shading: the throughput past it, the BSDF sample's density
    // and whether it was smooth; its ray's index among the bounce's continuations.
    Vec3f next_beta;
    float pdf = 0.f;
    bool delta = false, goes_on = false;
    bool refract = false;  // (recorded paths) the BSDF sample's transmission
    int next = 0;
    int shadow_begin = 0, shadow_end = 0;  // its shadow rays of this bounce
    // (Recorded paths) the area light's sample gathered for the vectors: the point on the light
    // (LightSample::hit; for a triangle sampled in the vectors, its t is their distance).
    Hit light_hit;
};

// (Recorded paths) what a shadow ray's light sample leaves in the path's record where nothing
// hides it (trace_path's NeeRecord): its kind, MIS weight over density, direction and point.
struct ShadowRecord {
    ShadowKind kind = ShadowKind::Point;
    float scale = 0.f;
    Vec3f dir;
    Hit hit;
};

namespace {
// trace_path's push_vertex: the vertex `hit` found by the ray (origin, dir) with throughput beta.
void push_vertex(PathRecord& rec, const Hit& hit, const Vec3f& origin, const Vec3f& dir, const Vec3f& beta,
                 float emission_weight) {
    rec.vertices.emplace_back();
    PathVertexRecord& v = rec.vertices.back();
    v.hit = hit;
    v.origin = origin;
    v.dir = dir;
    v.beta = beta;
    v.emission_weight = emission_weight;
}
}  // namespace

struct PathBatch::Impl {
    const Scene& scene;
    const RenderOptions& opt;
    PathSettings settings;
    PathState paths[kBatchSize];  // path i: camera sample i of the batch
    int live[kBatchSize];         // the live paths, in batch order
    // A bounce's shadow rays: what each adds if nothing is in its way, and their packets.
    std::vector<Vec3f> shadow_value;
    std::vector<RayPacket> shadow;
    std::vector<ShadowRecord> shadow_record;  // (recorded paths) each shadow ray's light sample
    bool recording = false;                   // the paths of this trace() are recorded
    RayHitPacket next[kBatchSize / kLanes];  // a bounce's continuations
    // The plain vertices of a bounce (render/shade_lanes.h), their paths' places in `live`.
    // Per mesh, for its plain vertices, what is the same at every point: the specular (a
    // constant texture), and then whether it is black (no GGX lobe); the alpha (a constant
    // roughness); the diffuse reflectance (a constant texture, no vertex colours); with both
    // reflectances, the mask of its reflecting and the probability of the GGX lobe. The rest
    // is looked up path by path, as Scene::bsdf_params does.
    struct PlainMesh {
        // its material's vertices are plain: MaterialKind::Standard (the Lambertian lobe and
        // the GGX lobe where the specular is not black), or plastic (MaterialKind::Plastic, in
        // lanes of their own: shade_plastic_lanes), or a mirror (MaterialKind::Conductor:
        // shade_mirror_lanes)
        bool plain = false, plastic = false, mirror = false;
        bool flat = false;   // no normals, uvs or normal map: Scene::surface_point_base is its points'
        bool constant_specular = false, constant_alpha = false, constant = false;
        bool glossy = false;  // constant_specular, and the specular is not black
        Vec3f specular;
        float alpha = 0.f;
        Vec3f diffuse;
        bool fixed = false;  // constant and constant_specular: reflects and lobe_p hold
        float reflects = 0.f, lobe_p = 0.f;
        // The plastic's: its index (a constant ior) and whether it is rough (a constant roughness).
        bool constant_eta = false;
        float eta = 0.f;
        bool rough = false;
    };
    std::vector<PlainMesh> plain_mesh;
    // What the vectors take of an entry of scene.lights: whether they sample it (a triangle
    // sampled by area with a constant emission and no spot), and then its triangle, the
    // probability of its pick, its area, emission and sides. Kept for every entry where the
    // scene has few (a batch's tables are made for each tile), looked up path by path otherwise.
    struct LightEntry {
        bool in_vectors = false;
        int mesh = -1;
        int64_t prim = -1;
        TriangleData td;
        float pmf = 0.f, area = 0.f;
        Vec3f emission;
        float two_sided = 0.f;
    };
    static constexpr size_t kMaxLightEntries = 64;
    std::vector<LightEntry> light_entries;
    LightEntry looked_up_;  // the entry looked up last, without them (reused: not built per path)
    // A bounce's vertices shaded in vectors: their lanes, their paths' places in `live`, their
    // count and whether any has a GGX lobe (the standard material's).
    struct LaneGroup {
        ShadeLanes<kBatchSize> lanes;
        int plain[kBatchSize];
        int n = 0;
        bool glossy = false;
    };
    // (The plastic's only where the scene has a plastic: a batch is made, and its lanes
    // zeroed, for each tile.)
    LaneGroup standard_;
    std::unique_ptr<LaneGroup> plastic_, mirror_;

    Impl(const Scene& s, const RenderOptions& o) : scene(s), opt(o), settings(s, o) {
        for (const Mesh& m : scene.meshes) {
            PlainMesh pm;
            const Material& mat = scene.materials[size_t(m.material)];
            pm.plastic = mat.kind == MaterialKind::Plastic && mat.coat;
            pm.mirror = mat.kind == MaterialKind::Conductor;
            pm.plain = mat.kind == MaterialKind::Standard || pm.plastic || pm.mirror;
            pm.flat = !m.normals && !m.uvs && mat.normal_map.empty();
            // Scene::bsdf_params' values where they are constant.
            if (pm.plain && mat.specular.is_constant()) {
                pm.constant_specular = true;
                pm.specular = Vec3f::load(mat.specular.data);
                pm.glossy = !is_black(pm.specular);
            }
            if (pm.plain && mat.roughness.is_constant()) {
                pm.constant_alpha = true;
                pm.alpha = ggx_alpha(mat.roughness.data[0]);
            }
            if (pm.plain && mat.diffuse.is_constant() && !m.colors) {
                pm.constant = true;
                pm.diffuse = Vec3f::load(mat.diffuse.data);  // Scene::diffuse_reflectance's
            }
            if (pm.constant && pm.constant_specular) {
                pm.fixed = true;
                pm.reflects = plain_reflects(pm.diffuse, pm.specular);
                if (pm.glossy && !pm.plastic) pm.lobe_p = lobe_probability(pm.diffuse, pm.specular);
            }
            if (pm.plastic && mat.ior.is_constant()) {
                pm.constant_eta = true;
                pm.eta = mat.ior.data[0];
            }
            if (pm.plastic && pm.constant_alpha) pm.rough = mat.roughness.data[0] > 0.f;
            plain_mesh.push_back(pm);
            if (pm.plastic && !plastic_) plastic_ = std::make_unique<LaneGroup>();
            if (pm.mirror && !mirror_) mirror_ = std::make_unique<LaneGroup>();
        }
        if (scene.light_distribution.valid() && scene.lights.size() <= kMaxLightEntries) {
            light_entries.resize(scene.lights.size());
            for (size_t li = 0; li < scene.lights.size(); ++li) light_entry(int(li), light_entries[li]);
        }
        // At most one on the area lights, one on the environment and one a point light for
        // each path.
        const size_t max_shadow = size_t(kBatchSize) * (2 + scene.point_lights.size());
        shadow_value.resize(max_shadow);
        shadow_record.resize(max_shadow);
        shadow.resize((max_shadow + kLanes - 1) / kLanes);
        // What Embree only reads, once: the rays then take their extents only.
        for (RayPacket& pk : shadow) set_packet_constants(pk.r);
        for (RayHitPacket& pk : next) set_packet_constants(pk.rh.ray);
    }

    void trace(CameraSample* samples, int n, Vec3f* L, RayCounters& counters, PathRecord* records);
    // The mask of a plain vertex's reflecting (a reflectance with luminance above 0).
    static float plain_reflects(const Vec3f& diffuse, const Vec3f& specular) {
        return lane_mask(!(luminance(diffuse) + luminance(specular) <= 0.f));
    }
    // specular_lobe_probability (scene/bsdf.h) of a plain vertex.
    static float lobe_probability(const Vec3f& diffuse, const Vec3f& specular) {
        BsdfParams bp;
        bp.diffuse = diffuse;
        bp.specular = specular;
        return specular_lobe_probability(bp);
    }
    // Scene::surface_point(h), into sp.
    void surface_point(const Hit& h, SurfacePoint& sp) const {
        if (plain_mesh[size_t(h.mesh)].flat)
            scene.surface_point_base(h.mesh, h.prim, h.b1, h.b2, sp);
        else
            sp = scene.surface_point(h);
    }
    // Entry li of scene.lights for the vectors, into e.
    void light_entry(int li, LightEntry& e) const {
        const Scene::EmissiveTriangle& lt = scene.lights[size_t(li)];
        const Mesh& m = scene.meshes[size_t(lt.mesh)];
        e.in_vectors = lt.prim >= 0 && !m.spherical_triangle && !m.spot && m.emission.is_constant();
        if (!e.in_vectors) return;
        e.mesh = lt.mesh;
        e.prim = lt.prim;
        e.td = m.triangle_data[lt.prim];
        e.pmf = float(double(scene.light_distribution.pmf(li)));
        e.area = scene.light_triangle_area(m, lt.prim);
        e.emission = Vec3f::load(m.emission.data);
        e.two_sided = lane_mask(m.two_sided_emission);
    }
    // Puts live path j, at a plain vertex of material m, into the lanes (its random numbers
    // drawn in shade_vertex's order, its light picked and its environment sample taken).
    // False, with nothing drawn, for a light sample the vectors cannot take (an infinite
    // distance to the light): shade_vertex then shades the vertex. Plastic: the vertex is a
    // plastic's (into plastic_), otherwise the standard material's (into standard_).
    template <bool Plastic>
    bool gather_plain(int j, const Material& m, Rng& rng);
    // The same for a mirror's vertex (into mirror_): its specular, and shade_vertex's random
    // numbers drawn (a delta material samples no light).
    void gather_mirror(int j, const Material& m, Rng& rng);
    // Claims the next lane of `group` for live path j and puts the path's point, direction and
    // throughput there; returns the lane.
    int take_lane(LaneGroup& group, int j);
};

// Lane k of the three arrays a gets v.
static void set3(float (&a)[3][kBatchSize], int k, const Vec3f& v) {
    a[0][k] = v.x;
    a[1][k] = v.y;
    a[2][k] = v.z;
}

int PathBatch::Impl::take_lane(LaneGroup& group, int j) {
    const PathState& ps = paths[live[j]];
    const int k = group.n++;
    group.plain[k] = j;
    ShadeLanes<kBatchSize>& l = group.lanes;
    set3(l.p, k, ps.sp.p);
    set3(l.p_error, k, ps.sp.p_error);
    set3(l.ng, k, ps.sp.ng);
    set3(l.ns, k, ps.sp.ns);
    set3(l.dir, k, ps.dir);
    set3(l.beta, k, ps.beta);
    return k;
}

void PathBatch::Impl::gather_mirror(int j, const Material& mat, Rng& rng) {
    const PathState& ps = paths[live[j]];
    const PlainMesh& pm = plain_mesh[size_t(ps.sp.mesh)];
    const int k = take_lane(*mirror_, j);
    ShadeLanes<kBatchSize>& l = mirror_->lanes;
    set3(l.specular, k, pm.constant_specular ? pm.specular : eval_texture3(mat.specular, ps.sp.uv));
    l.two_sided[k] = lane_mask(mat.two_sided);
    l.light_on[k] = l.env_on[k] = lane_mask(false);
    // shade_vertex's: three for the lights, two more for the sky where the scene has both,
    // three for the BSDF's sample (the mirror uses none).
    for (int i = settings.both_lights ? 8 : 6; i > 0; --i) rng.next_float();
}

template <bool Plastic>
bool PathBatch::Impl::gather_plain(int j, const Material& mat, Rng& rng) {
    const Rng start = rng;
    const PathState& ps = paths[live[j]];
    const PlainMesh& pm = plain_mesh[size_t(ps.sp.mesh)];
    LaneGroup& group = Plastic ? *plastic_ : standard_;
    const int k = take_lane(group, j);
    ShadeLanes<kBatchSize>& l = group.lanes;
    auto put3 = [k](float (&a)[3][kBatchSize], const Vec3f& v) { set3(a, k, v); };
    // Scene::bsdf_params' reflectances and alpha, and the GGX lobe's probability.
    const Vec3f diffuse = pm.constant ? pm.diffuse : scene.diffuse_reflectance(ps.sp);
    put3(l.diffuse, diffuse);
    const Vec3f specular = pm.constant_specular ? pm.specular : eval_texture3(mat.specular, ps.sp.uv);
    const bool glossy = pm.constant_specular ? pm.glossy : !is_black(specular);
    if constexpr (Plastic) {
        // The plastic's (Scene::bsdf_params): its coating, index and roughness, and the means
        // of its reflectances that choose its lobe (plastic_coat_probability).
        put3(l.specular, specular);
        float roughness = 0.f;
        if (!pm.constant_alpha) roughness = eval_texture1(mat.roughness, ps.sp.uv);
        l.alpha[k] = pm.constant_alpha ? pm.alpha : ggx_alpha(roughness);
        l.rough[k] = lane_mask(pm.constant_alpha ? pm.rough : roughness > 0.f);
        l.eta[k] = pm.constant_eta ? pm.eta : eval_texture1(mat.ior, ps.sp.uv);
        const CoatTable* coat = mat.coat.get();
        l.coat[k] = coat;
        l.coat_r[k] = coat->r;
        l.coat_smooth[k] = lane_mask(coat->smooth);
        l.coat_lobe[k] = lane_mask(!coat->smooth && !is_black(specular));
        l.nonlinear[k] = lane_mask(mat.nonlinear);
        l.ks[k] = plastic_mean(specular);
        l.kd[k] = plastic_mean(diffuse);
    } else {
        l.has_specular[k] = lane_mask(glossy);
        if (glossy) {
            group.glossy = true;
            put3(l.specular, specular);
            l.alpha[k] = pm.constant_alpha ? pm.alpha : ggx_alpha(eval_texture1(mat.roughness, ps.sp.uv));
            l.lobe_p[k] = pm.fixed ? pm.lobe_p : lobe_probability(diffuse, specular);
        }
    }
    l.two_sided[k] = lane_mask(mat.two_sided);
    l.reflects[k] = pm.fixed ? pm.reflects : plain_reflects(diffuse, specular);

    const float ul0 = rng.next_float(), ul1 = rng.next_float(), ul2 = rng.next_float();
    float ue1 = ul1, ue2 = ul2;
    if (settings.both_lights) {
        ue1 = rng.next_float();
        ue2 = rng.next_float();
    }
    const float ub0 = rng.next_float();  // the lobe's choice (the diffuse lobe the only one without GGX)
    if (glossy || Plastic) l.u_lobe[k] = ub0;
    const float ub1 = rng.next_float();
    l.disk[0][k] = ub1;
    l.disk[1][k] = rng.next_float();

    // Scene::sample_area_light: a triangle picked by power and sampled by area, with a
    // constant emission and no spot, is sampled in the vectors; any other light here, its
    // sample handed to them whole.
    l.light_on[k] = lane_mask(false);
    l.light_given[k] = lane_mask(false);
    if (settings.use_nee && scene.light_distribution.valid()) {
        float u;
        const int li = scene.pick_light(ul0, u);
        if (light_entries.empty()) light_entry(li, looked_up_);
        const LightEntry& e = light_entries.empty() ? looked_up_ : light_entries[size_t(li)];
        if (e.in_vectors) {
            const Vec2f b = square_to_triangle(ul1, ul2);
            l.b1[k] = b.x;
            l.b2[k] = b.y;
            put3(l.v0, e.td.v0);
            put3(l.v1, e.td.v1);
            put3(l.v2, e.td.v2);
            put3(l.light_ng, e.td.ng);
            l.edge[k] = e.td.largest_edge;
            l.pmf[k] = e.pmf;
            l.area[k] = e.area;
            put3(l.emission, e.emission);
            l.two_sided_emission[k] = e.two_sided;
            l.light_on[k] = lane_mask(true);
            if (recording) {
                Hit& h = paths[live[j]].light_hit;
                h.mesh = e.mesh;
                h.prim = e.prim;
                h.b1 = b.x;
                h.b2 = b.y;
            }
        } else {
            LightSample ls;
            if (scene.sample_area_light(ps.sp.p, ul0, ul1, ul2, ls)) {
                if (!std::isfinite(ls.dist)) {  // shadow_ray would not aim at a point
                    rng = start;
                    --group.n;
                    return false;
                }
                put3(l.given_dir, ls.dir);
                l.given_pdf[k] = ls.pdf;
                put3(l.given_radiance, ls.radiance);
                put3(l.given_p, ls.p);
                put3(l.given_p_error, ls.p_error);
                put3(l.given_ng, ls.ng);
                l.light_on[k] = l.light_given[k] = lane_mask(true);
                if (recording) paths[live[j]].light_hit = ls.hit;
            }
        }
    }
    l.env_on[k] = lane_mask(false);
    if (settings.use_nee && settings.use_env) {
        LightSample ls;
        const bool env = scene.sample_env(ue1, ue2, ls, settings.env_compensated);
        l.env_on[k] = lane_mask(env);
        if (env) {
            put3(l.env_dir, ls.dir);
            put3(l.env_radiance, ls.radiance);
            l.env_pdf[k] = ls.pdf;
        }
    }
    return true;
}

PathBatch::PathBatch(const Scene& scene, const RenderOptions& opt) : impl_(new Impl(scene, opt)) {}
PathBatch::~PathBatch() = default;

void PathBatch::trace(CameraSample* samples, int n, Vec3f* L, RayCounters& counters, PathRecord* records) {
    impl_->trace(samples, n, L, counters, records);
}

// trace_path (render/path.cpp) for n paths at once: the same operations, path by path, in the
// same order; only the rays are traced between the steps, in packets.
void PathBatch::Impl::trace(CameraSample* samples, int n, Vec3f* L, RayCounters& counters, PathRecord* records) {
    if (records && !opt.replayable)
        throw std::logic_error("PathBatch: recorded paths need replayable options (trace_path's recorded settings)");
    recording = records != nullptr;
    const RTCScene rtc = scene.bvh(settings.tracing);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;

    // The camera rays' first vertices.
    int nlive = 0;
    for (int i = 0; i < n; ++i) {
        const CameraSample& cs = samples[i];
        L[i] = Vec3f(0.f);
        PathRecord* const rec = records ? records + i : nullptr;
        if (rec) {
            rec->vertices.clear();
            rec->camera_missed = rec->escaped = false;
            rec->emitters_hidden = opt.hide_emitters;
        }
        if (cs.outside) {
            // Outside the image: black, nothing to differentiate.
            if (rec) rec->camera_missed = rec->emitters_hidden = true;
            continue;
        }
        ++counters.camera;
        if (!cs.first.found) {
            if (scene.has_envmap && !opt.hide_emitters) L[i] += scene.envmap.eval(cs.ray.dir);
            if (rec) rec->camera_missed = true;
            continue;
        }
        if (rec) push_vertex(*rec, cs.first.hit, cs.ray.origin, cs.ray.dir, Vec3f(1.f), opt.hide_emitters ? 0.f : 1.f);
        const bool emitter = scene.meshes[size_t(cs.first.hit.mesh)].is_emitter();
        if (opt.max_bounces == 0 && !emitter) continue;  // no surface point needed
        PathState& ps = paths[i];
        surface_point(cs.first.hit, ps.sp);
        if (!opt.hide_emitters && emitter) L[i] += scene.emitted(ps.sp, -cs.ray.dir);
        if (opt.max_bounces == 0) continue;
        ps.beta = Vec3f(1.f);
        ps.dir = cs.ray.dir;
        live[nlive++] = i;
    }

    for (int bounce = 0; nlive > 0; ++bounce) {
        // Shading: each live path's BSDF sample, its continuation's ray, its light samples and
        // what each would add.
        int nshadow = 0, nnext = 0;
        standard_.n = 0;
        if (plastic_) plastic_->n = 0;
        if (mirror_) mirror_->n = 0;
        standard_.glossy = false;
        // Path ps's continuation and a shadow ray (with what it adds if nothing hides it), into
        // the bounce's packets.
        // (`count`: nnext or nshadow, or a copy of it kept in a register.)
        auto add_next = [&](int& count, PathState& ps, const Ray& r, const Vec3f& next_beta, float pdf, bool delta) {
            ps.goes_on = true;
            ps.refract = false;
            ps.next_beta = next_beta;
            ps.pdf = pdf;
            ps.delta = delta;
            ps.next = count;
            set_ray_extent(next[count / kLanes].rh.ray, count % kLanes, r);
            ++count;
        };
        auto add_shadow = [&](int& count, const Ray& r, const Vec3f& value) {
            set_ray_extent(shadow[size_t(count / kLanes)].r, count % kLanes, r);
            shadow_value[size_t(count)] = value;
            ++count;
        };
        for (int j = 0; j < nlive; ++j) {
            PathState& ps = paths[live[j]];
            const PlainMesh& pm = plain_mesh[size_t(ps.sp.mesh)];
            if (pm.plain) {
                const Material& mat = scene.materials[size_t(scene.meshes[size_t(ps.sp.mesh)].material)];
                Rng& rng = samples[live[j]].rng;
                if (pm.mirror) {
                    gather_mirror(j, mat, rng);
                    continue;
                }
                if (pm.plastic ? gather_plain<true>(j, mat, rng) : gather_plain<false>(j, mat, rng)) continue;
            }
            ps.goes_on = false;
            ps.shadow_begin = nshadow;
            const bool delta = shade_vertex(
                scene, settings, ps.sp, ps.dir, ps.beta, samples[live[j]].rng, counters,
                [&](const Ray& r, const BsdfSample& bs, const Vec3f& next_beta) {
                    add_next(nnext, ps, r, next_beta, bs.pdf, bs.delta);
                    ps.refract = bs.refract;
                },
                [&](ShadowKind kind, const Ray& r, const Vec3f& value, const LightSample* ls, float scale) {
                    if (recording) {
                        ShadowRecord& sr = shadow_record[size_t(nshadow)];
                        sr.kind = kind;
                        sr.scale = scale;
                        if (ls) {
                            sr.dir = ls->dir;
                            sr.hit = ls->hit;
                        }
                    }
                    add_shadow(nshadow, r, value);
                });
            ps.shadow_end = nshadow;
            if (recording) records[live[j]].vertices.back().point_lights = !delta;
        }
        // The plain vertices, a vector of them at a time (the standard material's, then the
        // plastic's); then their rays into the packets.
        // (is_plastic, is_mirror: std::true_type for plastic_ or mirror_, whose continuations
        // may be a delta lobe's; a mirror's vertex has no light samples. Inlined, each, and the
        // ray counts copied in and out: the compiler then keeps them in registers, as it did
        // with one group.)
        auto read_back = [&](LaneGroup* group, auto is_plastic, auto is_mirror) EDGEPATH_ALWAYS_INLINE {
            constexpr bool plastic = decltype(is_plastic)::value, mirror = decltype(is_mirror)::value;
            if (group->n == 0) return;
            ShadeLanes<kBatchSize>& l = group->lanes;
            int shadows = nshadow, nexts = nnext;
            if constexpr (plastic)
                shade_plastic_lanes(l, group->n, settings.mis);
            else if constexpr (mirror)
                shade_mirror_lanes(l, group->n);
            else
                shade_lanes(l, group->n, settings.mis, group->glossy);
            auto get3 = [](const float (&a)[3][kBatchSize], int k) { return Vec3f(a[0][k], a[1][k], a[2][k]); };
            for (int k = 0; k < group->n; ++k) {
                PathState& ps = paths[live[group->plain[k]]];
                ps.sp.ns = get3(l.ns, k);
                ps.goes_on = false;
                ps.shadow_begin = shadows;
                Ray r;
                if (lane_set(l.goes_on, k)) {
                    ++counters.bounce;
                    r.origin = get3(l.next_origin, k);
                    r.dir = get3(l.next_dir, k);
                    add_next(nexts, ps, r, get3(l.next_beta, k), l.next_pdf[k], (plastic || mirror) && lane_set(l.next_delta, k));
                }
                if (recording) records[live[group->plain[k]]].vertices.back().point_lights = !mirror;
                if (lane_set(l.light_on, k)) {
                    if (recording) {
                        ShadowRecord& sr = shadow_record[size_t(shadows)];
                        sr.kind = ShadowKind::Area;
                        sr.scale = l.light_scale[k];
                        sr.dir = get3(l.light_to, k);
                        sr.hit = ps.light_hit;
                        if (!lane_set(l.light_given, k)) sr.hit.t = l.light_dist[k];
                    }
                    r.origin = get3(l.light_origin, k);
                    r.dir = get3(l.light_dir, k);
                    r.tmax = l.light_tmax[k];
                    add_shadow(shadows, r, get3(l.light_value, k));
                }
                if (lane_set(l.env_on, k)) {
                    r.origin = get3(l.env_origin, k);
                    r.dir = get3(l.env_dir, k);
                    r.tmax = std::numeric_limits<float>::infinity();
                    if (recording) {
                        ShadowRecord& sr = shadow_record[size_t(shadows)];
                        sr.kind = ShadowKind::Env;
                        sr.scale = l.env_scale[k];
                        sr.dir = r.dir;
                        sr.hit = Hit();
                    }
                    add_shadow(shadows, r, get3(l.env_value, k));
                }
                counters.shadow += uint64_t(shadows - ps.shadow_begin);
                // The point lights, path by path (shade_vertex's own code), with Scene::bsdf_params'
                // values.
                if (!mirror && !scene.point_lights.empty()) {
                    const Frame frame(ps.sp.ns);
                    BsdfParams bp;
                    bp.diffuse = get3(l.diffuse, k);
                    bp.two_sided = lane_set(l.two_sided, k);
                    if constexpr (plastic) {
                        bp.specular = get3(l.specular, k);
                        bp.alpha = l.alpha[k];
                        bp.kind = MaterialKind::Plastic;
                        bp.eta = l.eta[k];
                        bp.rough = lane_set(l.rough, k);
                        bp.coat = l.coat[k];
                        bp.nonlinear = lane_set(l.nonlinear, k);
                    } else {
                        if (lane_set(l.has_specular, k)) {
                            bp.specular = get3(l.specular, k);
                            bp.alpha = l.alpha[k];
                        } else {
                            bp.specular = Vec3f(0.f);
                        }
                        bp.kind = MaterialKind::Standard;
                    }
                    point_light_samples(scene, ps.sp, bp, frame, frame.to_local(-ps.dir), ps.beta, counters,
                                        [&](ShadowKind, const Ray& shadow_ray, const Vec3f& value, const LightSample*,
                                            float) {
                                            if (recording) shadow_record[size_t(shadows)].kind = ShadowKind::Point;
                                            add_shadow(shadows, shadow_ray, value);
                                        });
                }
                ps.shadow_end = shadows;
            }
            nshadow = shadows;
            nnext = nexts;
        };
        read_back(&standard_, std::false_type{}, std::false_type{});
        if (plastic_) read_back(plastic_.get(), std::true_type{}, std::false_type{});
        if (mirror_) read_back(mirror_.get(), std::false_type{}, std::true_type{});

        // The continuations, each hit's triangle fetched while the packets after it are traced;
        // then the shadow rays. A last vertex's continuation counts only where it meets an
        // emitter: without an environment, one that misses every emitter's box is not traced
        // (it reads as one that left the scene, which adds nothing then).
        const bool last = bounce + 1 >= opt.max_bounces;
        // (Recorded paths keep every last vertex, as trace_path records them.)
        const bool boxed = !recording && last && !scene.has_envmap && scene.emitter_boxes.size() <= kMaxEmitterBoxes;
        for (int p = 0; p * kLanes < nnext; ++p) {
            RayHitPacket& pk = next[p];
            const int m = std::min(kLanes, nnext - p * kLanes);
            close_packet(pk.rh.ray, pk.valid, m);
            clear_hits(pk.rh);
            if (boxed) {
                const RTCRay16& r = pk.rh.ray;
                const float* const origin[3] = {r.org_x, r.org_y, r.org_z};
                const float* const dir[3] = {r.dir_x, r.dir_y, r.dir_z};
                if (scene.may_meet_emitter(origin, dir, m, pk.valid) == 0) continue;
            }
            rtcIntersect16(pk.valid, rtc, &ctx, &pk.rh);
            Hit h;
            for (int i = 0; i < m; ++i)
                if (lane_hit(scene, pk.rh, i, h)) scene.prefetch(h);
        }
        for (int p = 0; p * kLanes < nshadow; ++p) {
            RayPacket& pk = shadow[size_t(p)];
            close_packet(pk.r, pk.valid, std::min(kLanes, nshadow - p * kLanes));
            rtcOccluded16(pk.valid, rtc, &ctx, &pk.r);
        }

        // Each path adds what it sees, in trace_path's order: its light samples that nothing
        // hides (an occluded ray's tfar is -inf), then the light its continuation meets.
        int kept = 0;
        for (int j = 0; j < nlive; ++j) {
            const int i = live[j];
            PathState& ps = paths[i];
            Vec3f& Li = L[i];
            PathRecord* const rec = records ? records + i : nullptr;
            for (int k = ps.shadow_begin; k < ps.shadow_end; ++k) {
                if (shadow[size_t(k / kLanes)].r.tfar[k % kLanes] < 0.f) continue;
                Li += shadow_value[size_t(k)];
                const ShadowRecord& sr = shadow_record[size_t(k)];
                if (!rec || sr.kind == ShadowKind::Point) continue;
                PathVertexRecord& v = rec->vertices.back();
                NeeRecord& nr = sr.kind == ShadowKind::Area ? v.nee_area : v.nee_env;
                nr.used = true;
                nr.dir = sr.dir;
                nr.scale = sr.scale;
                nr.hit = sr.hit;
            }
            if (!ps.goes_on) continue;
            const RayHitPacket& pk = next[ps.next / kLanes];
            const int lane = ps.next % kLanes;
            const Vec3f beta = ps.beta = ps.next_beta;
            const Vec3f dir(pk.rh.ray.dir_x[lane], pk.rh.ray.dir_y[lane], pk.rh.ray.dir_z[lane]);
            if (rec) {
                PathVertexRecord& v = rec->vertices.back();
                v.next = true;
                v.next_delta = ps.delta;
                v.next_refract = ps.refract;
                v.next_dir = dir;
                v.next_inv_pdf = 1.f / ps.pdf;
            }
            Vec3f Le;
            float w;
            Hit hit;
            if (!lane_hit(scene, pk.rh, lane, hit)) {
                if (escaped_light(scene, settings, dir, ps.pdf, ps.delta, Le, w)) {
                    Li += beta * Le * w;
                    if (rec) {
                        rec->escaped = true;
                        rec->escape_weight = w;
                    }
                }
                continue;
            }
            const Vec3f origin(pk.rh.ray.org_x[lane], pk.rh.ray.org_y[lane], pk.rh.ray.org_z[lane]);
            // A path's last vertex matters only for light it sees there.
            if (last && !(continuation_counts(settings, ps.delta) && scene.meshes[size_t(hit.mesh)].is_emitter())) {
                if (rec) push_vertex(*rec, hit, origin, dir, beta, 0.f);
                continue;
            }
            const Vec3f prev_p = ps.sp.p;
            surface_point(hit, ps.sp);
            ps.dir = dir;
            float emission_weight = 0.f;
            if (met_emission(scene, settings, hit.mesh, prev_p, ps.sp, dir, ps.pdf, ps.delta, Le, w)) {
                emission_weight = w;
                Li += beta * Le * w;
            }
            if (rec) push_vertex(*rec, hit, origin, dir, beta, emission_weight);
            if (!last) live[kept++] = i;
        }
        nlive = kept;
    }
}

}  // namespace edgepath
