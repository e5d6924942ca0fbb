// The public C++ API of the edgepath core: describe a scene with views over your own memory
// (scene/desc.h), build it once, render into your own buffer (render/render.h), differentiate
// (diff/backward.h; gradient buffers and directions: scene/gradients.h). This header gathers
// them; the layers below are described in docs/architecture.md.
#pragma once
#include <memory>
#include "diff/backward.h"
#include "render/render.h"
#include "scene/desc.h"

namespace edgepath {

class Scene;

// Validates `desc` (throws std::invalid_argument whose message names the offending field and
// value) and builds the acceleration structure and sampling distributions. The returned scene
// keeps pointers into the memory `desc` views: keep that memory alive and unchanged while the
// scene is used.
std::shared_ptr<const Scene> build_scene(const SceneDesc& desc);

// Size of the rendered image (the crop window if one is set).
int image_width(const Scene& scene);
int image_height(const Scene& scene);

// Triangles of meshes[mesh] that the scene skips as degenerate (zero area, or too thin for a
// normal in float: scene/geometry.h). They render as nothing and get zero gradients.
int64_t degenerate_triangles(const Scene& scene, int mesh);

}  // namespace edgepath
