#include "io/obj.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <tiny_obj_loader.h>

#include "io/image.h"

namespace edgepath {

float roughness_from_phong_exponent(float ns) {
    return std::sqrt(2.f / (std::max(ns, 0.f) + 2.f));
}

namespace {

std::string directory_of(const std::string& path) {
    const size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
}

std::string resolve_texture(const std::string& obj_dir, std::string name) {
    if (name.empty()) return name;
    std::replace(name.begin(), name.end(), '\\', '/');
    if (name.front() == '/') return name;
    return obj_dir + name;
}

ObjMaterial convert_material(const tinyobj::material_t& m, const std::string& obj_dir) {
    ObjMaterial out;
    out.name = m.name;
    out.defined = true;
    for (int i = 0; i < 3; ++i) {
        out.diffuse[i] = static_cast<float>(m.diffuse[i]);
        out.specular[i] = static_cast<float>(m.specular[i]);
        out.emission[i] = static_cast<float>(m.emission[i]);
    }
    out.roughness = roughness_from_phong_exponent(static_cast<float>(m.shininess));
    out.diffuse_texture = resolve_texture(obj_dir, m.diffuse_texname);
    return out;
}

// Maps the file's indices of one attribute (positions, uvs or normals) to a compact range
// for one mesh, copying the used values. `touched` remembers which entries to reset.
class Compactor {
public:
    Compactor(const std::vector<tinyobj::real_t>& values, int dim)
        : values_(values), dim_(dim), map_(values.size() / dim, -1) {}

    size_t size() const { return map_.size(); }

    int32_t add(int file_index, std::vector<float>& out) {
        int32_t& local = map_[file_index];
        if (local < 0) {
            local = static_cast<int32_t>(out.size() / dim_);
            touched_.push_back(file_index);
            for (int k = 0; k < dim_; ++k)
                out.push_back(static_cast<float>(values_[static_cast<size_t>(file_index) * dim_ + k]));
        }
        return local;
    }

    void reset() {
        for (int i : touched_) map_[i] = -1;
        touched_.clear();
    }

private:
    const std::vector<tinyobj::real_t>& values_;
    int dim_;
    std::vector<int32_t> map_;
    std::vector<int> touched_;
};

struct FaceRef {
    size_t shape, face;
};

}  // namespace

std::vector<ObjMesh> load_obj(const std::string& path) {
    tinyobj::ObjReaderConfig config;
    config.triangulate = true;
    config.vertex_color = false;
    tinyobj::ObjReader reader;
    if (!reader.ParseFromFile(path, config)) {
        std::string message = reader.Error();
        while (!message.empty() && (message.back() == '\n' || message.back() == '\r'))
            message.pop_back();
        throw IoError(path + ": " + (message.empty() ? "cannot read OBJ file" : message));
    }
    const tinyobj::attrib_t& attrib = reader.GetAttrib();
    const std::vector<tinyobj::shape_t>& shapes = reader.GetShapes();
    const std::vector<tinyobj::material_t>& materials = reader.GetMaterials();
    const std::string obj_dir = directory_of(path);

    // Group faces by material id, in order of first use.
    std::vector<int> group_material;
    std::unordered_map<int, size_t> group_of_material;
    std::vector<std::vector<FaceRef>> group_faces;
    for (size_t s = 0; s < shapes.size(); ++s) {
        const tinyobj::mesh_t& mesh = shapes[s].mesh;
        for (size_t f = 0; f < mesh.num_face_vertices.size(); ++f) {
            if (mesh.num_face_vertices[f] != 3)
                throw IoError(path + ": face " + std::to_string(f) + " of '" + shapes[s].name +
                              "' has " + std::to_string(mesh.num_face_vertices[f]) +
                              " vertices after triangulation");
            int id = f < mesh.material_ids.size() ? mesh.material_ids[f] : -1;
            if (id < 0 || id >= static_cast<int>(materials.size())) id = -1;
            auto [it, inserted] = group_of_material.try_emplace(id, group_faces.size());
            if (inserted) {
                group_material.push_back(id);
                group_faces.emplace_back();
            }
            group_faces[it->second].push_back({s, f});
        }
    }

    Compactor positions(attrib.vertices, 3), uvs(attrib.texcoords, 2),
        normals(attrib.normals, 3);
    auto check = [&](int index, const Compactor& table, const char* what) {
        if (index < 0 || static_cast<size_t>(index) >= table.size())
            throw IoError(path + ": " + what + " index " + std::to_string(index + 1) +
                          " out of range (" + std::to_string(table.size()) + " defined)");
    };

    std::vector<ObjMesh> meshes(group_faces.size());
    for (size_t g = 0; g < group_faces.size(); ++g) {
        ObjMesh& out = meshes[g];
        if (group_material[g] >= 0) out.material = convert_material(materials[group_material[g]], obj_dir);
        size_t with_uv = 0, with_normal = 0;
        for (const FaceRef& ref : group_faces[g]) {
            const tinyobj::mesh_t& mesh = shapes[ref.shape].mesh;
            for (int k = 0; k < 3; ++k) {
                const tinyobj::index_t& index = mesh.indices[ref.face * 3 + k];
                check(index.vertex_index, positions, "position");
                out.indices.push_back(positions.add(index.vertex_index, out.positions));
                if (index.texcoord_index >= 0) {
                    check(index.texcoord_index, uvs, "texture coordinate");
                    out.uv_indices.push_back(uvs.add(index.texcoord_index, out.uvs));
                    ++with_uv;
                }
                if (index.normal_index >= 0) {
                    check(index.normal_index, normals, "normal");
                    out.normal_indices.push_back(normals.add(index.normal_index, out.normals));
                    ++with_normal;
                }
            }
        }
        positions.reset();
        uvs.reset();
        normals.reset();
        const size_t corners = out.indices.size();
        const std::string group = "material group '" + out.material.name + "'";
        if (with_uv != 0 && with_uv != corners)
            throw IoError(path + ": " + group + " mixes faces with and without uvs");
        if (with_normal != 0 && with_normal != corners)
            throw IoError(path + ": " + group + " mixes faces with and without normals");
        // v = 0 is the top row of an image (Mitsuba's convention); OBJ has v = 0 at the bottom.
        for (size_t i = 1; i < out.uvs.size(); i += 2) out.uvs[i] = 1.f - out.uvs[i];
    }
    return meshes;
}

}  // namespace edgepath
