#include "render/render.h"

#include <atomic>

#include "render/path.h"
#include "render/tiles.h"

namespace edgepath {

namespace {
// Ray counts summed over the tiles of a pass.
struct RayTally {
    std::atomic<uint64_t> camera{0}, shadow{0}, bounce{0};
    void add(const RayCounters& c) {
        camera += c.camera;
        shadow += c.shadow;
        bounce += c.bounce;
    }
    RenderStats stats() const {
        RenderStats st;
        st.camera_rays = camera;
        st.shadow_rays = shadow;
        st.bounce_rays = bounce;
        return st;
    }
};
}  // namespace

RenderStats render(const Scene& scene, const RenderOptions& opt, float* image) {
    check_options(opt);
    RayTally tally;
    for_each_tile(scene, opt, [&](int x0, int y0, int x1, int y1) {
        RayCounters c;
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x) {
                uint64_t pixel = film_pixel_index(scene, x, y);
                double sum[3] = {0, 0, 0};
                for (int s = 0; s < opt.spp; ++s) {
                    if (opt.cancelled()) return;
                    Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                    Vec2f film = sample_film_point(scene, x + scene.crop_x, y + scene.crop_y, rng);
                    Vec2f lens = sample_lens_point(scene, rng);
                    Vec3f L = trace_path(scene, opt, scene.camera.generate_ray(film.x, film.y, lens.x, lens.y), rng, c);
                    for (int k = 0; k < 3; ++k) sum[k] += L[k];
                }
                float* out = image + (int64_t(y) * scene.out_width + x) * 3;
                for (int k = 0; k < 3; ++k) out[k] = float(sum[k] / opt.spp);
            }
        tally.add(c);
    });
    return tally.stats();
}

RenderStats render_channels(const Scene& scene, const RenderOptions& opt, const ChannelLayout& layout, float* values,
                            int32_t* ids) {
    check_options(opt);
    if (layout.num_ids > 0 && !ids) throw std::invalid_argument("ids: missing (the channels include ids)");
    const int nv = layout.num_values, ni = layout.num_ids;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    RayTally tally;
    for_each_tile(scene, opt, [&](int x0, int y0, int x1, int y1) {
        RayCounters c;
        float v[kMaxChannelValues];
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x) {
                const uint64_t pixel = film_pixel_index(scene, x, y);
                const int64_t index = int64_t(y) * scene.out_width + x;
                if (nv > 0) {
                    double sum[kMaxChannelValues] = {};
                    for (int s = 0; s < opt.spp; ++s) {
                        if (opt.cancelled()) return;
                        Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                        const Vec2f film = sample_film_point(scene, x + scene.crop_x, y + scene.crop_y, rng);
                        const Vec2f lens = sample_lens_point(scene, rng);
                        const Ray ray = scene.camera.generate_ray(film.x, film.y, lens.x, lens.y);
                        FirstHit first;
                        if (hit_values) {
                            first = first_hit(scene, ray, opt.hide_emitters);
                            eval_hit_channels(scene, layout, ray, first.found, first.hit, v);
                        }
                        if (radiance) {
                            const Vec3f L = trace_path(scene, opt, ray, rng, c, nullptr, hit_values ? &first : nullptr);
                            for (int k = 0; k < 3; ++k) v[ro + k] = L[k];
                        } else {
                            ++c.camera;
                        }
                        for (int k = 0; k < nv; ++k) sum[k] += v[k];
                    }
                    float* out = values + index * nv;
                    for (int k = 0; k < nv; ++k) out[k] = float(sum[k] / opt.spp);
                }
                if (ni > 0) {
                    // The ray through the pixel centre.
                    const Ray ray = scene.camera.generate_ray(float(x + scene.crop_x) + 0.5f, float(y + scene.crop_y) + 0.5f);
                    const FirstHit first = first_hit(scene, ray, opt.hide_emitters);
                    ++c.camera;
                    eval_hit_ids(layout, first.found, first.hit, ids + index * ni);
                }
            }
        tally.add(c);
    });
    return tally.stats();
}

}  // namespace edgepath
