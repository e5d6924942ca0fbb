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
std::shared_ptr<Scene> build_scene(const SceneDesc& desc);

// Points a built scene at a new description of it, for a scene that lives across calls (an
// optimisation loop): validates `desc` as build_scene does and rebuilds only what changed,
// found by comparing contents with the last build's: the BVH and edge list when the topology
// changes, an Embree refit when only vertex positions move, nothing when only materials,
// textures, lights, the environment or the camera change. The scene then keeps pointers into
// the memory `desc` views, as after build_scene. No other call may use the scene meanwhile.
enum class SceneUpdate { Built, Refit, Reused };
SceneUpdate update_scene(Scene& scene, const SceneDesc& desc);
// Another view of a built scene: validates `camera` and replaces the scene's camera (film and
// crop window included); nothing else is rebuilt. No other call may use the scene meanwhile.
void set_scene_camera(Scene& scene, const CameraDesc& camera);
// How often build_scene and update_scene built, refitted and reused the scene's BVH.
struct SceneBuildCounts {
    uint64_t builds = 0, refits = 0, reuses = 0;
};
SceneBuildCounts scene_build_counts(const Scene& scene);
// How often gradient passes built, refitted and reused the scene's edge hierarchy (the
// importance sampler of the edges seen from path vertices), kept across calls and views.
SceneBuildCounts scene_hierarchy_counts(const Scene& scene);

// Size of the rendered image (the crop window if one is set).
int image_width(const Scene& scene);
int image_height(const Scene& scene);

// Triangles of meshes[mesh] that the scene skips as degenerate (zero area, or too thin for a
// normal in float: scene/geometry.h). They render as nothing and get zero gradients.
int64_t degenerate_triangles(const Scene& scene, int mesh);

}  // namespace edgepath
