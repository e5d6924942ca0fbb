#include "io/obj.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cfloat>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string_view>
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

// ---- checking the text before tinyobjloader reads it ---------------------------------------
// tinyobjloader reads an unparsable number as 0, drops faces of fewer than three vertices and
// reads a binary file as an empty mesh, all without a word: these checks name the line instead.

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

std::vector<std::string_view> split_words(std::string_view line) {
    std::vector<std::string_view> words;
    size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && is_space(line[i])) ++i;
        const size_t start = i;
        while (i < line.size() && !is_space(line[i])) ++i;
        if (i > start) words.push_back(line.substr(start, i - start));
    }
    return words;
}

// A decimal number (digits, sign, point, exponent; no hex, inf or nan) finite as a float.
bool parse_float(std::string_view word) {
    if (word.empty() || word.size() > 64) return false;
    for (char c : word)
        if (!std::isdigit(static_cast<unsigned char>(c)) && !std::strchr("+-.eE", c)) return false;
    const std::string text(word);
    char* end = nullptr;
    const double value = std::strtod(text.c_str(), &end);
    return end == text.c_str() + text.size() && std::fabs(value) <= FLT_MAX;
}

// A nonzero integer that fits in int32 (OBJ indices count from 1; negative: from the end).
bool parse_index(std::string_view word) {
    if (word.empty() || word.size() > 11) return false;
    size_t i = word[0] == '-' || word[0] == '+' ? 1 : 0;
    if (i == word.size()) return false;
    for (size_t k = i; k < word.size(); ++k)
        if (!std::isdigit(static_cast<unsigned char>(word[k]))) return false;
    const long long value = std::strtoll(std::string(word).c_str(), nullptr, 10);
    return value != 0 && value >= INT32_MIN && value <= INT32_MAX;
}

// v, v/vt, v//vn or v/vt/vn.
bool parse_face_corner(std::string_view word) {
    const size_t a = word.find('/');
    if (a == std::string_view::npos) return parse_index(word);
    const size_t b = word.find('/', a + 1);
    const std::string_view v = word.substr(0, a);
    const std::string_view t = word.substr(a + 1, b == std::string_view::npos ? b : b - a - 1);
    if (b == std::string_view::npos) return parse_index(v) && parse_index(t);
    const std::string_view n = word.substr(b + 1);
    return parse_index(v) && (t.empty() || parse_index(t)) && parse_index(n);
}

void check_obj_text(const std::string& path) {
    std::ifstream file(path, std::ios::binary);
    if (!file) throw IoError(path + ": cannot open (" + std::strerror(errno) + ")");
    std::ostringstream buffer;
    buffer << file.rdbuf();
    const std::string text = buffer.str();
    size_t line_start = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;  // a UTF-8 byte order mark
    for (size_t number = 1; line_start < text.size(); ++number) {
        size_t line_end = text.find('\n', line_start);
        if (line_end == std::string::npos) line_end = text.size();
        const std::string_view line(text.data() + line_start, line_end - line_start);
        line_start = line_end + 1;
        const auto where = [&] { return path + ":" + std::to_string(number) + ": "; };
        for (char c : line)
            if (static_cast<unsigned char>(c) < 0x20 && !is_space(c))
                throw IoError(where() + "control character " + std::to_string(int(c)) +
                              " in the text (a binary or UTF-16 file, not an OBJ file)");
        const std::vector<std::string_view> words = split_words(line);
        if (words.empty() || words[0][0] == '#') continue;
        const std::string_view key = words[0];
        size_t minimum = 0;
        if (key == "v" || key == "vn") minimum = 3;
        else if (key == "vt") minimum = 1;
        else if (key != "f") continue;
        const size_t count = words.size() - 1;
        if (key == "f") {
            if (count < 3)
                throw IoError(where() + "a face needs at least 3 vertices, this one has " +
                              std::to_string(count));
            for (size_t i = 1; i < words.size(); ++i)
                if (!parse_face_corner(words[i]))
                    throw IoError(where() + "cannot read face vertex '" + std::string(words[i]) +
                                  "' (expected v, v/vt, v//vn or v/vt/vn with nonzero indices)");
            continue;
        }
        if (count < minimum)
            throw IoError(where() + "'" + std::string(key) + "' needs at least " +
                          std::to_string(minimum) + " numbers, got " + std::to_string(count));
        for (size_t i = 1; i < words.size(); ++i)
            if (!parse_float(words[i]))
                throw IoError(where() + "cannot read '" + std::string(words[i]) +
                              "' as a finite number");
    }
}

}  // namespace

std::vector<ObjMesh> load_obj(const std::string& path) {
    check_obj_text(path);
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
