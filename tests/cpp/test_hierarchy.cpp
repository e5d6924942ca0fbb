// The edge hierarchy: sample() and pdf() agree, and the probabilities sum to one.
#include <gtest/gtest.h>

#include <map>
#include <vector>

#include "edgepath.h"
#include "edges/hierarchy.h"
#include "sampling/rng.h"
#include "scene/scene.h"
#include "scene/shapes.h"

namespace edgepath {
namespace {

struct HierarchyScene {
    MeshData sphere = make_sphere(Vec3f(0, 1, 0), 0.5f, 8, 16), box = make_box(Vec3f(1.5f, 0.2f, 0), Vec3f(0.4f, 0.4f, 0.4f)),
             quad = make_quad(Vec3f(-2, 0, -2), Vec3f(4, 0, 0), Vec3f(0, 0, 4));
    std::vector<float> kd = {0.5f, 0.5f, 0.5f}, ks = {0, 0, 0}, rough = {0.5f};
    std::shared_ptr<const Scene> scene;
    HierarchyScene() {
        SceneDesc d;
        d.camera.width = d.camera.height = 8;
        d.camera.position[2] = -5;
        MaterialDesc m;
        m.diffuse = {kd.data(), 1, 1, 3};
        m.specular = {ks.data(), 1, 1, 3};
        m.roughness = {rough.data(), 1, 1, 1};
        d.materials.push_back(m);
        d.meshes = {sphere.desc(0), box.desc(0), quad.desc(0)};
        scene = build_scene(d);
    }
};

TEST(EdgeHierarchy, SampleAndPdfAgree) {
    HierarchyScene hs;
    const Scene& scene = *hs.scene;
    std::vector<int32_t> ids(scene.edges().size());
    for (size_t i = 0; i < ids.size(); ++i) ids[i] = int32_t(i);
    EdgeHierarchy h;
    h.build(scene, ids);
    BoundsCone cone;
    cone.axis = normalize(Vec3f(0.3f, 1, 0.1f));
    cone.cos_half = 0.9f;
    for (int with_cone = 0; with_cone < 2; ++with_cone) {
        EdgeHierarchy::Query q;
        q.p = Vec3f(0.3f, 0.01f, 0.4f);
        q.n = Vec3f(0, 1, 0);
        q.cone = with_cone ? &cone : nullptr;
        // Descents that end where no edge can contribute fail; the rest of the mass is the
        // edges' probabilities.
        double sum = 0;
        for (size_t e = 0; e < ids.size(); ++e) sum += h.pdf(q, int32_t(e));
        EXPECT_GT(sum, 0.1) << "cone " << with_cone;
        EXPECT_LE(sum, 1.0 + 1e-5) << "cone " << with_cone;
        const int n = 200000;
        std::map<int32_t, int> counts;
        int failed = 0;
        Rng rng(7, 1);
        for (int i = 0; i < n; ++i) {
            int32_t e;
            float prob;
            if (!h.sample(q, rng.next_float(), e, prob)) {
                ++failed;
                continue;
            }
            EXPECT_NEAR(prob, h.pdf(q, e), 1e-5f * prob);
            counts[e]++;
        }
        EXPECT_NEAR(failed, n * (1 - sum), 5 * std::sqrt(n * sum * (1 - sum)) + 1);
        for (const auto& [e, c] : counts) {
            const double p = h.pdf(q, e), sigma = std::sqrt(n * p * (1 - p)) + 1;
            EXPECT_NEAR(c, n * p, 5 * sigma) << "edge " << e;
        }
    }
}

}  // namespace
}  // namespace edgepath
