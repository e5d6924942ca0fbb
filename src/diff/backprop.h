// The adjoint sweep of one recorded path (interior term of the gradient, see
// docs: every direction after the camera is held fixed in world space; pdfs and MIS weights are
// constants). Boundary terms (edge sampling) are added by their own passes.
#pragma once
#include "diff/gradients.h"
#include "render/path.h"

namespace edgepath {

class SecondaryEdges;

// Adds d(adjoint . L)/d(parameters) for the path in `rec` to `sink`; with `secondary`, also the
// boundary term of the edges seen from each scattering vertex (edges/secondary.h).
void backprop_path(const Scene& scene, const SceneGradients& slots, const PathRecord& rec, const Vec3f& adjoint,
                   GradSink& sink, const SecondaryEdges* secondary = nullptr);

}  // namespace edgepath
