// The adjoint sweep of one recorded path (interior term of the gradient, see
// docs: every direction after the camera is held fixed in world space; pdfs and MIS weights are
// constants). The boundary term of the edges seen from the path's vertices is added during the
// sweep (edges/secondary.h); that of the edges the camera sees, by its own pass (edges/primary.h).
#pragma once
#include "render/path.h"
#include "scene/geometry.h"
#include "scene/gradients.h"

namespace edgepath {

class SecondaryEdges;
struct EdgeTermLog;

// Adds d(adjoint . L)/d(parameters) for the path in `rec` to `sink`; with `secondary` (made for
// the same `slots`), also the boundary term of the edges seen from each scattering vertex
// (edges/secondary.h). With `log`,
// those edge terms are recorded (log->replaying false) or replayed from an earlier sweep over
// the same path (true) instead of sampled again.
void backprop_path(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, const Vec3f& adjoint,
                   GradSink& sink, const SecondaryEdges* secondary = nullptr, EdgeTermLog* log = nullptr);

// Forward mode (a derivative image): the three colours' sweeps in one, adjoint (w, w, w) with
// one lane of every scalar adjoint per colour (math/adjoint.h). `sink` (projecting) then holds
// the three colours' projections (GradSink::take_projections), the same, lane by lane, as three
// backprop_path calls with the adjoints (w, 0, 0), (0, w, 0), (0, 0, w). With `secondary`, `log`
// is required: scratch for the edge terms, sampled once and applied to each colour.
void backprop_path_colours(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, float w,
                           GradSink& sink, const SecondaryEdges* secondary = nullptr, EdgeTermLog* log = nullptr);

// ---- pieces of the sweep, shared with the output channels (diff/channels.h) ------------------

// The differentiable geometry of a hit: a fixed ray (origin, dir) meeting a triangle.
struct VertexGeometry {
    const Mesh* mesh;
    const int32_t* tri;
    Vec3f v[3];
    TriangleHit<float> th;  // re-solved from the ray, so that value and adjoint agree exactly
    SurfacePoint sp;

    VertexGeometry(const Scene& scene, const Hit& hit, const Vec3f& origin, const Vec3f& dir);
};

// The adjoint of an RGB quantity: Vec3f for float and Adj3 (channel c belongs to colour c with
// Adj3), a vector of lanes for AdjN (whose lanes are output values, not colours).
template <class A>
struct RgbAdjoint {
    using type = Vec3f;
};
template <int N>
struct RgbAdjoint<AdjN<N>> {
    using type = TVec3<AdjN<N>>;
};

// Adjoints of the quantities derived from a hit. A: the scalar adjoints' type (float, Adj3 for
// one lane per output colour, or AdjN for one lane per output value).
template <class A>
struct THitAdjoint {
    TVec3<A> dp, dn, dng;  // position, shading normal (unbent), geometric normal
    typename RgbAdjoint<A>::type dcolor;  // interpolated vertex colour (Mesh::color)
    TVec2<A> duv;          // texture coordinates
    TVec2<A> db;           // barycentrics (b1, b2)
    A dt = A(0);           // distance along the ray
    // Direct adjoints of the triangle's three vertex positions and three uvs (the normal map's
    // tangent depends on them, not through the hit point).
    TVec3<A> dtri[3];
    TVec2<A> dtri_uv[3];
    THitAdjoint() {}  // every adjoint zero (TVec2, TVec3 and the lanes start at zero)
};
using HitAdjoint = THitAdjoint<float>;

// Sends the adjoints `a` of a hit to the mesh's buffers (`ms`, may be null) and adds the
// adjoint of the ray through the intersection to (d_origin, d_dir). Without `positions` (the
// caller knows that neither the mesh's vertices nor the ray's adjoint reach anything wanted),
// only the uvs', colours' and normals' buffers: the rest (the geometric normal, the point, the
// intersection) is left out and (d_origin, d_dir) untouched.
template <class A>
void finish_hit(const VertexGeometry& g, const THitAdjoint<A>& a, const SceneGradients::MeshSlots* ms, GradSink& sink,
                const Vec3f& origin, const Vec3f& dir, TVec3<A>& d_origin, TVec3<A>& d_dir, bool positions = true);

// Adjoint of a texture lookup: texels into `slot`, and (if `duv`) the derivative along uv.
template <class A>
void d_texture(const Texture& tex, const GradSlot& slot, Vec2f uv, const A* dval, GradSink& sink, TVec2<A>* duv);

// Adjoint of the diffuse reflectance at g's hit, diffuse(uv) times the vertex colour
// (Scene::bsdf_params), for material `material`: texels into its slot, the colour's adjoint
// into ha.dcolor and the uv's into ha.duv. `dval`: an RGB adjoint.
template <class A>
void d_diffuse(const Scene& scene, const VertexGeometry& g, const SceneGradients& slots, const Vec3f& dval,
               GradSink& sink, THitAdjoint<A>& ha);

// Adjoint of the material's normal map at g's hit (Scene::surface_point): turns ha.dn, the
// adjoint of the mapped shading normal, into that of the normal before the map, and sends the
// rest to the map's texels (its slot), ha.duv, ha.dtri and ha.dtri_uv. Nothing without a map.
template <class A>
void d_normal_map(const Scene& scene, const VertexGeometry& g, const SceneGradients& slots, GradSink& sink,
                  THitAdjoint<A>& ha);

// The slots of mesh `mesh`, or null when none were given.
const SceneGradients::MeshSlots* mesh_slots(const SceneGradients& s, int mesh);

// The camera parameters' share of the adjoints (d_origin, d_dir) of the camera ray through film
// point `film` and lens point `lens`, into the camera's slot (when wanted). A: float, or
// math/adjoint.h's lanes (each lane computed as float's code computes it).
template <class A>
void d_camera_params(const Scene& scene, const SceneGradients& slots, const Vec2f& film, const Vec2f& lens,
                     const TVec3<A>& d_origin, const TVec3<A>& d_dir, GradSink& sink) {
    if (!slots.camera.wanted()) return;
    A cam[kCameraParams] = {};
    d_camera_ray(scene.camera_params, film.x, film.y, lens.x, lens.y, d_origin, d_dir, cam);
    for (int i = 0; i < kCameraParams; ++i) sink.add(slots.camera, i, cam[i]);
}

}  // namespace edgepath
