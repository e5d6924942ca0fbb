// Lat-long environment map (Mitsuba's convention, see scene/desc.h), importance-sampled by a
// piecewise-constant distribution over the cells between texels, weighted by sin(theta); a
// constant map (one texel), uniformly over the sphere. An image alone samples it by the light
// above its mean instead (compensated()).
#pragma once
#include <cmath>
#include <memory>
#include <mutex>
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
        for_each_cell([&](int r, int c, double l, double sin_theta) { w[size_t(r) * cols + c] = l * sin_theta; });
        dist.build(w, rows, cols);
        compensated_ = std::make_shared<Compensated>();
    }

    // The distribution of the light samples of an image that combines them with the BSDF's
    // samples and that no gradient pass retraces (render/path.h, env_nee): each cell's
    // luminance less the map's mean over the sphere, where positive (the "MIS compensation" of
    // Karlik et al. 2019). Where the map is no brighter than its mean the BSDF's samples find its
    // light well enough, and the light samples go where it is brighter. Empty for a map nowhere
    // above its mean by more than rounding (a uniform one): the BSDF's samples alone find it.
    // Built at its first use (a render's, on any thread), and shared by the copies of this map.
    const Distribution2D& compensated() const {
        Compensated& k = *compensated_;
        std::call_once(k.once, [&] {
            double sum = 0, solid = 0;
            for_each_cell([&](int, int, double l, double sin_theta) {
                sum += l * sin_theta;
                solid += sin_theta;
            });
            const double mean = solid > 0 ? sum / solid : 0;
            // A uniform map's cells differ from its mean by rounding alone: no light above it.
            const double above = mean * (1.0 + 1e-6);
            std::vector<double> w(size_t(rows) * cols);
            for_each_cell([&](int r, int c, double l, double sin_theta) {
                w[size_t(r) * cols + c] = l > above ? (l - mean) * sin_theta : 0.0;
            });
            k.dist.build(w, rows, cols);
        });
        return k.dist;
    }

    // f(row, col, l, sin_theta) for every sampling cell: its mean luminance l (of its four
    // texels, no lower than 0) and the sine of its centre's polar angle.
    template <class F>
    void for_each_cell(F&& f) const {
        for (int r = 0; r < rows; ++r) {
            int r1 = std::min(r + 1, tex.height - 1);
            double sin_theta = std::sin((r + 0.5) / rows * 3.14159265358979);
            for (int c = 0; c < cols; ++c) {
                int c1 = (c + 1) % cols;
                double l = luminance(texel(r, c)) + luminance(texel(r, c1)) + luminance(texel(r1, c)) +
                           luminance(texel(r1, c1));
                f(r, c, std::max(0.0, l) * 0.25, sin_theta);
            }
        }
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

    // Texel-space position of a world direction: x in [0, W) (column i at x = i, so u = (x +
    // 0.5) / W, wrapping), y in [0, rows] (row j at y = j).
    Vec2f position(const Vec3f& world_dir) const {
        Vec3f d = to_local(world_dir);
        float u = std::atan2(d.x, -d.z) * (0.5f * kInvPi);
        float x = u * float(cols) - 0.5f;
        x -= float(cols) * std::floor(x / float(cols));
        if (x >= float(cols)) x = 0.f;  // rounding of tiny negative x
        float v = std::acos(std::clamp(d.y, -1.f, 1.f)) * kInvPi;
        return {x, v * float(rows)};
    }

    // One texel (a constant environment, as Mitsuba's `constant` emitter): the same value in
    // every direction. Its lookups skip the direction's position (an arc tangent and an arc
    // cosine), which only weighs the texel against itself (the bilinear weights add up to 1, up
    // to rounding), and it is sampled uniformly over the sphere where it is sampled at all (an
    // image alone leaves it to the BSDF: its compensated() is empty): density 1 / (4 pi)
    // everywhere, where the lat-long cells' density would be 1 / (2 pi^2 sin theta), heavier at
    // the poles and with more variance for the same value.
    bool constant() const { return tex.width == 1 && tex.height == 1; }
    static constexpr float kUniformPdf = 0.25f * kInvPi;

    // The four texels of a lookup, their weights, and the derivatives of the weights with
    // respect to the local direction (for unit directions).
    struct Footprint {
        int64_t texel[4];
        float weight[4];
        Vec3f dweight[4];  // d weight / d local direction
    };

    // The footprint with its weights' derivatives (the gradient pass).
    Footprint footprint(const Vec3f& world_dir) const {
        Footprint f;
        float tx, ty;
        weights(world_dir, f, tx, ty);
        // x = W atan2(d.x, -d.z) / (2 pi) - 1/2, y = rows acos(d.y) / pi.
        Vec3f d = to_local(world_dir);
        float r2 = d.x * d.x + d.z * d.z;
        Vec3f dx(0.f), dy(0.f);
        if (r2 > 1e-12f) {
            float k = float(cols) * 0.5f * kInvPi / r2;
            dx = Vec3f(-d.z * k, 0.f, d.x * k);
            if (tex.height > 1)
                dy = Vec3f(0.f, -float(rows) * kInvPi / std::sqrt(std::max(1.f - d.y * d.y, 1e-12f)), 0.f);
        }
        f.dweight[0] = dx * (-(1 - ty)) + dy * (-(1 - tx));
        f.dweight[1] = dx * (1 - ty) + dy * (-tx);
        f.dweight[2] = dx * (-ty) + dy * (1 - tx);
        f.dweight[3] = dx * ty + dy * tx;
        return f;
    }

    // The texels and weights alone (dweight left unset), and the position inside the cell (tx, ty):
    // what a lookup needs.
    void weights(const Vec3f& world_dir, Footprint& f, float& tx, float& ty) const {
        weights_at(position(world_dir), f, tx, ty);
    }
    // The same at a texel-space position (position()).
    void weights_at(const Vec2f& p, Footprint& f, float& tx, float& ty) const {
        int x0 = std::min(int(p.x), cols - 1), y0 = std::min(int(p.y), rows - 1);
        tx = p.x - float(x0);
        ty = tex.height > 1 ? p.y - float(y0) : 0.f;
        int x1 = (x0 + 1) % cols, y1 = std::min(y0 + 1, tex.height - 1);
        const int64_t W = tex.width;
        f.texel[0] = y0 * W + x0;
        f.texel[1] = y0 * W + x1;
        f.texel[2] = y1 * W + x0;
        f.texel[3] = y1 * W + x1;
        f.weight[0] = (1 - tx) * (1 - ty);
        f.weight[1] = tx * (1 - ty);
        f.weight[2] = (1 - tx) * ty;
        f.weight[3] = tx * ty;
    }

    Vec3f eval(const Vec3f& world_dir) const {
        return constant() ? texel(0) * scale : eval_at(position(world_dir));
    }
    // The value towards world_dir and the density sample() gives it (with the same
    // `compensated`), from one position lookup.
    Vec3f eval(const Vec3f& world_dir, float& pdf_out, bool compensated = false) const {
        if (constant()) {
            pdf_out = (compensated ? this->compensated() : dist).valid() ? kUniformPdf : 0.f;
            return texel(0) * scale;
        }
        const Vec2f p = position(world_dir);
        pdf_out = pdf_at(p, compensated);
        return eval_at(p);
    }
    Vec3f eval_at(const Vec2f& p) const {
        // The weights only: a lookup of the forward pass needs no derivatives.
        Footprint f;
        float tx, ty;
        weights_at(p, f, tx, ty);
        Vec3f v(0.f);
        for (int k = 0; k < 4; ++k) v += texel(f.texel[k]) * f.weight[k];
        return v * scale;
    }
    Vec3f texel(int64_t index) const { return Vec3f::load(tex.data + index * tex.channels); }

    float pdf(const Vec3f& world_dir) const {
        if (!dist.valid()) return 0.f;
        return constant() ? kUniformPdf : pdf_at(position(world_dir));
    }
    float pdf_at(const Vec2f& p, bool compensated = false) const {
        const Distribution2D& d = compensated ? this->compensated() : dist;
        if (!d.valid()) return 0.f;
        int c = std::min(int(p.x), cols - 1), r = std::min(int(p.y), rows - 1);
        float sin_theta = std::sin(p.y / float(rows) * kPi);
        if (sin_theta <= 0.f) return 0.f;
        return d.pmf(r, c) * float(rows * cols) / (2.f * kPi * kPi * sin_theta);
    }

    // A direction by `dist`, or by compensated() (then never a constant map's); `value`, if
    // given, gets the map's value there (eval's, from the sampled position itself: no arc
    // tangent and arc cosine of the direction to find it again).
    bool sample(float u1, float u2, Vec3f& world_dir, float& pdf_out, bool compensated = false,
                Vec3f* value = nullptr) const {
        const Distribution2D& d = compensated ? this->compensated() : dist;
        if (!d.valid()) return false;
        if (constant()) {  // uniform: no rotation needed
            world_dir = square_to_sphere(u1, u2);
            pdf_out = kUniformPdf;
            if (value) *value = texel(0) * scale;
            return true;
        }
        int r = 0, c = 0;
        d.sample(u1, u2, r, c);
        // Cell c lies between columns c and c + 1: u from (c + 0.5) / W to (c + 1.5) / W.
        float x = (float(c) + 0.5f + u2) / float(cols), y = (float(r) + u1) / float(rows);
        float theta = y * kPi, phi = x * 2.f * kPi;
        float sin_theta = std::sin(theta);
        if (sin_theta <= 0.f) return false;
        Vec3f local(sin_theta * std::sin(phi), std::cos(theta), -sin_theta * std::cos(phi));
        world_dir = to_world_dir(local);
        pdf_out = d.pmf(r, c) * float(rows * cols) / (2.f * kPi * kPi * sin_theta);
        // The texel-space position of the direction (position()'s): x * cols - 1/2, y * rows.
        if (value) *value = eval_at(Vec2f(std::min(float(c) + u2, std::nextafter(float(cols), 0.f)), float(r) + u1));
        return pdf_out > 0.f;
    }

private:
    struct Compensated {
        std::once_flag once;
        Distribution2D dist;
    };
    std::shared_ptr<Compensated> compensated_ = std::make_shared<Compensated>();
};

}  // namespace edgepath
