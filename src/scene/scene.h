// The scene as the kernels see it: validated views over the caller's arrays, an Embree BVH, and
// the light-sampling distributions. Built by build_scene(); update() points it at a new
// description of the scene and rebuilds only what changed, so that it lives across calls.
#pragma once
#include <algorithm>
#include <cstdint>
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>
#include <embree3/rtcore.h>
#include "math/frame.h"
#include "math/ray.h"
#include "scene/edges.h"
#include "scene/filter.h"
#include "sampling/spherical_triangle.h"
#include "sampling/distribution.h"
#include "scene/bsdf.h"
#include "scene/camera.h"
#include "scene/desc.h"
#include "scene/envmap.h"
#include "scene/geometry.h"
#include "scene/spot.h"
#include "scene/texture.h"

namespace edgepath {

// Embree's ray for `ray`; for intersection queries, the RTCRayHit with no hit yet.
inline RTCRay to_rtc_ray(const Ray& ray) {
    RTCRay r;
    r.org_x = ray.origin.x;
    r.org_y = ray.origin.y;
    r.org_z = ray.origin.z;
    r.dir_x = ray.dir.x;
    r.dir_y = ray.dir.y;
    r.dir_z = ray.dir.z;
    r.tnear = ray.tmin;
    r.tfar = ray.tmax;
    r.mask = 0xFFFFFFFFu;
    r.flags = 0;
    r.time = 0.f;
    r.id = 0;
    return r;
}
inline RTCRayHit to_rtc_ray_hit(const Ray& ray) {
    RTCRayHit rh;
    rh.ray = to_rtc_ray(ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    return rh;
}

// What a surface point needs of a triangle that depends on the triangle alone, kept triangle by
// triangle (Mesh::triangle_data): 52 bytes a triangle, found without the index array.
struct TriangleData {
    Vec3f v0, v1, v2;  // its vertices 0, 1, 2, as the mesh's `vertices` holds them
    Vec3f ng;          // cross_normal(v1 - v0, v2 - v0): normalize(cross(v1 - v0, v2 - v0))
    float largest_edge = 0.f;  // triangle_largest_edge(v0, v1, v2) (math/ray.h)
};

// Meshes sampled by spherical triangles with at most this many triangles pick one by the
// solid angle it shows the shading point (each sample weighs them all); larger ones by power.
constexpr int64_t kSphericalPickMax = 16;

struct Mesh {
    const float* vertices = nullptr;
    int64_t num_vertices = 0;
    const int32_t* indices = nullptr;
    int64_t num_triangles = 0;
    const float* uvs = nullptr;
    const int32_t* uv_indices = nullptr;
    const float* normals = nullptr;
    const int32_t* normal_indices = nullptr;
    const float* colors = nullptr;  // (num_vertices, 3), or null
    int material = 0;
    Texture emission;
    bool two_sided_emission = false;
    bool spot = false;         // emission scaled by the spot profile spot_profile (scene/spot.h)
    float spot_profile[5] = {0, 0, 1, 0, 0};
    bool solid_angle = false;  // sampled by the solid angle of its bounding sphere (desc.h)
    Vec3f sphere_center;       // that sphere, when solid_angle (set by Scene::build_lights)
    float sphere_radius = 0.f;
    bool spherical_triangle = false;  // triangles sampled by their solid angle (desc.h)
    // With at most kSphericalPickMax triangles: one light entry for the mesh, its triangle
    // picked by the solid angle each shows the shading point (set by Scene::build_lights).
    bool spherical_by_mesh = false;
    int64_t light_offset = -1;  // index of triangle 0 in Scene::lights, -1 if not emissive
    int64_t num_degenerate = 0; // triangles skipped as degenerate (is_degenerate)
    // Each triangle's TriangleData (Scene::surface_point reads a hit's there). Owned by the
    // scene, kept up to date by Scene::update.
    const TriangleData* triangle_data = nullptr;

    Vec3f vertex(int64_t i) const { return Vec3f::load(vertices + 3 * i); }
    // cross(v1 - v0, v2 - v0) of triangle f: the face normal (by the winding), not normalised.
    Vec3f face_normal(int64_t f) const {
        const int32_t* t = indices + 3 * f;
        const Vec3f p0 = vertex(t[0]);
        return cross(vertex(t[1]) - p0, vertex(t[2]) - p0);
    }
    // Its unit normal as the scene keeps it (TriangleData::ng): cross_normal of those edges.
    Vec3f unit_face_normal(int64_t f) const {
        const int32_t* t = indices + 3 * f;
        const Vec3f p0 = vertex(t[0]);
        return cross_normal(vertex(t[1]) - p0, vertex(t[2]) - p0);
    }
    bool is_emitter() const { return !emission.empty(); }
    // The vertex colour at barycentrics (b1, b2) of triangle f; 1 without colours.
    Vec3f color(int64_t f, float b1, float b2) const {
        if (!colors) return Vec3f(1.f);
        const int32_t* t = indices + 3 * f;
        return Vec3f::load(colors + 3 * int64_t(t[0])) * (1.f - b1 - b2) + Vec3f::load(colors + 3 * int64_t(t[1])) * b1 +
               Vec3f::load(colors + 3 * int64_t(t[2])) * b2;
    }
    // Area of triangle f (the lights' areas: Scene::build_lights).
    float triangle_area(int64_t f) const {
        const int32_t* t = indices + 3 * f;
        const Vec3f a = vertex(t[0]), b = vertex(t[1]), c = vertex(t[2]);
        return 0.5f * cross_length(b - a, c - a);
    }
    // Too thin to have a normal (scene/geometry.h): skipped by the BVH, the lights and the edges.
    bool is_degenerate(int64_t f) const {
        const int32_t* t = indices + 3 * f;
        return is_degenerate_triangle(vertex(t[0]), vertex(t[1]), vertex(t[2]));
    }
};

struct Material {
    Texture diffuse, specular, roughness;
    Texture ior;  // Dielectric and Plastic only
    Texture normal_map;  // empty: none
    MaterialKind kind = MaterialKind::Standard;
    bool two_sided = false;
    bool nonlinear = false;  // Plastic
    std::shared_ptr<const CoatTable> coat;  // Plastic: the coating's transmittance
};

struct Hit {
    int mesh = -1;
    int64_t prim = -1;
    float b1 = 0.f, b2 = 0.f;  // barycentrics of vertices 1 and 2
    float t = 0.f;
};

struct SurfacePoint {
    Vec3f p;
    Vec3f p_error;  // bound on p's rounding error, per component (math/ray.h)
    Vec3f ng;  // geometric normal, cross(v1 - v0, v2 - v0) normalised
    Vec3f ns;  // shading normal (interpolated normals, or ng; then the material's normal map)
    Vec2f uv;  // interpolated uvs, or the barycentrics (b1, b2) when the mesh has none
    int mesh = -1;
    int64_t prim = -1;
    float b1 = 0.f, b2 = 0.f;
};

struct LightSample {
    Vec3f dir;           // from the shading point towards the light, normalised
    float dist = 0.f;    // infinity for the environment
    Vec3f radiance;      // emitted radiance towards the shading point
    float pdf = 0.f;     // solid angle, including the choice of the triangle
    Hit hit;             // the point on an area light (mesh, triangle, barycentrics)
    Vec3f p, p_error, ng;  // that point, its error bound and geometric normal (area lights)
};

// A ray leaving the surface at sp in direction d.
inline Ray spawn_ray(const SurfacePoint& sp, const Vec3f& d) { return spawn_ray(sp.p, sp.p_error, sp.ng, d); }

// The shadow ray from sp towards the light sample ls: to its point on an area light, or along
// its direction for the environment.
inline Ray shadow_ray(const SurfacePoint& sp, const LightSample& ls) {
    if (!std::isfinite(ls.dist)) return spawn_ray(sp, ls.dir);
    return spawn_ray_to(sp.p, sp.p_error, sp.ng, ls.p, ls.p_error, ls.ng);
}

class EdgeHierarchy;

// Which of the scene's two BVHs a query traces. Exact: Embree's robust mode, watertight (a ray
// through an edge shared by two triangles meets one of them), for the edge samples' side rays
// and every path a gradient pass traces or retraces. Fast: Embree's default intersection, for
// images no gradient follows (RenderOptions::replayable false, render/path.h tracing_of): 9%
// less CPU time on the Cornell box, but a ray aimed at a shared edge may slip through by a
// rounding (measured on a flat grid of quads: 17% of the rays aimed at points of shared edges,
// and 5 in 1.35 million aimed at random points; docs/gradients.md), as in Mitsuba, which asks
// for no robust mode. Each is built on its first use, so a scene that only makes images holds
// the fast one alone, and one that only takes gradients the exact one alone.
enum class Tracing { Exact, Fast };

class Scene {
public:
    ~Scene();
    Scene(const Scene&) = delete;
    Scene& operator=(const Scene&) = delete;

    // Validates (std::invalid_argument naming the field) and builds.
    static std::shared_ptr<Scene> build(const SceneDesc& desc);

    // Validates `desc` and points the scene at it (as build() would: afterwards the scene keeps
    // pointers into the memory `desc` views), rebuilding only what its contents changed, found
    // by comparing them with copies kept from the last build: the Embree BVH and the edge list
    // when the topology changes (mesh count, vertex counts, the index arrays, whether uvs and
    // normals are given); the edge list alone when uvs, normals or vertex colours change; an Embree refit when only vertex positions move (the first time, a
    // build of a refittable BVH; a build too when a triangle becomes degenerate or stops being
    // one); nothing for materials, textures, emission, lights, the environment and the camera,
    // which are only views. Returns what it did: Built, the BVHs dropped, each built anew on
    // its first use (bvh()); Refit, those held refitted, each on its first use. Not
    // thread-safe: no other call may use the scene meanwhile. If it throws, the scene must not
    // be used until an update succeeds.
    enum class Update { Built, Refit, Reused };
    Update update(const SceneDesc& desc);
    struct BuildStats {
        // BVHs built (each kind of Tracing a call uses, on its first use after a Built update)
        // and refitted (on a BVH's first use after a Refit update); update() calls that
        // changed nothing the BVHs depend on.
        uint64_t builds = 0, refits = 0, reuses = 0;
    };
    BuildStats build_stats() const {
        std::lock_guard<std::mutex> lock(bvh_mutex_);
        return stats_;
    }
    // Another view of the same scene: validates `camera` and replaces the camera, its film and
    // crop window (nothing else depends on them). Not thread-safe, as update().
    void set_camera(const CameraDesc& camera);

    Camera camera;
    TCameraParams<float> camera_params;  // the same camera, as differentiable parameters
    PixelFilter filter;
    int crop_x = 0, crop_y = 0, out_width = 0, out_height = 0;
    std::vector<Mesh> meshes;
    std::vector<Material> materials;
    // Whether mesh m is black seen from behind its faces (from the side opposite to their
    // geometric normals, where the shading normal is bent away from the viewer): a one-sided
    // material (glass is two-sided) and no emission from the back.
    bool dark_behind(const Mesh& m) const {
        return !materials[size_t(m.material)].two_sided && !(m.is_emitter() && m.two_sided_emission);
    }
    bool has_envmap = false;
    Envmap envmap;

    // A light to pick: a triangle, or (prim -1) a whole mesh sampled by solid angle.
    struct EmissiveTriangle {
        int mesh;
        int64_t prim;
        float area;
    };
    std::vector<EmissiveTriangle> lights;
    // A box around each emitting mesh's triangles, a little larger (set by build_lights): a ray
    // that meets none of them meets no emitter.
    struct Box {
        Vec3f lo, hi;
    };
    std::vector<Box> emitter_boxes;
    // For rays i < n from (origin[0][i], origin[1][i], origin[2][i]) along dir[.][i] (t >= 0):
    // may[i] = -1 where the ray may meet an emitter, 0 only where it misses every box of
    // emitter_boxes (Embree's lane masks); returns how many may.
    int may_meet_emitter(const float* const origin[3], const float* const dir[3], int n, int* may) const;
    bool may_meet_emitter(const Vec3f& origin, const Vec3f& dir) const {
        const float o[3] = {origin.x, origin.y, origin.z}, d[3] = {dir.x, dir.y, dir.z};
        const float* const op[3] = {o, o + 1, o + 2};
        const float* const dp[3] = {d, d + 1, d + 2};
        int may = 0;
        return may_meet_emitter(op, dp, 1, &may) > 0;
    }
    // Delta lights (desc.h): next-event estimation only, every one at every vertex.
    std::vector<PointLightDesc> point_lights;
    Distribution1D light_distribution;
    // The environment has light to sample (not black); whether a render samples it is
    // env_nee's decision (render/path.h).
    bool env_sampled = false;

    bool intersect(const Ray& ray, Hit& hit, Tracing tracing = Tracing::Exact) const;
    // The first hit on anything but faces f0 and f1 of mesh `mesh` (-1: none), however close to
    // theirs: a surface meeting the ray where they do is found, which stepping the ray's start
    // past their hit cannot do (edges/sides.h: a floor through a wall's lower edge).
    bool intersect_excluding(const Ray& ray, int mesh, int64_t f0, int64_t f1, Hit& hit) const;
    bool occluded(const Ray& ray, Tracing tracing = Tracing::Exact) const;
    // Embree's intersectors return barycentrics of 0 where twice the triangle's area seen
    // across the ray (|U + V + W|, in the scene's units squared) is below 1e-18: edges below
    // about 5e-10 units, or a triangle seen almost edge-on; the hit itself and its t are right.
    // Every hit taken from Embree passes here: one with b1 = b2 = 0 has its barycentrics solved
    // again in double (clamped into the triangle), so that a tiny scene's paths leave from
    // where its rays meet it and not from a corner.
    void settle_hit(const Vec3f& origin, const Vec3f& dir, Hit& hit) const {
        if (hit.b1 == 0.f && hit.b2 == 0.f) resolve_barycentrics(origin, dir, hit);
    }

    SurfacePoint surface_point(int mesh, int64_t prim, float b1, float b2) const;
    // What surface_point sets of every point, into sp: its triangle, barycentrics, point, the
    // point's error bound and the geometric normal; and the shading normal and uv of a mesh
    // without normals and uvs (ng, and the barycentrics). surface_point's whole result for a
    // mesh without normals, uvs or a normal map (the forward batch calls it for those).
    void surface_point_base(int mesh, int64_t prim, float b1, float b2, SurfacePoint& sp) const {
        const TriangleData& td = meshes[size_t(mesh)].triangle_data[prim];
        sp.mesh = mesh;
        sp.prim = prim;
        sp.b1 = b1;
        sp.b2 = b2;
        const float b0 = 1.f - b1 - b2;
        sp.p = td.v0 * b0 + td.v1 * b1 + td.v2 * b2;
        sp.p_error = triangle_point_error(td.v0, td.v1, td.v2, b0, b1, b2, td.largest_edge);
        sp.ng = td.ng;
        sp.ns = sp.ng;
        sp.uv = Vec2f(b1, b2);
    }
    // The shading normal before the normal map (interpolated normals, or ng) at barycentrics
    // (b1, b2) of triangle `prim`, and the triangle's dp/du for the normal map (false: none).
    Vec3f unmapped_normal(int mesh, int64_t prim, float b1, float b2) const;
    bool triangle_dpdu(int mesh, int64_t prim, Vec3f& dpdu) const;
    SurfacePoint surface_point(const Hit& h) const { return surface_point(h.mesh, h.prim, h.b1, h.b2); }
    // Starts loading what surface_point(h) reads of h's triangle (a hint; it changes nothing).
    void prefetch(const Hit& h) const {
        const char* d = reinterpret_cast<const char*>(meshes[size_t(h.mesh)].triangle_data + h.prim);
        __builtin_prefetch(d);
        __builtin_prefetch(d + sizeof(TriangleData) - 1);
    }
    BsdfParams bsdf_params(const SurfacePoint& sp) const;
    // bsdf_params' diffuse reflectance alone: the material's diffuse texture at sp's uv, times
    // the mesh's vertex colour where it has them.
    Vec3f diffuse_reflectance(const SurfacePoint& sp) const;
    // Radiance emitted by the surface at sp in direction w (world, leaving the surface).
    Vec3f emitted(const SurfacePoint& sp, const Vec3f& w) const;

    // Radiance (or, for a point light, intensity) scale of a spot profile in direction w.
    static float spot_scale(bool spot, const float* profile, const Vec3f& w) {
        return spot ? spot_falloff(profile, w) : 1.f;
    }
    // Next-event estimation samples both kinds of emitters separately, each with its own
    // sample: picking one of them at random would multiply a small lamp's nearly noiseless
    // estimate by a random 0 or 1/p. (A constant environment is left to the BSDF's samples
    // when the strategies are combined: env_nee in render/path.h.)
    // Samples an area light as seen from p (u0 picks the triangle, by power).
    bool sample_area_light(const Vec3f& p, float u0, float u1, float u2, LightSample& ls) const;
    // The entry of `lights` that sample_area_light picks with u0 (light_distribution valid);
    // u: u0 kept below 1 and remapped into the entry's bin.
    int pick_light(float u0, float& u) const {
        u = std::min(u0, 0.99999994f);
        return light_distribution.sample(u);
    }
    // Samples a direction towards the environment (by its radiance; `compensated`: by
    // Envmap::compensated()).
    bool sample_env(float u1, float u2, LightSample& ls, bool compensated = false) const;
    // Solid-angle density with which sample_area_light would produce the direction from p to
    // the emitting surface point `on_light`.
    float light_pdf(const Vec3f& p, const SurfacePoint& on_light) const;
    // Area of emitting triangle `prim` of mesh m: its light entry's (as build_lights computed
    // it, Mesh::triangle_area) where it has one of its own.
    float light_triangle_area(const Mesh& m, int64_t prim) const {
        return m.solid_angle || m.spherical_by_mesh ? m.triangle_area(prim)
                                                    : lights[size_t(m.light_offset + prim)].area;
    }

    // The Embree scene of that kind of tracing, at the positions of the last update: built
    // (thread-safe) if the scene holds none yet, refittable once the vertices have moved, or
    // refitted if the vertices moved since it was last used.
    RTCScene bvh(Tracing tracing) const {
        const BvhSlot& s = bvh_[int(tracing)];
        return s.ready.load(std::memory_order_acquire) ? s.rtc : prepare_bvh(tracing);
    }
    // Whether the scene holds that kind's BVH (a query builds it; one held since before the
    // vertices moved is refitted at its next query).
    bool has_bvh(Tracing tracing) const {
        std::lock_guard<std::mutex> lock(bvh_mutex_);
        return bvh_[int(tracing)].rtc != nullptr;
    }

    // The edges of all meshes (see scene/edges.h), built on first use: only gradient passes
    // that want geometry or camera derivatives pay for them. Once vertices have moved (the BVH
    // built for refitting), it holds the nearly flat edges too, marked (Edge::flat), which the
    // passes skip: the list is then the same whatever the positions, so that a move refits the
    // edge hierarchy.
    const std::vector<Edge>& edges() const;
    // Per edge of edges(), in its order, what the gradient passes' set-ups read of it: built on
    // first use after the edge list (thread-safe), in parallel, and shared by the views of a call
    // and by the calls that leave the geometry alone.
    struct EdgeMeasures {
        std::vector<float> length;          // |v1 - v0|
        // Of a smooth edge, the angle between its faces' normals over pi (the camera's pass
        // samples a smooth edge that does not fold by it); 0 for the other kinds.
        std::vector<double> smooth_weight;
        // Per mesh: how many of its edges are not flat and have a nonzero length (what the
        // passes can sample).
        std::vector<int64_t> sampled;
    };
    const EdgeMeasures& edge_measures() const;

    // The edge hierarchy (edges/hierarchy.h) over `edges` (indices into edges()), the first
    // `group` of them under a subtree of their own, kept across calls and views: the kept one
    // for these arguments brought up to date (EdgeHierarchy::update: rebuilt, refit or reused).
    // Two are kept (the views of one call may want different things: each keeps its own).
    // Thread-safe: a tree still held by a pass is shared as it is where nothing would change it
    // (many threads rendering one scene), and copied before it is changed for another.
    std::shared_ptr<const EdgeHierarchy> edge_hierarchy(const std::vector<int32_t>& edges, size_t group) const;
    // The same for the edges and group that list(edges, group) writes, `key` naming them: a
    // function of the key and of the geometry alone. A tree kept for that key and the geometry
    // as it is now is reused without calling list (a view or a call that changed no geometry
    // saves a sweep over the edges and the lists' comparisons).
    std::shared_ptr<const EdgeHierarchy> edge_hierarchy(
        const std::vector<uint8_t>& key, const std::function<void(std::vector<int32_t>&, size_t&)>& list) const;
    struct HierarchyStats {
        uint64_t builds = 0, refits = 0, reuses = 0;  // edge_hierarchy() calls
    };
    HierarchyStats hierarchy_stats() const;
    // Changes whenever update() finds that vertices, uvs, normals or the topology may have
    // changed (the edge list is then built anew on use); the same otherwise.
    uint64_t geometry_version() const { return geometry_version_; }

private:
    Scene() = default;
    void set_views(const SceneDesc& desc);
    // edge_hierarchy's choice among the kept trees (under their mutex): the one that `fits`, or
    // else the one used least recently; updated for `edges` and `group` (nullptr: its own).
    std::shared_ptr<const EdgeHierarchy> kept_hierarchy(const std::function<bool(const EdgeHierarchy&)>& fits,
                                                        const std::vector<int32_t>* edges, size_t group) const;
    RTCScene prepare_bvh(Tracing tracing) const;
    void resolve_barycentrics(const Vec3f& origin, const Vec3f& dir, Hit& hit) const;
    bool hit_of(const RTCRayHit& rh, Hit& hit) const;
    void drop_bvhs();
    void build_lights();
    // The cone of directions from p of mesh m's bounding sphere: its axis (unit), and
    // 1 - cos of its half angle; false if p is inside the sphere.
    bool light_cone(const Mesh& m, const Vec3f& p, Vec3f& axis, float& one_minus_cos) const;
    // Weights w[t] of picking each triangle of a spherical_by_mesh mesh from p: its solid
    // angle (an estimate where too small or large to sample by it), 0 where p is behind a
    // one-sided emitter's face; returns their sum.
    // The triangles as seen from p go to tris[t].
    double spherical_pick_weights(const Mesh& m, const Vec3d& p, double* w, SphericalTriangle* tris) const;
    // A light sample on triangle `prim` of `mesh` picked with probability pmf: by its solid
    // angle for spherical_triangle meshes where usable, otherwise a point uniform on it.
    // `seen`: the triangle as seen from p, when already computed.
    bool sample_light_triangle(int mesh, int64_t prim, const Vec3f& p, float u1, float u2, double pmf,
                               LightSample& ls, const SphericalTriangle* seen = nullptr) const;

    // The BVH of each kind of Tracing: null until built; not ready while its vertices wait for
    // a refit (update() leaves that to its next use: a BVH that only some calls trace, the
    // previews of an optimisation, is not refitted at every step).
    struct BvhSlot {
        RTCScene rtc = nullptr;
        std::atomic<bool> ready{false};
    };
    mutable BvhSlot bvh_[2];
    mutable std::mutex bvh_mutex_;
    bool updated_ = false;  // an update succeeded: kept_ holds the geometry
    // The vertices have moved once: the BVHs are built for refitting from then on (Embree's
    // refittable BVH traces a little slower than its static one), and the edge list keeps its
    // nearly flat edges.
    bool moving_ = false;
    // The arrays of the last build that the BVH and the edge list depend on, per mesh (uvs and
    // normals count -1 when not given).
    struct Kept {
        int64_t num_vertices = 0, num_uvs = -1, num_normals = -1;
        std::vector<float> vertices, uvs, normals, colors;
        std::vector<int32_t> indices, uv_indices, normal_indices;
        std::vector<TriangleData> triangle_data;  // Mesh::triangle_data
        std::vector<uint8_t> degenerate;  // Mesh::is_degenerate, triangle by triangle
    };
    std::vector<Kept> kept_;
    mutable BuildStats stats_;
    mutable std::mutex edges_mutex_;
    mutable std::atomic<bool> edges_ready_{false};
    mutable std::vector<Edge> edges_;
    mutable std::mutex measures_mutex_;
    mutable std::atomic<bool> measures_ready_{false};
    mutable EdgeMeasures measures_;
    // Per mesh, what its part of edges_ was made from, for the moves of a scene whose vertices
    // move (moving_): dropped when the triangles, uvs, normals or colours change.
    mutable std::vector<MeshEdgeList> edge_lists_;
    // The edge hierarchies kept for edge_hierarchy() (defined with it, in edges/hierarchy.cpp:
    // the scene layer does not see the edges layer).
    struct KeptHierarchies {
        static constexpr size_t kKept = 2;
        std::mutex mutex;
        std::shared_ptr<EdgeHierarchy> kept[kKept];
        uint64_t used[kKept] = {0, 0};  // when each was last used (a count of calls)
        uint64_t calls = 0;
    };
    mutable std::unique_ptr<KeptHierarchies> hierarchies_;
    mutable HierarchyStats hierarchy_stats_;
    uint64_t geometry_version_ = 0;
};

}  // namespace edgepath
