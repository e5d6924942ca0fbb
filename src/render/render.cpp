#include <atomic>
#include <stdexcept>
#include <string>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "edgepath.h"
#include "render/path.h"

namespace edgepath {

namespace {
constexpr int kTileSize = 16;
}

RenderStats render(const Scene& scene, const RenderOptions& opt, float* image) {
    if (opt.spp < 1) throw std::invalid_argument("spp: must be at least 1, got " + std::to_string(opt.spp));
    if (opt.max_bounces < 0)
        throw std::invalid_argument("max_bounces: must be non-negative, got " + std::to_string(opt.max_bounces));
    const int W = scene.out_width, H = scene.out_height;
    const int tiles_x = (W + kTileSize - 1) / kTileSize, tiles_y = (H + kTileSize - 1) / kTileSize;
    std::atomic<uint64_t> n_camera{0}, n_shadow{0}, n_bounce{0};
    auto body = [&](const tbb::blocked_range<int>& range) {
        RayCounters c;
        for (int tile = range.begin(); tile < range.end(); ++tile) {
            int x0 = (tile % tiles_x) * kTileSize, y0 = (tile / tiles_x) * kTileSize;
            for (int y = y0; y < std::min(y0 + kTileSize, H); ++y)
                for (int x = x0; x < std::min(x0 + kTileSize, W); ++x) {
                    int fx = x + scene.crop_x, fy = y + scene.crop_y;
                    uint64_t pixel = uint64_t(fy) * uint64_t(scene.camera.width) + uint64_t(fx);
                    double sum[3] = {0, 0, 0};
                    for (int s = 0; s < opt.spp; ++s) {
                        Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                        Vec2f film = sample_film_point(scene, fx, fy, rng);
                        Vec3f L = trace_path(scene, opt, scene.camera.generate_ray(film.x, film.y), rng, c);
                        sum[0] += L.x;
                        sum[1] += L.y;
                        sum[2] += L.z;
                    }
                    float* out = image + (int64_t(y) * W + x) * 3;
                    for (int k = 0; k < 3; ++k) out[k] = opt.spp > 0 ? float(sum[k] / opt.spp) : 0.f;
                }
        }
        n_camera += c.camera;
        n_shadow += c.shadow;
        n_bounce += c.bounce;
    };
    int threads = opt.num_threads > 0 ? opt.num_threads : tbb::this_task_arena::max_concurrency();
    tbb::task_arena arena(threads);
    arena.execute([&] { tbb::parallel_for(tbb::blocked_range<int>(0, tiles_x * tiles_y, 1), body); });
    RenderStats st;
    st.camera_rays = n_camera;
    st.shadow_rays = n_shadow;
    st.bounce_rays = n_bounce;
    return st;
}

}  // namespace edgepath
