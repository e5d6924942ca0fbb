// Wavefront OBJ (+ MTL) loading through tinyobjloader. Faces are triangulated and grouped by
// material: one ObjMesh per material used, in order of first use in the file. Each mesh keeps
// only the vertices its faces use, with separate index arrays for positions, uvs and normals
// (as the file has them), ready for MeshDesc.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace edgepath {

struct ObjMaterial {
    std::string name;                   // MTL name; empty for faces with no (known) material
    bool defined = false;               // false: no usemtl, or an unknown material name
    float diffuse[3] = {0, 0, 0};       // Kd
    float specular[3] = {0, 0, 0};      // Ks
    float emission[3] = {0, 0, 0};      // Ke
    float roughness = 1.f;              // GGX alpha from Ns: sqrt(2 / (Ns + 2))
    std::string diffuse_texture;        // map_Kd resolved relative to the OBJ file, or empty
};

struct ObjMesh {
    std::vector<float> positions;       // (num_positions, 3)
    std::vector<float> uvs;             // (num_uvs, 2), v flipped (v = 0 is the image top); may be empty
    std::vector<float> normals;         // (num_normals, 3); may be empty
    std::vector<int32_t> indices;       // (num_triangles, 3) into positions
    std::vector<int32_t> uv_indices;    // (num_triangles, 3) into uvs, or empty when no uvs
    std::vector<int32_t> normal_indices;  // (num_triangles, 3) into normals, or empty
    ObjMaterial material;
    int64_t num_triangles() const { return static_cast<int64_t>(indices.size() / 3); }
};

// GGX alpha for a Phong exponent Ns (the usual Blinn-Phong / Beckmann correspondence).
float roughness_from_phong_exponent(float ns);

// Throws IoError (image.h) naming the path if the file cannot be read or parsed, or if a
// material group mixes faces with and without uvs (or normals).
std::vector<ObjMesh> load_obj(const std::string& path);

}  // namespace edgepath
