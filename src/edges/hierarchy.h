// A bounding volume hierarchy over edges, for importance sampling the edges seen from a point
// (section 5 of the docs). Each node keeps its box, the total length of its edges, and a cone
// bounding the normals of the faces adjacent to its smooth edges, so that a node whose smooth
// edges cannot be silhouettes from the point is rejected at once; boundary edges and creases
// (silhouettes or shading jumps from everywhere) are flagged and never culled by the cone.
//
// Sampling descends from the root, picking a child with probability proportional to an upper
// bound of its contribution at the point: length / distance^2, times a bound of the cosine at
// the point (the BSDF's support), zero without possible silhouettes; optionally restricted to
// the cone of directions towards a box (the lights). pdf() gives the probability of any edge
// under the same rules, for multiple importance sampling.
#pragma once
#include <cstdint>
#include <vector>
#include "edges/edges.h"
#include "math/vec.h"

namespace edgepath {

class Scene;

struct BoundsCone {
    Vec3f center;  // the cone of directions from a point towards a box: axis and cos(half angle)
    Vec3f axis;
    float cos_half = -1.f;  // -1: every direction
};

class EdgeHierarchy {
public:
    // Builds over the edges of `scene` listed in `edges` (indices into scene.edges()).
    void build(const Scene& scene, const std::vector<int32_t>& edges);
    bool empty() const { return nodes_.empty(); }
    double build_ms() const { return build_ms_; }

    // What the importance is evaluated against.
    struct Query {
        Vec3f p, n;             // the point and its shading normal
        bool two_sided = false; // directions below the surface count too
        const BoundsCone* cone = nullptr;  // only edges inside this cone (lights), or all
    };
    // Picks an edge (index into scene.edges()) with probability `prob`; false if none can
    // contribute.
    bool sample(const Query& q, float u, int32_t& edge, float& prob) const;
    // The probability that sample() picks `edge` (an index into scene.edges()).
    float pdf(const Query& q, int32_t edge) const;

private:
    struct Node {
        Vec3f lo, hi;
        Vec3f cone_axis;
        float cone_cos = 1.f;   // cos of the normal cone's half angle; -1: no culling
        bool always = false;    // holds a boundary edge or a crease
        float length = 0.f;
        int32_t left = -1, right = -1;  // children; leaf when left < 0
        int32_t parent = -1;
        int32_t edge = -1;      // leaf: index into scene.edges()
    };
    float importance(const Query& q, const Node& n) const;
    int32_t build_node(std::vector<int32_t>& items, int begin, int end, int32_t parent,
                       const std::vector<Vec3f>& p0, const std::vector<Vec3f>& p1,
                       const std::vector<Vec3f>& n0, const std::vector<Vec3f>& n1, const std::vector<uint8_t>& always,
                       const std::vector<int32_t>& ids);
    std::vector<Node> nodes_;
    std::vector<int32_t> leaf_of_;  // scene edge index -> leaf node (-1: not in the hierarchy)
    double build_ms_ = 0.0;
};

}  // namespace edgepath
