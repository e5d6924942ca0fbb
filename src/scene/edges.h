// The edges where visibility can change, built from the meshes (Scene::edges: on first use, and
// again after an update that moved vertices or changed uvs, normals, colours or topology), for the
// boundary terms of the gradient (edge sampling, see the docs).
//
// Faces are made adjacent by welding vertices that share a POSITION (the exact float triple), not
// an index, so uv seams, split normals and duplicated vertices do not create false boundaries.
// Kinds of edges kept:
//   boundary  - one face (open meshes): a silhouette from every point that sees it;
//   crease    - two faces at an angle in a mesh without shading normals, or two faces whose
//               shading normals, uvs or vertex colours differ along the edge (split normals,
//               a uv seam, the fan of a sphere's pole, a colour seam): the shading or the
//               texture may jump across it, so it is a discontinuity seen from everywhere (and
//               a silhouette where one face is front-facing and the other is not);
//   smooth    - two faces at an angle in a mesh with shading normals: a silhouette only;
//   shared    - more than two faces (non-manifold): kept once per pair of consecutive faces
//               around it, each pair treated as a two-face edge (never assumed away).
// Edges between two faces of the same orientation within 1e-5 rad of one plane (the rounding of
// a plane's float corners), with the same shading, uvs and colours, are dropped (never a
// silhouette, never a shading discontinuity; faces at a larger angle, however small, fold where
// the eye lies between their planes); degenerate edges (both ends at one position) too. A scene
// whose vertices move (kept across calls, refittable) keeps the former, marked flat (Edge::flat),
// so that its edge list is the same from step to step and its edge hierarchy is refit.
#pragma once
#include <cstdint>
#include <vector>
#include "math/vec.h"

namespace edgepath {

struct MeshDesc;

enum class EdgeKind : uint8_t { Boundary, Crease, Smooth };

struct Edge {
    int32_t mesh = -1;
    int32_t v0 = -1, v1 = -1;  // vertex indices in the mesh (of the first face that has the edge)
    int64_t f0 = -1, f1 = -1;  // adjacent triangles; f1 = -1 on a boundary
    EdgeKind kind = EdgeKind::Boundary;
    // A crease whose sides differ in more than their faces' normals: uvs, vertex colours or split
    // vertex normals (a texture seam, a modelled crease). A crease that is not a seam (flat
    // shading) jumps only by the angle between its faces, however small.
    bool seam = false;
    // A seam whose sides differ in their uvs alone (the same shading normals and colours: a uv
    // seam of a smooth mesh, a pole's fan): where its mesh's material reads no texture (nor its
    // emission), nothing steps across it, and it is a silhouette only, like a smooth edge.
    bool uv_only = false;
    // Its two faces are within the coplanar bound, with the same shading (an edge a scene built
    // afresh drops): kept, marked, only in the list of a scene whose vertices move
    // (build_mesh_edges' keep_flat), so that the list does not change when a move of the order
    // of rounding turns an edge flat or back. The passes skip it as if it were not there; the
    // edge hierarchy holds it as an empty leaf (zero length), never sampled.
    bool flat = false;
};

// All the edges of one mesh (mesh index `mesh` is stored in each edge). With `keep_flat`, the
// edges between nearly coplanar faces are kept too, marked Edge::flat: the list then depends on
// the triangles, uvs, normals and colours only, not on where the vertices are (but for faces
// that become or stop being degenerate, and positions that start or stop coinciding).
void build_mesh_edges(const MeshDesc& mesh, int32_t mesh_index, std::vector<Edge>& out, bool keep_flat = false);

// Per face of the mesh, whether it is degenerate (is_degenerate_triangle): not there for the
// edges (the scene skips it), so its neighbours' edges with it are boundaries.
std::vector<uint8_t> degenerate_faces(const MeshDesc& mesh);

// What one mesh's part of an edge list (build_mesh_edges with keep_flat) was made from, kept
// across the moves of a scene whose vertices move. The part depends on the positions only
// through the welding (which vertices share a position), the degenerate faces and the flat
// marks: a move that keeps the first two (nearly every optimisation step) needs the marks alone
// recomputed, not the pairing of the faces (a sort of every half-edge: most of a list's time).
// Its owner drops it whenever the mesh's triangles, uvs, normals or colours change.
class MeshEdgeList {
public:
    // Appends build_mesh_edges(mesh, mesh_index, out, true)'s edges to `out` and keeps what they
    // were made from. `degenerate`: degenerate_faces(mesh), which the caller may hold already
    // (the scene keeps it per triangle).
    void build(const MeshDesc& mesh, const std::vector<uint8_t>& degenerate, int32_t mesh_index,
               std::vector<Edge>& out);
    // Where the welding and the degenerate faces of `mesh` are those the part was built with,
    // brings the part (in `all`, where build() put it) to what build() would make now, bit for
    // bit: only the flat marks can differ. False, with nothing changed, where they are not.
    bool refresh(const MeshDesc& mesh, const std::vector<uint8_t>& degenerate, std::vector<Edge>& all) const;

private:
    size_t begin_ = 0, count_ = 0;  // the part's place in the list
    std::vector<int64_t> weld_;
    std::vector<uint8_t> degenerate_;
    // Per edge of the part: whether it is flat where its faces are nearly coplanar (two faces,
    // the same shading, uvs and colours on both sides).
    std::vector<uint8_t> flattenable_;
};

// A solid a closed mesh bounds: its box, and the side of its faces' planes it lies on (-1:
// behind, against the normals of their winding, as for a mesh whose winding turns outwards;
// +1: in front; 0: a part without volume, no side).
struct Solid {
    Vec3d lo, hi;
    int side = 0;
};

// The solids of mesh `mesh_index` (its edges among `edges`, as build_mesh_edges lists them),
// where it is closed: no edge of it is a boundary, and each edge's two faces run along it in
// opposite directions. One per part of the mesh (its faces joined by their corners' positions),
// on the side that makes the part's signed volume positive; appended to `solids`, and
// `solid_of_face[f]` set to face f's (-1 for a degenerate face). False, with nothing added,
// where the mesh is not closed. A ray leaving a face of a closed mesh into its solid meets the
// mesh again before it leaves the solid's box: from there nothing outside the box is seen
// directly (inside a glass ball, the rest of the scene).
bool mesh_solids(const MeshDesc& mesh, int32_t mesh_index, const std::vector<Edge>& edges, std::vector<Solid>& solids,
                 std::vector<int32_t>& solid_of_face);

// Whether the edge is a silhouette seen from point `p`: a boundary always; otherwise when p is
// in front of exactly one of the two faces (planes through the edge).
inline bool is_silhouette(const Vec3f& p, const Vec3f& e0, const Vec3f& n0, const Vec3f& n1, EdgeKind kind) {
    if (kind == EdgeKind::Boundary) return true;
    const float s0 = dot(p - e0, n0), s1 = dot(p - e0, n1);
    return (s0 > 0.f) != (s1 > 0.f);
}

// The side of the edge (e0, e1) a ray (o, d) passes on: the sign of
//   g = dot(cross(e0 - o, e1 - o), d),
// zero when the ray meets the edge's line. The boundary term of an edge is a line integral of
// (dg/dparameter) / |dg/dsample| (f+ - f-) over the points where g = 0; any positive scaling of g
// leaves that ratio unchanged, so d need not be normalised. The partial derivatives of g:
struct EdgeSideGradient {
    Vec3f d_e0, d_e1, d_o, d_d;
};
inline EdgeSideGradient edge_side_gradient(const Vec3f& e0, const Vec3f& e1, const Vec3f& o, const Vec3f& d) {
    const Vec3f a = e0 - o, b = e1 - o;
    EdgeSideGradient g;
    g.d_e0 = cross(b, d);
    g.d_e1 = cross(d, a);
    g.d_o = -(g.d_e0 + g.d_e1);
    g.d_d = cross(a, b);
    return g;
}

}  // namespace edgepath
