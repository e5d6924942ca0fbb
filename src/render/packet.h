// Camera rays traced in Embree packets. The camera samples of a tile are generated in the order
// the passes visit them (row by row, pixel by pixel, sample by sample), kPacketSize at a time;
// their first intersections are found by one packet query (rays of neighbouring pixels travel
// together through the BVH, so the nodes they visit are loaded once for all), and each sample
// is then handed on, in that order, with its random stream, its film point, its ray and its
// first hit. The rest of the path is traced by trace_path (render/path.h), one ray at a time, or,
// in the forward pass, with the other paths of its batch (render/batch.h).
//
// Each sample keeps its own random stream, drawn before the packet is traced exactly as a single
// sample would draw it, so an image does not depend on how the samples are grouped or on the
// thread count.
#pragma once
#include <algorithm>

#include "render/path.h"
#include "sampling/rng.h"
#include "scene/desc.h"
#include "scene/scene.h"

namespace edgepath {

// Rays per packet: 16, the width of Embree's native packets with AVX-512 (with AVX2 it traces
// them as two of 8). The Cornell box's camera rays alone (256², 64 spp, no bounce, one thread,
// an AVX-512 machine) took 0.82x the CPU time of packets of 8 (medians of 5 alternating runs).
constexpr int kPacketSize = 16;

// Intersects rays[0..n) (n <= kPacketSize) as one coherent packet; first[i] is what
// Scene::intersect(rays[i], tracing) finds, bit for bit (Render.PacketsMatchSingleRays checks it).
void intersect_packet(const Scene& scene, Tracing tracing, const Ray* rays, int n, FirstHit* first);

// Index of output pixel (x, y) in the full film: it seeds the pixel's random streams, so a crop
// renders the same samples as the full image.
inline uint64_t film_pixel_index(const Scene& scene, int x, int y) {
    return uint64_t(y + scene.crop_y) * uint64_t(scene.camera.width) + uint64_t(x + scene.crop_x);
}

// One camera sample of a pass.
struct CameraSample {
    int x = 0, y = 0;  // output pixel
    int s = 0;         // sample index in the pixel
    uint64_t pixel = 0;  // film pixel index (seeds the sample's streams)
    Rng rng;           // the sample's stream, past the film and lens points
    Vec2f film;
    Vec2f lens;        // the lens sample (thin lens; otherwise the lens centre)
    Ray ray;
    FirstHit first;
    bool outside = false;  // the film point lies outside a fisheye's image circle: black, not traced
};

// Camera sample s of output pixel (x, y) with the random numbers of Rng::for_sample(seed,
// pixel, s): its film and lens points and its ray, written into c (c.first is left as it is).
inline void set_camera_sample(CameraSample& c, const Scene& scene, uint64_t seed, int x, int y, int s) {
    c.s = s;
    c.x = x;
    c.y = y;
    c.pixel = film_pixel_index(scene, x, y);
    c.rng = Rng::for_sample(seed, c.pixel, uint64_t(s));
    c.film = sample_film_point(scene, x + scene.crop_x, y + scene.crop_y, c.rng);
    c.lens = sample_lens_point(scene, c.rng);
    c.ray = scene.camera.generate_ray(c.film.x, c.film.y, c.lens.x, c.lens.y);
    c.outside = !scene.camera.sees(c.film.x, c.film.y);
}

// The same, returned (first not yet found).
inline CameraSample camera_sample(const Scene& scene, uint64_t seed, int x, int y, int s) {
    CameraSample c;
    set_camera_sample(c, scene, seed, x, y, s);
    return c;
}

// The whole path of camera sample c (camera_sample(scene, seed, ...)) traced by trace_path and
// recorded into rec, with the path's own stream mix64(seed ^ pixel): a sample taken alone, as
// the survival pilot and tests take them.
inline void record_camera_path(const Scene& scene, const RenderOptions& opt, uint64_t seed, CameraSample c,
                               PathRecord& rec, RayCounters& counters) {
    rec.film = c.film;
    rec.lens = c.lens;
    rec.stream = mix64(seed ^ c.pixel);
    trace_path(scene, opt, c.ray, c.rng, counters, &rec, nullptr);
}

// Calls fn(samples, n) for the camera samples of the output pixels [x0, x1) x [y0, y1), in
// order (rows, pixels, samples), `capacity` (a multiple of kPacketSize) at a time in `samples`
// (n <= capacity; fewer at the end), with the random numbers of Rng::for_sample(opt.seed, pixel,
// s) and the first hits traced in packets of kPacketSize in the BVH tracing_of(opt) names (with
// opt.hide_emitters, past the emitters, as first_hit finds them). A sample outside the camera's image
// (CameraSample::outside) has no hit; the passes count it black. Stops (returns false) once opt
// is cancelled.
template <class BatchFn>
bool for_each_camera_batch(const Scene& scene, const RenderOptions& opt, int x0, int y0, int x1, int y1,
                           CameraSample* samples, int capacity, BatchFn&& fn) {
    Ray rays[kPacketSize];
    FirstHit first[kPacketSize];
    const int spp = opt.spp;
    const Tracing tracing = tracing_of(opt);
    const int64_t count = int64_t(x1 - x0) * (y1 - y0) * spp;
    // The next sample: sample s of pixel (x, y).
    int x = x0, y = y0, s = 0;
    for (int64_t begin = 0; begin < count; begin += capacity) {
        if (opt.cancelled()) return false;
        const int n = int(std::min<int64_t>(capacity, count - begin));
        for (int p = 0; p < n; p += kPacketSize) {
            CameraSample* batch = samples + p;
            const int m = std::min(kPacketSize, n - p);
            for (int i = 0; i < m; ++i) {
                set_camera_sample(batch[i], scene, opt.seed, x, y, s);
                if (++s == spp) {
                    s = 0;
                    if (++x == x1) {
                        x = x0;
                        ++y;
                    }
                }
                rays[i] = batch[i].ray;
                if (batch[i].outside) rays[i].tmax = -1.f;  // an inactive lane (tnear > tfar)
            }
            intersect_packet(scene, tracing, rays, m, first);
            for (int i = 0; i < m; ++i) {
                if (batch[i].outside) first[i] = FirstHit();
                batch[i].first = first[i];
                if (opt.hide_emitters && first[i].found && scene.meshes[size_t(first[i].hit.mesh)].is_emitter())
                    batch[i].first = first_hit(scene, rays[i], true, tracing);
            }
        }
        fn(samples, n);
    }
    return true;
}

// Calls fn(sample) for every camera sample of the output pixels [x0, x1) x [y0, y1), in order,
// as for_each_camera_batch makes them.
template <class SampleFn>
bool for_each_camera_sample(const Scene& scene, const RenderOptions& opt, int x0, int y0, int x1, int y1,
                            SampleFn&& fn) {
    CameraSample batch[kPacketSize];
    return for_each_camera_batch(scene, opt, x0, y0, x1, y1, batch, kPacketSize, [&](CameraSample* samples, int n) {
        for (int i = 0; i < n; ++i) fn(samples[i]);
    });
}

}  // namespace edgepath
