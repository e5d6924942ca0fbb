#include "edgepath.h"

#include "scene/scene.h"

namespace edgepath {

std::shared_ptr<const Scene> build_scene(const SceneDesc& desc) { return Scene::build(desc); }
int image_width(const Scene& s) { return s.out_width; }
int image_height(const Scene& s) { return s.out_height; }
int64_t degenerate_triangles(const Scene& s, int mesh) { return s.meshes.at(size_t(mesh)).num_degenerate; }

}  // namespace edgepath
