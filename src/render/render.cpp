#include <atomic>

#include "edgepath.h"
#include "render/path.h"
#include "render/tiles.h"

namespace edgepath {

RenderStats render(const Scene& scene, const RenderOptions& opt, float* image) {
    check_options(opt);
    std::atomic<uint64_t> n_camera{0}, n_shadow{0}, n_bounce{0};
    for_each_tile(scene, opt, [&](int x0, int y0, int x1, int y1) {
        RayCounters c;
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x) {
                uint64_t pixel = film_pixel_index(scene, x, y);
                double sum[3] = {0, 0, 0};
                for (int s = 0; s < opt.spp; ++s) {
                    Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                    Vec2f film = sample_film_point(scene, x + scene.crop_x, y + scene.crop_y, rng);
                    Vec3f L = trace_path(scene, opt, scene.camera.generate_ray(film.x, film.y), rng, c);
                    for (int k = 0; k < 3; ++k) sum[k] += L[k];
                }
                float* out = image + (int64_t(y) * scene.out_width + x) * 3;
                for (int k = 0; k < 3; ++k) out[k] = float(sum[k] / opt.spp);
            }
        n_camera += c.camera;
        n_shadow += c.shadow;
        n_bounce += c.bounce;
    });
    RenderStats st;
    st.camera_rays = n_camera;
    st.shadow_rays = n_shadow;
    st.bounce_rays = n_bounce;
    return st;
}

}  // namespace edgepath
