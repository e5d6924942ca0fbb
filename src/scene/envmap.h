// Lat-long environment map (Mitsuba's convention, see scene/desc.h), importance-sampled by a
// piecewise-constant distribution over the cells between texels, weighted by sin(theta).
#pragma once
#include <cmath>
#include "sampling/distribution.h"
#include "sampling/warp.h"
#include "scene/texture.h"

namespace edgepath {

struct Envmap {
    Texture tex;
    float to_world[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    float scale = 1.f;
    int rows = 1, cols = 1;  // sampling cells
    Distribution2D dist;

    void build(const EnvmapDesc& d) {
        tex = Texture(d.values);
        for (int i = 0; i < 9; ++i) to_world[i] = d.to_world[i];
        scale = d.scale;
        rows = std::max(tex.height - 1, 1);
        cols = tex.width;
        std::vector<double> w(size_t(rows) * cols);
        for (int r = 0; r < rows; ++r) {
            int r1 = std::min(r + 1, tex.height - 1);
            double sin_theta = std::sin((r + 0.5) / rows * 3.14159265358979);
            for (int c = 0; c < cols; ++c) {
                int c1 = (c + 1) % cols;
                double l = luminance(texel(r, c)) + luminance(texel(r, c1)) + luminance(texel(r1, c)) +
                           luminance(texel(r1, c1));
                w[size_t(r) * cols + c] = std::max(0.0, l) * 0.25 * sin_theta;
            }
        }
        dist.build(w, rows, cols);
    }

    Vec3f texel(int row, int col) const {
        const float* p = tex.data + (int64_t(row) * tex.width + col) * tex.channels;
        return Vec3f(p[0], p[1], p[2]);
    }

    Vec3f to_local(const Vec3f& w) const {
        const float* m = to_world;  // local = R^T world
        return {m[0] * w.x + m[3] * w.y + m[6] * w.z, m[1] * w.x + m[4] * w.y + m[7] * w.z,
                m[2] * w.x + m[5] * w.y + m[8] * w.z};
    }
    Vec3f to_world_dir(const Vec3f& l) const {
        const float* m = to_world;
        return {m[0] * l.x + m[1] * l.y + m[2] * l.z, m[3] * l.x + m[4] * l.y + m[5] * l.z,
                m[6] * l.x + m[7] * l.y + m[8] * l.z};
    }

    // Texel-space position (x in [0, W), y in [0, rows]) of a world direction.
    Vec2f position(const Vec3f& world_dir) const {
        Vec3f d = to_local(world_dir);
        float u = std::atan2(d.x, -d.z) * (0.5f * kInvPi);
        u -= std::floor(u);
        float v = std::acos(std::clamp(d.y, -1.f, 1.f)) * kInvPi;
        return {u * float(cols), v * float(rows)};
    }

    Vec3f eval(const Vec3f& world_dir) const {
        Vec2f p = position(world_dir);
        int x0 = std::min(int(p.x), cols - 1), y0 = std::min(int(p.y), rows - 1);
        float tx = p.x - float(x0), ty = tex.height > 1 ? p.y - float(y0) : 0.f;
        int x1 = (x0 + 1) % cols, y1 = std::min(y0 + 1, tex.height - 1);
        Vec3f v = texel(y0, x0) * ((1 - tx) * (1 - ty)) + texel(y0, x1) * (tx * (1 - ty)) +
                  texel(y1, x0) * ((1 - tx) * ty) + texel(y1, x1) * (tx * ty);
        return v * scale;
    }

    float pdf(const Vec3f& world_dir) const {
        if (!dist.valid()) return 0.f;
        Vec2f p = position(world_dir);
        int c = std::min(int(p.x), cols - 1), r = std::min(int(p.y), rows - 1);
        float sin_theta = std::sin(p.y / float(rows) * kPi);
        if (sin_theta <= 0.f) return 0.f;
        return dist.pmf(r, c) * float(rows * cols) / (2.f * kPi * kPi * sin_theta);
    }

    bool sample(float u1, float u2, Vec3f& world_dir, float& pdf_out) const {
        if (!dist.valid()) return false;
        int r, c;
        dist.sample(u1, u2, r, c);
        float x = (float(c) + u2) / float(cols), y = (float(r) + u1) / float(rows);
        float theta = y * kPi, phi = x * 2.f * kPi;
        float sin_theta = std::sin(theta);
        if (sin_theta <= 0.f) return false;
        Vec3f local(sin_theta * std::sin(phi), std::cos(theta), -sin_theta * std::cos(phi));
        world_dir = to_world_dir(local);
        pdf_out = dist.pmf(r, c) * float(rows * cols) / (2.f * kPi * kPi * sin_theta);
        return pdf_out > 0.f;
    }
};

}  // namespace edgepath
