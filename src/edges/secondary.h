// The boundary term of secondary visibility: edges seen from path vertices (shadows, reflections,
// indirect light; section 4 of the docs), in direction space. At a vertex p with fixed outgoing
// direction wo, the reflected radiance is the integral over directions w of
//   F(w) = f(wo, w) |cos| L_in(w);
// an edge (v0, v1) puts a step into F along the great-circle arc w . N = 0,
// N = (v0 - p) x (v1 - p), and contributes
//   integral over the arc of (w . dN/dparameter) / |N| (F_u - F_l) dl,
//   dl = |(I - w w^T)(v1 - v0)| / |x - p| dt,   x = v0 + t (v1 - v0).
// F_u, F_l are estimated by tracing the rest of the path from p a small angle to each side.
// Gradients go to v0 and v1 and to p (and through p back along the path to the camera).
//
// Edges are importance-sampled by the edge hierarchy (edges/hierarchy.h): one descent per vertex,
// over all edges or, when the scene has area lights, restricted to the cone towards them (the
// edges that cast shadows; with at most LightTriangles::kMax light triangles, to the edges and
// the nodes' boxes that come within a small margin of one of them), the strategy picked at
// random (the light strategy by the BSDF's diffuse share and its glossy lobe's share of the
// light cone) and the two combined by one-sample
// multiple importance sampling (balance heuristic on the joint density of the edge and the point
// on it). The point on the edge is sampled by angle (EdgePointSampler): weighted by a bound of
// the BSDF lobe, or inside the light cone uniformly (mixed with the lobe bound there for a
// glossy lobe), and where the scene has at most LightTriangles::kMax light triangles, only
// where the directions pass within a small margin of one of them.
// opt.edge_sampling == Uniform: one edge by length over all edges and a point uniform by length
// instead (the baseline).
#pragma once
#include <algorithm>
#include <memory>
#include <vector>
#include "edges/hierarchy.h"
#include "sampling/rng.h"
#include "scene/bsdf_diff.h"
#include "scene/desc.h"
#include "scene/gradients.h"
#include "scene/scene.h"

namespace edgepath {

// One edge sample's term at a vertex, without the adjoint: the adjoint weight w makes it
//   s = w . u,  gradients s g.d_e0, s g.d_e1 to the edge's ends and s g.d_o to the vertex.
struct EdgeTerm {
    int32_t edge;
    Vec3f u;
    EdgeSideGradient g;
};

// The edge terms of one path's vertices, kept by a sweep over the path: which edges and points
// are sampled, and what the two sides see, do not depend on the adjoint. The pilot pass of the
// survival roulette reads them; a derivative image's sweep (backprop_path_colours) applies them to
// each colour; another sweep over the same path with another adjoint may replay them.
struct EdgeTermLog {
    std::vector<EdgeTerm> terms;
    std::vector<uint32_t> begin, end;  // vertex k's terms: [begin[k], end[k])
    bool replaying = false;
    void start(size_t vertices) {
        terms.clear();
        begin.assign(vertices, 0);
        end.assign(vertices, 0);
        replaying = false;
    }
};

class SecondaryEdges {
public:
    // Empty (nothing to do) unless the option is on and vertices or the camera are wanted.
    SecondaryEdges(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots);
    bool active() const { return total_ > 0.0; }
    int max_bounces() const { return opt_.max_bounces; }

    // Whether a mesh's vertices are wanted (their motion moves the path vertices on them).
    bool mesh_wanted(int mesh) const { return size_t(mesh) < slots_.meshes.size() && slots_.meshes[size_t(mesh)].vertices.wanted(); }
    bool camera_wanted() const { return slots_.camera.wanted(); }

    // The boundary term at path vertex `sp` (shading normal already bent for wo), which scatters
    // with `bounces_left` scattering events after it. `weight`: the adjoint times the path
    // throughput up to the vertex. `position_matters`: whether anything wanted moves the vertex
    // (the camera, or a mesh the path has met so far); if not, only edges of meshes whose
    // vertices are wanted can contribute, and only those are sampled. Adds the edge vertices'
    // gradients to `sink` and returns the adjoint of the vertex position p.
    // With `record`, also appends the terms (EdgeTerm) it adds; with a zero `weight` as well,
    // it only records them (nothing reaches `sink`, the result is zero).
    Vec3f add(const SurfacePoint& sp, const Vec3f& wo, const TBsdfParams<float>& bsdf, int bounces_left,
              const Vec3f& weight, bool position_matters, Rng rng, GradSink& sink,
              std::vector<EdgeTerm>* record = nullptr) const;
    // The probability with which the term is sampled at a vertex on mesh `mesh` at depth
    // `depth` (0: the camera's vertex), from set_survival(); 1 when none was set.
    float survival(int mesh, int depth) const {
        if (survival_.empty()) return 1.f;
        const size_t c = survival_class(mesh, depth);
        return c < survival_.size() ? survival_[c] : 1.f;
    }
    // The classes of vertices survival() tells apart: a mesh and a depth (the last one holds
    // every deeper vertex).
    static constexpr int kSurvivalDepths = 4;
    static size_t survival_class(int mesh, int depth) {
        return size_t(mesh) * kSurvivalDepths + size_t(std::min(depth, kSurvivalDepths - 1));
    }
    void set_survival(std::vector<float> p) { survival_ = std::move(p); }

    // Adds recorded terms again, with the adjoint weight `weight`; returns the adjoint of p.
    Vec3f replay(const EdgeTerm* terms, size_t count, const Vec3f& weight, GradSink& sink) const;
    // The same for each output colour at once (math/adjoint.h): colour c's term is that of the
    // weight's channel c alone, as replay with (weight.x, 0, 0), ... would add it.
    AVec3 replay_colours(const EdgeTerm* terms, size_t count, const Vec3f& weight, GradSink& sink) const;

private:
    // One edge sample: edge `edge` (index into scene.edges()) at parameter t, the estimate
    // scaled by `scale` (MIS weight x edge length / probability of the edge).
    Vec3f evaluate(int32_t edge, float t, float scale, const SurfacePoint& sp, const Vec3f& wo,
                   const TBsdfParams<float>& bsdf, int bounces_left, const Vec3f& weight, Rng& rng,
                   GradSink& sink, std::vector<EdgeTerm>* record) const;
    // A term's gradients for the adjoint weight `weight`: to the edge's ends into `sink`; returns
    // the adjoint of the vertex position.
    Vec3f apply(const EdgeTerm& term, const Vec3f& weight, GradSink& sink) const;
    // What apply and replay_colours share: the term's gradients scaled by s (a float, or an
    // Adj3 with one scale per colour) into the edge's ends; returns the vertex position's.
    template <class S>
    TVec3<S> send(const EdgeTerm& term, const S& s, GradSink& sink) const;

    // A set of edges with its sampler by length (uniform): the edges of the meshes `keep` keeps
    // that are not flat and have a nonzero length. Without by_length_, neither the edges nor a
    // sampler: total 1 where the set has an edge, else 0 (from the meshes' counts of such edges).
    struct EdgeSet {
        std::vector<int32_t> edges;  // indices into scene.edges()
        std::vector<double> cumulative;
        double total = 0.0;
    };
    void build_set(EdgeSet& set, bool (*keep)(const SecondaryEdges&, int mesh));

    const Scene& scene_;
    const RenderOptions& opt_;
    const SceneGradients& slots_;
    bool uniform_ = false;
    bool by_length_ = false;  // the sets' samplers are needed (uniform_, or a dielectric)
    EdgeSet all_, wanted_;  // every edge; the edges of meshes whose vertices are wanted
    // The hierarchy over every edge, the wanted meshes' edges under a node of their own
    // (wanted_root_) when not every mesh is wanted: one build serves both sets. Kept by the
    // scene across calls and views (Scene::edge_hierarchy).
    std::shared_ptr<const EdgeHierarchy> hierarchy_;
    int32_t wanted_root_ = 0;
    bool has_wanted_set_ = false;
    double total_ = 0.0;
    bool has_lights_ = false;
    Vec3f lights_center_;  // a bounding sphere of the area lights
    float lights_radius_ = 0.f;
    // The light triangles' corners where there are few (none otherwise): LightTriangles.
    Vec3f light_corners_[LightTriangles::kMax][3];
    int light_count_ = 0;
    std::vector<float> survival_;  // per survival_class(); empty: 1 everywhere
};

}  // namespace edgepath
