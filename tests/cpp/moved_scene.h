// A test helper: a scene of the form of one whose vertices move.
#pragma once
#include <memory>
#include <vector>

#include "edgepath.h"
#include "scene/scene.h"

namespace edgepath {

// A fresh scene of `desc` in the form of one whose vertices have moved: built at other
// positions (every vertex halved), then updated to desc's. That form has a BVH built for
// refitting and an edge list that keeps the nearly flat edges (marked Edge::flat, empty leaves
// of the edge hierarchy), so that later moves keep the list and refit the tree. `update`, if
// given, receives what the update did (a rebuild: the BVH becomes refittable).
inline std::shared_ptr<Scene> build_moved(const SceneDesc& desc, SceneUpdate* update = nullptr) {
    SceneDesc other = desc;
    std::vector<std::vector<float>> halved(desc.meshes.size());
    for (size_t i = 0; i < desc.meshes.size(); ++i) {
        halved[i].assign(desc.meshes[i].vertices, desc.meshes[i].vertices + 3 * desc.meshes[i].num_vertices);
        for (float& x : halved[i]) x *= 0.5f;
        other.meshes[i].vertices = halved[i].data();
    }
    const std::shared_ptr<Scene> s = build_scene(other);
    const SceneUpdate done = update_scene(*s, desc);
    if (update) *update = done;
    return s;
}

}  // namespace edgepath
