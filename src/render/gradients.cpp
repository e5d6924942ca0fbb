// The gradient pass: every camera sample is re-traced with the random numbers of the forward
// pass (same seed: same paths), recorded, and swept in reverse (the interior term); then the
// boundary terms of the edges are added by their own passes.
#include "diff/backprop.h"
#include "edgepath.h"
#include "edges/primary.h"
#include "edges/secondary.h"
#include "render/path.h"
#include "render/tiles.h"
#include <tbb/enumerable_thread_specific.h>

namespace edgepath {

namespace {

// Runs fn(pixel x, y, sample record) for every camera sample, in parallel.
template <class SampleFn, class TileEnd>
void for_each_sample(const Scene& scene, const RenderOptions& opt, SampleFn&& fn, TileEnd&& tile_end) {
    for_each_tile(scene, opt, [&](int x0, int y0, int x1, int y1) {
        RayCounters c;
        PathRecord rec;
        rec.vertices.reserve(size_t(opt.max_bounces) + 1);
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x) {
                uint64_t pixel = film_pixel_index(scene, x, y);
                for (int s = 0; s < opt.spp; ++s) {
                    Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                    rec.stream = mix64(mix64(opt.seed ^ 0x736563ull) ^ (pixel * uint64_t(opt.spp) + uint64_t(s)));
                    rec.film = sample_film_point(scene, x + scene.crop_x, y + scene.crop_y, rng);
                    trace_path(scene, opt, scene.camera.generate_ray(rec.film.x, rec.film.y), rng, c, &rec);
                    fn(x, y, rec);
                }
            }
        tile_end();
    });
}

}  // namespace

void render_gradients(const Scene& scene, const RenderOptions& opt, const float* adjoint, const SceneGradients& grads) {
    check_options(opt);
    const float inv_spp = 1.f / float(opt.spp);
    const SecondaryEdges secondary(scene, opt, grads);
    const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
    tbb::enumerable_thread_specific<GradSink> sinks([] { return GradSink(false); });
    for_each_sample(
        scene, opt,
        [&](int x, int y, const PathRecord& rec) {
            const float* a = adjoint + (int64_t(y) * scene.out_width + x) * 3;
            Vec3f av(a[0] * inv_spp, a[1] * inv_spp, a[2] * inv_spp);
            if (is_black(av)) return;
            backprop_path(scene, grads, rec, av, sinks.local(), sec);
        },
        [&] { sinks.local().flush(); });
    primary_edge_pass(scene, opt, grads, adjoint, nullptr);
}

void derivative_image(const Scene& scene, const RenderOptions& opt, const SceneGradients& dirs, float* out) {
    check_options(opt);
    const float inv_spp = 1.f / float(opt.spp);
    const int64_t n = int64_t(scene.out_width) * scene.out_height * 3;
    std::fill(out, out + n, 0.f);
    const SecondaryEdges secondary(scene, opt, dirs);
    const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
    tbb::enumerable_thread_specific<GradSink> sinks([] { return GradSink(true); });
    for_each_sample(
        scene, opt,
        [&](int x, int y, const PathRecord& rec) {
            GradSink& sink = sinks.local();
            float* o = out + (int64_t(y) * scene.out_width + x) * 3;
            for (int c = 0; c < 3; ++c) {
                Vec3f e(0.f);
                e[c] = inv_spp;
                backprop_path(scene, dirs, rec, e, sink, sec);
                o[c] += float(sink.take_projection());  // each pixel belongs to one tile: no race
            }
        },
        [] {});
    primary_edge_pass(scene, opt, dirs, nullptr, out);
}

}  // namespace edgepath
