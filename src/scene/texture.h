// Textures: float arrays (height, width, channels) with bilinear lookup, wrapping in u and v.
// Texel (i, j) has its centre at uv = ((i + 0.5) / width, (j + 0.5) / height); v = 0 is row 0.
// A lookup is split into a footprint (which texels, which weights) and a weighted sum, so the
// adjoint pass can scatter gradients into the same four texels.
#pragma once
#include <cmath>
#include <cstdint>
#include "math/vec.h"
#include "scene/desc.h"

namespace edgepath {

struct Texture {
    const float* data = nullptr;
    int height = 0, width = 0, channels = 0;

    Texture() = default;
    explicit Texture(const TextureDesc& d) : data(d.data), height(d.height), width(d.width), channels(d.channels) {}
    bool empty() const { return data == nullptr; }
    bool is_constant() const { return width == 1 && height == 1; }
};

// Four texels and their bilinear weights (offsets are texel indices, not float offsets).
struct TexelFootprint {
    int64_t texel[4];
    float weight[4];
    // d weight / d u and d weight / d v, for the adjoint with respect to uv.
    float dweight_du[4];
    float dweight_dv[4];
};

inline int wrap_index(int i, int n) {
    int m = i % n;
    return m < 0 ? m + n : m;
}

inline TexelFootprint bilinear_footprint(const Texture& tex, Vec2f uv) {
    TexelFootprint f;
    float x = uv.x * float(tex.width) - 0.5f;
    float y = uv.y * float(tex.height) - 0.5f;
    float fx = std::floor(x), fy = std::floor(y);
    float tx = x - fx, ty = y - fy;
    int x0 = wrap_index(int(fx), tex.width), x1 = wrap_index(int(fx) + 1, tex.width);
    int y0 = wrap_index(int(fy), tex.height), y1 = wrap_index(int(fy) + 1, tex.height);
    f.texel[0] = int64_t(y0) * tex.width + x0;
    f.texel[1] = int64_t(y0) * tex.width + x1;
    f.texel[2] = int64_t(y1) * tex.width + x0;
    f.texel[3] = int64_t(y1) * tex.width + x1;
    f.weight[0] = (1 - tx) * (1 - ty);
    f.weight[1] = tx * (1 - ty);
    f.weight[2] = (1 - tx) * ty;
    f.weight[3] = tx * ty;
    float W = float(tex.width), H = float(tex.height);
    f.dweight_du[0] = -(1 - ty) * W; f.dweight_du[1] = (1 - ty) * W;
    f.dweight_du[2] = -ty * W;       f.dweight_du[3] = ty * W;
    f.dweight_dv[0] = -(1 - tx) * H; f.dweight_dv[1] = -tx * H;
    f.dweight_dv[2] = (1 - tx) * H;  f.dweight_dv[3] = tx * H;
    return f;
}

inline float texture_channel(const Texture& tex, const TexelFootprint& f, int c) {
    float v = 0.f;
    for (int k = 0; k < 4; ++k) v += f.weight[k] * tex.data[f.texel[k] * tex.channels + c];
    return v;
}

inline Vec3f eval_texture3(const Texture& tex, Vec2f uv) {
    if (tex.is_constant()) return Vec3f::load(tex.data);
    TexelFootprint f = bilinear_footprint(tex, uv);
    return {texture_channel(tex, f, 0), texture_channel(tex, f, 1), texture_channel(tex, f, 2)};
}

inline float eval_texture1(const Texture& tex, Vec2f uv) {
    if (tex.is_constant()) return tex.data[0];
    return texture_channel(tex, bilinear_footprint(tex, uv), 0);
}

// Mean over all texels (per channel), used to weight light and lobe selection.
inline Vec3f texture_mean3(const Texture& tex) {
    double s[3] = {0, 0, 0};
    int64_t n = int64_t(tex.width) * tex.height;
    for (int64_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) s[c] += tex.data[i * tex.channels + c];
    return n > 0 ? Vec3f(float(s[0] / n), float(s[1] / n), float(s[2] / n)) : Vec3f(0.f);
}

}  // namespace edgepath
