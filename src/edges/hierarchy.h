// Importance sampling of the edges seen from a point (section 5 of the docs).
//
// EdgeHierarchy: a bounding volume hierarchy over edges, in two trees under one root: the edges
// that are discontinuities from everywhere (boundaries, creases of flat-shaded meshes) and the
// smooth edges (silhouettes only). A group of edges (a render's: the meshes whose vertices are
// wanted) can have a subtree of its own, holding those two trees for it, beside the others'. Each node keeps its box and bounding sphere, the total length
// of its edges, and a cone bounding the normals of the faces adjacent to its smooth edges, so
// that a node whose smooth edges cannot be silhouettes from the point is rejected at once; a
// leaf tests its edge exactly (the point in front of exactly one of the two faces).
//
// Sampling descends from the root, picking a child with probability proportional to an upper
// bound of its contribution at the point (or, at most twice, taking both: see sample()):
//   length x (BSDF lobe bound over the node's directions) / distance^2,
// zero without possible silhouettes (a node's bounds are computed once per query, however many
// descents and refinements visit it: Memo). The lobe bound (LobeBound) is a cosine bound for the
// diffuse part plus a spherical-Gaussian approximation of a GGX lobe around the mirror
// direction, both evaluated at the angle between the node and the direction minus the node's
// angular radius. A leaf is scored by the lobe bound's integral over the arc its edge subtends
// (closed form) over the distance to the edge's line, a small subtree by the sum of its leaves.
// A crease counts in full where it is a silhouette, by the angle between its faces where p sees
// both from one side (a shading jump), not at all where p is behind both faces of a one-sided
// material. Two strategies share one descent's arithmetic: over all edges, and restricted
// to the cone of directions towards the lights (the edges that cast shadows), so the
// probability of the chosen edge under both comes out of one traversal, for multiple importance
// sampling. Under the light strategy a node is scored by its share of the cone (box-cone test;
// a node's share of a narrow cone, smaller than the node, by its children a few levels down),
// and with few light triangles (Query::lights) zero where its box lies outside every triangle's
// widened wedge; a leaf by the lobe bound's integral over the part of its arc the point sampler
// takes (EdgeArc::lights_part: inside the cone and near a light triangle), zero where that part
// is empty, so that no descent ends on an edge it cannot sample.
//
// EdgePointSampler: the point on a chosen edge. Strategy All: a mixture of uniform by length
// and a density in the angle phi the edge subtends at the point (directions w(phi) in the plane
// through the point and the edge) proportional to the lobe bound (tabulated, piecewise linear,
// its cumulative distribution inverted by Newton's method with a bisection safeguard). Strategy
// Lights: over the part of the edge inside the light cone (found in closed form:
// w(phi) . axis = R cos(phi - psi) >= cos(half angle)) and, with LightTriangles, within their
// margin of some light triangle (EdgeArc::lights_part), uniform by length, or where the lobe
// bound has a glossy part a mixture of uniform by length (a tenth, as strategy All) and the lobe bound
// tabulated over that part alone (a lobe narrower than the light's cone: the highlight).
//
// Built in O(n log n) (parallel median splits), kept in the scene across calls and views
// (Scene::edge_hierarchy), refit when only vertices move.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>
#include "math/vec.h"
#include "scene/edges.h"

namespace edgepath {

class Scene;

struct BoundsCone {
    Vec3f axis;             // the cone of directions from a point towards a sphere (the lights)
    float cos_half = -1.f;  // cos(half angle); -1: every direction
    float half = 3.14159265f;  // the half angle
    // The cone from p towards the sphere (c, r); false (and every direction) when p is inside.
    bool towards(const Vec3f& p, const Vec3f& c, float r);
};

// What the BSDF at the point can do with light from a direction w: about
//   diffuse x max(0, n.w) + specular x exp(sharpness (r.w - 1)),  zero where n.w <= 0.
struct LobeBound {
    Vec3f n = Vec3f(0.f, 0.f, 1.f);  // the normal on the side of the outgoing direction
    Vec3f r = Vec3f(0.f, 0.f, 1.f);  // the outgoing direction mirrored about n
    float diffuse = 1.f, specular = 0.f, sharpness = 0.f;
    // The glossy part's integral along a great circle through its peak, in angle, over its peak
    // value: about pi alpha.
    float width = 0.f;
    // From a BSDF's mean diffuse and specular albedo, GGX alpha and cos(n, wo) > 0.
    static LobeBound make(const Vec3f& n, const Vec3f& wo, float diffuse, float specular, float alpha);
    // The value at direction w (unit). (Inline: the point sampler tabulates it 17 times an edge.)
    float eval(const Vec3f& w) const {
        const float c = dot(n, w);
        if (!(c > 0.f)) return 0.f;
        float v = diffuse * c;
        if (specular > 0.f) {
            const float q = 1.f + sharpness * (1.f - dot(r, w));
            v += specular / (q * q);
        }
        return v;
    }
    // The glossy part's largest value over the directions of `cone`, over its peak: 1 where the
    // mirror direction lies inside the cone, falling as the lobe does with the angle between
    // them beyond the cone's half angle; 0 without a glossy part.
    float glossy_share(const BoundsCone& cone) const;
    // Its integral over the arc of directions from p to the segment (v0, v1), in angle (closed
    // form; the glossy part is not cut off below the horizon); *h: the distance from p to the
    // segment's line.
    double integral(const Vec3f& p, const Vec3f& v0, const Vec3f& v1, double* h = nullptr) const;
};

// The area lights' triangles seen from a shading point p, for the light strategy's choice of
// edge and point on it: each triangle as the three planes through p and its sides, their unit
// normals facing it (the directions from p through the triangle are those with n . w >= 0 for
// all three). A direction within an angle `margin` of a triangle has n . w >= -margin for all
// three: so the part of an edge's arc of directions where that holds for some triangle holds
// every direction within `margin` of a light, whichever way (across the edge or along it) a
// direction sampled there is moved. Both faces of a triangle count (the planes do not depend on
// its winding); a triangle behind p bounds the directions towards it only.
struct LightTriangles {
    static constexpr int kMax = 8;  // more triangles: the light cone alone
    int count = 0;
    float margin = 0.f;
    Vec3f n[kMax][3];      // zero: no bound from that side (p in the triangle's plane, a degenerate one)
    Vec3f abs_n[kMax][3];  // their components' absolute values
    Vec3f p;               // the point they are seen from
    // A triangle's three planes again, lane k of each row for plane k (lane 3 repeats plane 0),
    // for outside(): the three tests of a triangle in one pass, the same arithmetic as
    // dot(n, c) + dot(abs_n, half) for each.
    struct alignas(16) Planes {
        float x[4], y[4], z[4];     // n
        float ax[4], ay[4], az[4];  // abs_n
    };
    Planes planes[kMax];
    // From the triangles' corners (count <= kMax) seen from p.
    void set(const Vec3f& p, const Vec3f (*corners)[3], int count, float margin);
    // Whether the box [lo, hi] lies wholly outside every triangle's widened wedge: for each
    // triangle one of its planes has n . (x - p) < -margin |x - p| at every x in the box (with
    // slack for rounding), so no direction from p to a point of the box comes within the margin
    // of a light triangle. False (not known) without triangles.
    bool outside(const Vec3f& lo, const Vec3f& hi) const;
};

// The arc of directions from a point p to an edge (v0, v1): w(phi) = a cos(phi) + b sin(phi),
// phi in [phi0, phi1] (less than pi apart), b along the edge, a towards the foot of the
// perpendicular from p, h the distance to the edge's line; x(phi) = v0 + b (s_foot + h tan(phi)).
struct EdgeArc {
    Vec3f a, b;
    float s_foot = 0.f, h = 0.f, len = 0.f, phi0 = 0.f, phi1 = 0.f;
    // False when the edge is degenerate seen from p (p on its line, a zero-length edge).
    bool set(const Vec3f& p, const Vec3f& v0, const Vec3f& v1);
    // The part of the arc strategy Lights takes, [lo, hi]: inside `cone`, and with `lights` (seen
    // from the same p) within their margin of some light triangle (the hull over the triangles
    // of each one's part). False when it is empty. The point sampler's part and a leaf's Lights
    // importance (EdgeHierarchy) both come from here.
    bool lights_part(const BoundsCone& cone, const LightTriangles* lights, float& lo, float& hi) const;
    // The parameter t in [0, 1] of the angle phi, and back.
    float param(float phi) const { return std::clamp((s_foot + h * std::tan(phi)) / len, 0.f, 1.f); }
    float angle(float t) const { return std::atan((t * len - s_foot) / h); }
};

// An edge's arc seen from p and the part strategy Lights takes of it (EdgeArc::lights_part), with
// that part's ends in t (EdgeArc::param), as a leaf's Lights importance (EdgeHierarchy) and the
// point sampler on the edge (EdgePointSampler) both need them.
struct ArcPart {
    EdgeArc arc;
    bool arc_ok = false;  // EdgeArc::set succeeded
    bool part = false;    // lights_part found a part (lo, hi); its ends t0, t1 in t
    float lo = 0.f, hi = 0.f, t0 = 0.f, t1 = 0.f;
    // From p to (v0, v1) under the cone and triangles: set, then lights_part, then the ends' t.
    // False unless both succeed.
    bool compute(const Vec3f& p, const Vec3f& v0, const Vec3f& v1, const BoundsCone& cone, const LightTriangles* lights);
};

// The arcs and parts a query's leaf scoring computed (EdgeHierarchy::Query::arcs), the latest
// kSize of them, for the point sampler on the edges the descent then chooses, which would compute
// the same again: the chosen leaf was scored a few leaves before the descent ended there.
// reset() before each query (the same p, cone and triangles throughout one).
class LeafArcs {
public:
    static constexpr int kSize = 32;
    void reset() {
        count_ = 0;
        next_ = 0;
    }
    void keep(int32_t edge, const Vec3f& v0, const Vec3f& v1, const ArcPart& part) {
        ids_[next_] = edge;
        Entry& e = entries_[next_];
        e.v0 = v0;
        e.v1 = v1;
        e.part = part;
        next_ = (next_ + 1) & (kSize - 1);
        count_ += count_ < kSize;
    }
    // The latest kept for this edge with exactly these ends, or null.
    const ArcPart* find(int32_t edge, const Vec3f& v0, const Vec3f& v1) const {
        // Newest first: from next_ - 1 down, then (once full) from the end of the ring down.
        int i = next_ - 1;
        while (i >= 0 && ids_[i] != edge) --i;
        if (i < 0 && count_ == kSize) {
            i = kSize - 1;
            while (i >= next_ && ids_[i] != edge) --i;
            if (i < next_) i = -1;
        }
        if (i < 0) return nullptr;
        const Entry& e = entries_[i];
        return e.v0.x == v0.x && e.v0.y == v0.y && e.v0.z == v0.z && e.v1.x == v1.x && e.v1.y == v1.y && e.v1.z == v1.z
                   ? &e.part
                   : nullptr;
    }

private:
    static_assert((kSize & (kSize - 1)) == 0, "a power of two");
    struct Entry {
        Vec3f v0, v1;
        ArcPart part;
    };
    int32_t ids_[kSize];
    Entry entries_[kSize];
    int next_ = 0, count_ = 0;
};

class EdgeHierarchy {
public:
    // Builds over the edges of `scene` listed in `edges` (indices into scene.edges()). The first
    // `group` of them (if neither none nor all) get a subtree of their own under the root,
    // group_root(), which sample() and pdf() can start from to pick among those alone.
    void build(const Scene& scene, const std::vector<int32_t>& edges, size_t group = 0);
    // Brings a hierarchy kept across calls up to date with `scene`, for the same arguments as
    // build(): rebuilt when the edges or groups differ from the last build's (their ends, faces
    // or kinds: a change of topology), or when an edge moves between the discontinuities and the
    // smooth edges (a face became degenerate or stopped being so); refit when only the edges'
    // positions or faces' normals changed: the leaves, then the nodes' boxes, lengths and
    // normal cones over the same tree, bottom-up (no new splits; the cones fitted over each
    // node's edges exactly as a build fits them, so a refit tree equals a build that splits
    // alike); otherwise reused, with the flags the materials and emission decide (one-sided
    // creases, emitters) brought up to date if they changed.
    enum class Update { Built, Refit, Reused };
    Update update(const Scene& scene, const std::vector<int32_t>& edges, size_t group = 0);
    struct Stats {
        uint64_t builds = 0, refits = 0, reuses = 0;  // update() calls
    };
    const Stats& stats() const { return stats_; }
    // Whether the last build was for these arguments.
    bool built_for(const std::vector<int32_t>& edges, size_t group) const {
        return built_ && group == group_ && edges == ids_;
    }
    // The caller's name for the edges and group it was last updated with (Scene::edge_hierarchy
    // with a key), and whether its leaves are `scene`'s geometry as it is now: then a call with
    // the same key, whose edges are the same, needs not list them again.
    void set_key(const std::vector<uint8_t>& key) { key_ = key; }
    bool current_for(const Scene& scene, const std::vector<uint8_t>& key) const;
    // Whether update(scene, edges, group) would leave it as it is (reuse it, flags and all).
    bool unchanged_for(const Scene& scene, const std::vector<int32_t>& edges, size_t group) const;
    const std::vector<int32_t>& edges() const { return ids_; }
    size_t group() const { return group_; }
    // The node over the group's edges: 0 (the root) when they are all the edges, -1 when none.
    int32_t group_root() const { return group_root_; }
    bool empty() const { return nodes_.empty(); }
    // The last build() or update(), in milliseconds.
    double build_ms() const { return build_ms_; }
    // Checks (for tests) that every node's box and sphere hold its edges as `scene` has them
    // now, its length is theirs, its normal cone holds their faces' normals and its plane range
    // their planes at its centre, within a relative tolerance `tol`, and that its children lie
    // side by side after it, their parent it, their edges its own in order; returns the first
    // node that fails, or -1.
    int32_t check_bounds(const Scene& scene, float tol) const;
    // The first node (for tests) whose bounds, flags or links differ from `other`'s, bit for
    // bit (a leaf's edge, an inner node's normal cone where it has one); -1 where none does and
    // both have as many nodes.
    int32_t first_difference(const EdgeHierarchy& other) const;

    // The nodes' bounds at one point, kept across the descents of one query (both strategies,
    // every split, and the levels of children that score a node): each is computed once.
    // reset() before each new query.
    class Memo;
    struct Query {
        Vec3f p;                           // the shading point
        LobeBound lobe;
        const BoundsCone* cone = nullptr;  // the lights; nullptr: no second strategy
        // With the cone, the light triangles seen from p (or nullptr: the cone alone). Strategy
        // Lights then scores a leaf by the part of its edge the point sampler takes (empty: zero)
        // and a node by its box against the triangles' widened wedges (outside all: zero).
        const LightTriangles* lights = nullptr;
        Memo* memo = nullptr;              // optional
        // Only light arriving straight from emitters counts (the vertex's last bounce): a crease
        // of a mesh that does not emit, seen with both faces on one side, has the same (no)
        // emission either side and adds nothing.
        bool direct_only = false;
        // Optional: where the leaves' arcs and Lights parts are kept for the point sampler.
        LeafArcs* arcs = nullptr;
    };
    enum Strategy { All = 0, Lights = 1 };
    struct Choice {
        int32_t edge = -1;        // index into scene.edges()
        float prob[2] = {0, 0};   // the expected number of times each strategy picks it
    };
    // A descent splits (goes down both children, one edge from each) at most kMaxSplits times:
    // where p lies in both children's boxes, where both children's importances are comparable and
    // a large part of the whole, and (strategy Lights) where the light cone is narrow. So a query
    // gives up to kMaxChoices edges, each at most once.
    static constexpr int kMaxSplits = 2, kMaxChoices = 1 << kMaxSplits;
    // Picks edges with strategy `s` (Lights needs q.cone) among those under node `start` (the
    // root, or group_root()), writing up to kMaxChoices of them to `out`, each with its expected
    // count under both strategies. Returns how many (0: no edge can contribute).
    int sample(const Query& q, Strategy s, float u, Choice out[kMaxChoices], int32_t start = 0) const;
    // The expected numbers of times sample() from `start` picks `edge` (an index into
    // scene.edges()), under each strategy (zero for an edge not under `start`).
    Choice pdf(const Query& q, int32_t edge, int32_t start = 0) const;

private:
    // 128 bytes on a 64-byte boundary, two cache lines: the first holds what every score reads
    // (coarse(), importance_of(), the descents), the second a leaf's edge or an inner node's
    // normal cone (read only where there are silhouettes to bound) and what the build, refit and
    // pdf() read. A node's two children are adjacent (left, left + 1): the descents score both.
    struct Leaf {
        Vec3f a, b, n0, n1;         // its ends; of a smooth edge or a crease: its faces' normals
    };
    struct Cone {
        Vec3f axis;                 // the normal cone of an inner node's smooth edges
        float sin = 0.f;
        // Smooth edges: the range of the faces' plane equations at the centre, n_f . (c - x_f).
        float plane_lo = 0.f, plane_hi = 0.f;
        // The sum of its edges' faces' unit normals (n0 + n1 of each edge; zero for a boundary
        // or a crease between faces of zero area), its children's added: every inner node has
        // it, and the cone's axis is its direction.
        Vec3f normals{0.f};
    };
    struct alignas(64) Node {
        Vec3f lo, hi;
        Vec3f center;
        float radius = 0.f;         // of the bounding sphere
        float length = 0.f;
        int32_t count = 0;          // edges under it
        int32_t left = -1;          // children left, left + 1; leaf when left < 0
        float cone_cos = -1.f;      // the normal cone (inner nodes: Cone); cos -1: no culling
        float dihedral = 0.f;       // mean angle between the two faces' normals (smooth edges)
        bool always = false;        // holds a boundary edge or a crease
        bool crease = false;        // holds only creases
        bool dark_behind = false;   // holds only edges whose two faces are black seen from behind
        bool emissive = false;      // holds an edge of an emitter
        // The second line: a leaf's edge, or an inner node's cone (fit_cone; cone_cos > -1).
        union {
            Leaf leaf;
            Cone cone;
        };
        int32_t edge = -1;          // leaf: index into scene.edges()
        int32_t parent = -1;
        int32_t first = 0;          // its edges: order_[first, first + count)
        bool seam = false;          // holds a seam (Edge::seam)
        bool mixed = false;         // joins the kinds' or the groups' trees: no normal cone
        Node() : leaf() {}
        int32_t right() const { return left + 1; }
    };
    static_assert(sizeof(Node) == 128, "a node is two cache lines");
public:
    // A node's own bounds at a point: its importance under both strategies; whether p lies
    // inside its bounding sphere, and whether the light cone is narrow beside it (then its
    // children score it better).
    struct Coarse {
        float value[2] = {0.f, 0.f};
        bool inside = false, narrow = false;
    };
    class Memo {
    public:
        void reset();
        const Coarse* find(int32_t node) const;
        Coarse* insert(int32_t node);  // nullptr when full
        // find(), or else insert() (found false; nullptr when full), in one probe sequence:
        // insert() takes the first entry find() stops at.
        Coarse* lookup(int32_t node, bool& found) {
            for (uint32_t h = slot(node);; h = (h + 1) & (kSize - 1)) {
                Entry& e = entries_[h];
                if (e.stamp == stamp_) {
                    if (e.node == node) {
                        found = true;
                        return &e.value;
                    }
                    continue;
                }
                found = false;
                if (used_ * 4 >= kSize * 3) return nullptr;  // full enough: computed without keeping
                e.stamp = stamp_;
                e.node = node;
                ++used_;
                return &e.value;
            }
        }

    private:
        static constexpr uint32_t kSize = 1024;  // a power of two
        static uint32_t slot(int32_t node) { return (uint32_t(node) * 2654435761u) & (kSize - 1); }
        struct Entry {
            uint32_t stamp = 0;
            int32_t node = -1;
            Coarse value;
        };
        Entry entries_[kSize];
        uint32_t stamp_ = 1;
        uint32_t used_ = 0;
    };

private:
    void coarse(const Query& q, const Node& n, Coarse& out) const;
    // Node `index`'s importance under both strategies: its own bounds, or its children's where
    // they are tighter, or for a subtree of at most kExactLeaves edges the sum of its leaves.
    // refine: levels of children scoring a node whose sphere holds p; light_refine: levels of
    // children scoring its share of a narrow light cone.
    void importance(const Query& q, int32_t index, float out[2], int refine = kRefine, int light_refine = kLightRefine) const;
    // The same, past the memo's entry (`kept`, or null; `found`: it held the node already).
    void importance_of(const Query& q, int32_t index, Coarse* kept, bool found, float out[2], int refine,
                       int light_refine) const;
    // A small subtree's importance (at most kExactLeaves edges): the sum of its leaves' own
    // values, each kept in the memo (what importance() with no refinement gives for it).
    void leaves_sum(const Query& q, int32_t index, float out[2]) const;
    static constexpr int kRefine = 3, kLightRefine = 4;
    // A subtree of at most this many edges is scored by the sum of its leaves (fewer descents end
    // where no leaf can contribute).
    static constexpr int kExactLeaves = 8;
    // What a leaf is made of: its edge's ends (an empty leaf's both at its midpoint), its faces'
    // unit normals (zero where it has none) and its flags, as the scene has them now.
    struct LeafInput {
        Vec3f p0, p1, n0, n1;
        bool always, crease, seam, dark_behind, emissive;
    };
    static LeafInput leaf_input(const Scene& scene, const Edge& e);
    struct Input;
    void build(const Scene& scene, const Input& in, size_t group);
    static void set_leaf(const LeafInput& in, int32_t edge, Node& node);
    // The inner nodes and cones of the subtree at `index`, its leaves set (a refit).
    void refit(int32_t index);
    void refresh_flags(const Input& in);
    void refresh_inner_flags();
    // The subtree over items [begin, end) rooted at `index`, its other nodes from `next` on.
    void build_range(const Input& in, std::vector<int32_t>& items, int begin, int end, int32_t index, int32_t parent,
                     int32_t next);
    // A subtree over items [begin, end): [begin, split) the discontinuities from everywhere,
    // [split, end) the smooth edges, each under a child of its own when both are there.
    void build_kinds(const Input& in, std::vector<int32_t>& items, int begin, int split, int end, int32_t index,
                     int32_t parent, int32_t next);
    void finish_inner(int32_t index);
    // The cones' input in the leaves' order (a node's edges lie side by side from node.first):
    // each edge's faces' normals n0, n1 and its end p0, one array per coordinate (x, y, z of n0,
    // then of n1, then of p0), kept across updates.
    struct ConeInput {
        std::vector<float> v[9];
        void resize(size_t n);
        void set(size_t k, const LeafInput& in);
    };
    ConeInput cone_in_;
    void fit_cone(Node& n) const;
    // Whether inner node n gets a normal cone: not where it joins the kinds' or groups' trees, nor
    // where it holds discontinuities other than creases, nor in a small subtree (at most
    // kExactLeaves edges), which the descents score by its leaves and never by its own bounds.
    static bool has_cone(const Node& n) {
        return n.left >= 0 && !n.mixed && (!n.always || n.crease) && n.count > kExactLeaves;
    }
    // Whether a descent with strategy k that has split `used` times splits at n, whose children
    // have importances il, ir; `whole`: the root's importances.
    bool splits(const Query& q, const Node& n, const float il[2], const float ir[2], const float whole[2], int k,
                int used) const;
    std::vector<Node> nodes_;
    std::vector<int32_t> leaf_of_;  // scene edge index -> leaf node (-1: not in the hierarchy)
    int32_t group_root_ = -1;
    double build_ms_ = 0.0;
    // The last build's arguments and edges (what update() compares), and its items in the
    // leaves' order (indices into the edge list it was given).
    bool built_ = false;
    std::vector<int32_t> ids_;
    size_t group_ = 0;
    std::vector<Edge> kept_edges_;
    std::vector<int32_t> order_;
    // The scene and its geometry version (Scene::geometry_version) the leaves were last set
    // from, and per mesh what the flags depend on (mesh_flags()).
    const Scene* scene_ = nullptr;
    uint64_t version_ = 0;
    std::vector<uint8_t> mesh_flags_;
    std::vector<uint8_t> key_;  // set_key(); empty: none
    // Whether its leaves are `edges` in `group`, with `scene`'s geometry as it is now.
    bool holds(const Scene& scene, const std::vector<int32_t>& edges, size_t group) const;
    static std::vector<uint8_t> mesh_flags(const Scene& scene);
    Stats stats_;
};

// One sampler per edge sample: its const calls may build the light part's table (lazily), so
// one sampler is not for concurrent use.
class EdgePointSampler {
public:
    // The edge (v0, v1) seen from p. False when it is degenerate seen from p (p on its line, or
    // a zero-length edge). With `lights` (as seen from the same p, and with a cone), strategy
    // Lights keeps to the part of the edge inside the cone that is also within the lights'
    // margin of some light triangle (the hull of those parts over the triangles).
    bool setup(const Vec3f& p, const Vec3f& v0, const Vec3f& v1, const LobeBound& lobe, const BoundsCone* cone,
               const LightTriangles* lights = nullptr);
    // The same, from the edge's arc and Lights part as ArcPart::compute found them for the same
    // p, edge, cone and triangles (the leaf's scoring kept them: LeafArcs); with `cone` null,
    // without strategy Lights (its density zero), as setup() without a cone.
    bool setup(const ArcPart& known, const LobeBound& lobe, const BoundsCone* cone);
    // A parameter t in [0, 1] (x = v0 + t (v1 - v0)) by strategy `s`; false if the strategy
    // cannot sample this edge (Lights: no part of it inside the cone).
    bool sample(EdgeHierarchy::Strategy s, float u, float& t) const;
    // The density of t, per unit t, under each strategy.
    float pdf(EdgeHierarchy::Strategy s, float t) const;
    // Both strategies' densities of t, as pdf() gives them, with one angle of t for the two
    // (strategy Lights' only where `lights`; 0 otherwise).
    void pdfs(float t, bool lights, float& all, float& lights_pdf) const;
    // The angle of parameter t and back.
    float angle(float t) const;
    float param(float phi) const;
    static constexpr int kBins = 16;
    static constexpr float kUniform = 0.1f;  // strategy All's share of uniform by length
    // Strategy Lights' share of uniform by length over the part inside the cone where the lobe
    // bound has a glossy part (the rest follows the lobe bound there); 1 otherwise.
    static constexpr float kLightsUniform = 0.1f;

private:
    // The lobe bound tabulated over an interval of angles [lo, hi] (kBins bins, piecewise linear)
    // and its integral up to the bins' ends.
    struct Table {
        float lo = 0.f, hi = 0.f;
        // (Written by build() before anything reads them: not zeroed first, a sampler is made
        // per edge sample.)
        float g[kBins + 1];    // the lobe bound at the bins' ends
        float cdf[kBins + 1];  // its integral (in angle) up to them
        float total = 0.f;          // 0 where the integral is zero or not finite
        // Over the directions a cos(phi) + b sin(phi), phi in [lo, hi].
        void build(const Vec3f& a, const Vec3f& b, const LobeBound& lobe, float lo, float hi);
        // The angle below which a share u in [0, 1) of the integral lies.
        float invert(float u) const;
        // The (unnormalised) piecewise-linear value at angle phi.
        float value(float phi) const;
    };
    float dphi_dt(float t) const;
    // Strategy Lights' density at t inside its part [t0_, t1_], phi the angle of t.
    float lights_pdf(float t, float phi) const;
    // The table over the part inside the cone, built the first time a sample or a density needs
    // it: a point strategy All takes outside that part needs neither it nor its total.
    void build_lights() const;
    EdgeArc arc_;
    // The part strategy Lights samples: inside the light cone (and near a light triangle, with
    // LightTriangles); empty when cone1 <= cone0. [t0_, t1_]: the same in t (param()).
    float cone0_ = 0.f, cone1_ = 0.f, t0_ = 0.f, t1_ = 0.f;
    Table all_;                        // over the whole edge [phi0, phi1]
    // Over the part inside the cone, where lights_uniform_ < 1 (a glossy lobe): built lazily
    // (build_lights(); lights_pending_ until then, with the lobe it is built from).
    mutable Table lights_;
    mutable float lights_uniform_ = 1.f;
    mutable bool lights_pending_ = false;
    LobeBound lobe_;
};

}  // namespace edgepath
