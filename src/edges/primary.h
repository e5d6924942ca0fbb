// The boundary term of primary visibility: edges seen by the camera (edge sampling, section 3 of
// the docs). Silhouette edges are projected to the film, clipped to the output (widened by the
// pixel filter), and sampled in proportion to their clipped film length; at each sample a full
// camera path is traced on each side of the edge, in the limit at the edge point (edges/sides.h),
// and the difference, weighted by the pixel filter (and by the adjoint image in reverse mode),
// moves the edge's two vertices and the camera through the derivative of the side function
// (scene/edges.h). The side paths of several samples are traced together (render/batch.h).
#pragma once
#include "render/channels.h"
#include "scene/desc.h"
#include "scene/gradients.h"
#include "scene/scene.h"

namespace edgepath {

// The most edge samples whose side paths are traced together (two paths each, a PathBatch's
// worth).
constexpr int kPrimaryEdgeBatch = 32;

// Whether the pass has anything to do: it is switched on and some vertex or the camera is wanted.
bool primary_edges_wanted(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots);

// Reverse mode: adds d(adjoint . image)/d(parameter) to the slots' gradient buffers
// (adjoint: the output image's (H, W, layout.num_values) adjoint). Forward mode
// (adjoint == nullptr): adds the term's share of the derivative image along the slots'
// directions to `out` (H, W, layout.num_values). The image holds the layout's continuous
// channels: each side of an edge sample traces a path (radiance) and evaluates the camera
// ray's first hit (the other channels). With the geometric normal, the smooth edges of meshes
// with shading normals (where only that normal jumps) are sampled too. `batch`: how many edge
// samples' side paths are traced together, 1 to kPrimaryEdgeBatch; the result is the same for
// any, bit for bit.
void primary_edge_pass(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots,
                       const ChannelLayout& layout, const float* adjoint, float* out,
                       int batch = kPrimaryEdgeBatch);

// The radiance image alone (H, W, 3).
inline void primary_edge_pass(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots,
                              const float* adjoint, float* out) {
    primary_edge_pass(scene, opt, slots, ChannelLayout::radiance(), adjoint, out);
}

}  // namespace edgepath
