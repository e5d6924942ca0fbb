// Procedural meshes that own their arrays: used by tests, benchmarks and examples.
#pragma once
#include <cstdint>
#include <vector>
#include "math/vec.h"
#include "scene/desc.h"

namespace edgepath {

struct MeshData {
    std::vector<float> vertices;  // (n, 3)
    std::vector<float> normals;   // (n, 3) or empty
    std::vector<float> uvs;       // (n, 2) or empty
    std::vector<int32_t> indices; // (m, 3)

    int64_t num_vertices() const { return int64_t(vertices.size() / 3); }
    int64_t num_triangles() const { return int64_t(indices.size() / 3); }
    // A view for SceneDesc; valid while this object lives and is unchanged.
    MeshDesc desc(int material) const;
    void transform(const Vec3f& scale, const Vec3f& translate);
    void append(const MeshData& other);  // both must agree on having normals / uvs
};

// UV sphere of radius r around c: `rings` latitude bands, `segments` longitude bands; smooth
// outward normals; uv = (longitude, latitude) in [0,1].
MeshData make_sphere(const Vec3f& c, float r, int rings, int segments);
// Axis-aligned rectangle spanned by corner, corner + e1, corner + e2, corner + e1 + e2; the face
// normal is normalize(cross(e1, e2)); uv (0,0) at the corner.
MeshData make_quad(const Vec3f& corner, const Vec3f& e1, const Vec3f& e2);
// Axis-aligned box with outward faces, flat (no normals).
MeshData make_box(const Vec3f& lo, const Vec3f& hi);

}  // namespace edgepath
