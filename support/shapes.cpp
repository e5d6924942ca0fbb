#include "support/shapes.h"

#include <cmath>

namespace edgepath {

MeshDesc MeshData::desc(int material) const {
    MeshDesc d;
    d.vertices = vertices.data();
    d.num_vertices = num_vertices();
    d.indices = indices.data();
    d.num_triangles = num_triangles();
    if (!uvs.empty()) {
        d.uvs = uvs.data();
        d.num_uvs = int64_t(uvs.size() / 2);
    }
    if (!normals.empty()) {
        d.normals = normals.data();
        d.num_normals = int64_t(normals.size() / 3);
    }
    d.material = material;
    return d;
}

void MeshData::transform(const Vec3f& scale, const Vec3f& translate) {
    for (size_t i = 0; i < vertices.size(); i += 3)
        for (int k = 0; k < 3; ++k) vertices[i + k] = vertices[i + k] * scale[k] + translate[k];
    for (size_t i = 0; i < normals.size(); i += 3) {
        Vec3f n(normals[i] / scale.x, normals[i + 1] / scale.y, normals[i + 2] / scale.z);
        n = normalize(n);
        normals[i] = n.x;
        normals[i + 1] = n.y;
        normals[i + 2] = n.z;
    }
}

void MeshData::append(const MeshData& o) {
    int32_t base = int32_t(num_vertices());
    vertices.insert(vertices.end(), o.vertices.begin(), o.vertices.end());
    normals.insert(normals.end(), o.normals.begin(), o.normals.end());
    uvs.insert(uvs.end(), o.uvs.begin(), o.uvs.end());
    for (int32_t i : o.indices) indices.push_back(i + base);
}

MeshData make_sphere(const Vec3f& c, float r, int rings, int segments) {
    MeshData m;
    const double pi = 3.14159265358979323846;
    // Poles are single vertices, so no triangle is degenerate.
    auto push = [&](const Vec3f& n, float u, float v) {
        Vec3f p = c + n * r;
        m.vertices.insert(m.vertices.end(), {p.x, p.y, p.z});
        m.normals.insert(m.normals.end(), {n.x, n.y, n.z});
        m.uvs.insert(m.uvs.end(), {u, v});
    };
    push(Vec3f(0, 1, 0), 0.5f, 0.f);
    for (int i = 1; i < rings; ++i) {
        double theta = pi * i / rings;
        for (int j = 0; j < segments; ++j) {
            double phi = 2 * pi * j / segments;
            push(Vec3f(float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)), float(-std::sin(theta) * std::sin(phi))),
                 float(double(j) / segments), float(double(i) / rings));
        }
    }
    push(Vec3f(0, -1, 0), 0.5f, 1.f);
    auto ring = [&](int i, int j) { return int32_t(1 + (i - 1) * segments + (j % segments)); };
    int32_t south = int32_t(m.num_vertices() - 1);
    for (int j = 0; j < segments; ++j) m.indices.insert(m.indices.end(), {0, ring(1, j), ring(1, j + 1)});
    for (int i = 1; i < rings - 1; ++i)
        for (int j = 0; j < segments; ++j) {
            int32_t a = ring(i, j), b = ring(i, j + 1), cc = ring(i + 1, j), d = ring(i + 1, j + 1);
            m.indices.insert(m.indices.end(), {a, cc, d, a, d, b});
        }
    for (int j = 0; j < segments; ++j) m.indices.insert(m.indices.end(), {south, ring(rings - 1, j + 1), ring(rings - 1, j)});
    return m;
}

MeshData make_quad(const Vec3f& corner, const Vec3f& e1, const Vec3f& e2) {
    MeshData m;
    Vec3f p[4] = {corner, corner + e1, corner + e1 + e2, corner + e2};
    float uv[8] = {0, 0, 1, 0, 1, 1, 0, 1};
    for (int i = 0; i < 4; ++i) m.vertices.insert(m.vertices.end(), {p[i].x, p[i].y, p[i].z});
    m.uvs.assign(uv, uv + 8);
    m.indices = {0, 1, 2, 0, 2, 3};
    return m;
}

MeshData make_box(const Vec3f& lo, const Vec3f& hi) {
    MeshData m;
    Vec3f s = hi - lo;
    auto face = [&](const Vec3f& corner, const Vec3f& e1, const Vec3f& e2) {
        MeshData q = make_quad(corner, e1, e2);
        q.uvs.clear();
        m.append(q);
    };
    Vec3f ex(s.x, 0, 0), ey(0, s.y, 0), ez(0, 0, s.z);
    face(lo, ey, ex);                 // -z
    face(lo + ez, ex, ey);            // +z
    face(lo, ez, ey);                 // -x
    face(lo + ex, ey, ez);            // +x
    face(lo, ex, ez);                 // -y
    face(lo + ey, ez, ex);            // +y
    return m;
}

}  // namespace edgepath
