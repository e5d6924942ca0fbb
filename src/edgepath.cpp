#include "edgepath.h"

#include "scene/scene.h"

namespace edgepath {

std::shared_ptr<Scene> build_scene(const SceneDesc& desc) { return Scene::build(desc); }
SceneUpdate update_scene(Scene& s, const SceneDesc& desc) { return SceneUpdate(int(s.update(desc))); }
void set_scene_camera(Scene& s, const CameraDesc& camera) { s.set_camera(camera); }
SceneBuildCounts scene_build_counts(const Scene& s) {
    const Scene::BuildStats& b = s.build_stats();
    return {b.builds, b.refits, b.reuses};
}
SceneBuildCounts scene_hierarchy_counts(const Scene& s) {
    const Scene::HierarchyStats& h = s.hierarchy_stats();
    return {h.builds, h.refits, h.reuses};
}
int image_width(const Scene& s) { return s.out_width; }
int image_height(const Scene& s) { return s.out_height; }
int64_t degenerate_triangles(const Scene& s, int mesh) { return s.meshes.at(size_t(mesh)).num_degenerate; }

}  // namespace edgepath
