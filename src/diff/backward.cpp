// The gradient pass: every camera sample is re-traced with the random numbers of the forward
// pass (same seed: same paths), recorded, and swept in reverse (the interior term, with the
// boundary term of the edges seen from the path's vertices); then the boundary term of the edges
// the camera sees is added by its own pass. The same pass serves the output channels
// (render/channels.h): the radiance through the recorded path, the other continuous channels
// through the camera ray's first hit (diff/channels.h).
#include "diff/backward.h"

#include "diff/backprop.h"
#include "diff/channels.h"
#include "edges/primary.h"
#include "edges/secondary.h"
#include "render/channels.h"
#include "render/path.h"
#include "render/tiles.h"
#include <algorithm>
#include <cmath>
#include <tbb/enumerable_thread_specific.h>

namespace edgepath {

namespace {

void check_layout(const ChannelLayout& layout) {
    if (layout.num_values == 0)
        throw std::invalid_argument("channels: no continuous channel to differentiate (ids have no derivative)");
}

// The pilot pass of the secondary term's roulette (RenderOptions::secondary_survival): about
// kPilotPixels camera samples on a regular grid of pixels, with random numbers of their own (so
// that the probabilities do not depend on the samples they weigh: the roulette stays unbiased),
// traced and swept one after another (the same probabilities for any thread count). For each
// class of vertices (SecondaryEdges::survival_class: its mesh, its depth) it measures the mean
// square of the term's gradient there, M = mean (|s| (|d e0| + |d e1| + |d p|))^2 over the
// vertices (zero where nothing was sampled); a class gets sqrt(M / M_max), the allocation of
// samples that minimises the variance for the time when vertices cost alike, no lower than the
// floor. Classes with fewer than kPilotMin pilot vertices keep 1. `adjoint`: the pixels'
// adjoints (reverse mode; values `stride` apart, radiance at `offset`), or null (forward mode:
// every colour alike).
constexpr int kPilotPixels = 1024, kPilotMin = 16;

void calibrate_survival(const Scene& scene, const RenderOptions& opt, const SceneGradients& slots,
                        SecondaryEdges& secondary, const float* adjoint, int stride, int offset) {
    secondary.set_survival({});
    const float floor = opt.secondary_survival;
    if (!(floor < 1.f) || !secondary.active()) return;
    const int W = scene.out_width, H = scene.out_height;
    // About kPilotPixels pixels, and no more than an eighth of the pass's own samples.
    const double pilot = std::min(double(kPilotPixels), double(W) * double(H) * double(opt.spp) / 8.0);
    const int step = std::max(1, int(std::ceil(std::sqrt(double(W) * double(H) / std::max(pilot, 1.0)))));
    const uint64_t seed = mix64(opt.seed ^ 0x70696c6f74ull);  // the pilot's own streams
    const size_t classes = SecondaryEdges::survival_class(int(scene.meshes.size()), 0);
    std::vector<double> sum(classes, 0.0);
    std::vector<int64_t> count(classes, 0);
    PathRecord rec;
    EdgeTermLog log;
    GradSink discard(true);  // projections only, never written anywhere
    RayCounters counters;
    for (int y = step / 2; y < H; y += step)
        for (int x = step / 2; x < W; x += step) {
            Vec3f a(1.f);
            if (adjoint) {
                const float* ap = adjoint + (int64_t(y) * W + x) * stride + offset;
                a = Vec3f(ap[0], ap[1], ap[2]);
                if (is_black(a)) continue;
            }
            const CameraSample c = camera_sample(scene, seed, x, y, 0);
            if (c.outside) continue;
            record_camera_path(scene, opt, seed, c, rec, counters);
            if (rec.camera_missed) continue;
            log.replaying = false;
            backprop_path(scene, slots, rec, a, discard, &secondary, &log);
            discard.take_projection();
            const int K = std::min(int(rec.vertices.size()), opt.max_bounces);
            for (int k = 0; k < K; ++k) {
                const PathVertexRecord& r = rec.vertices[size_t(k)];
                const float q = std::min(1.f, std::max(r.beta.x, std::max(r.beta.y, r.beta.z)));
                double X = 0.0;
                if (size_t(k) < log.begin.size() && q > 0.f) {
                    const Vec3f w = a * r.beta / q;
                    for (uint32_t i = log.begin[size_t(k)]; i < log.end[size_t(k)]; ++i) {
                        const EdgeTerm& t = log.terms[i];
                        const double sv = std::abs(double(dot(w, t.u)));
                        X += sv * (length(t.g.d_e0) + length(t.g.d_e1) + length(t.g.d_o));
                    }
                }
                const size_t c = SecondaryEdges::survival_class(r.hit.mesh, k);
                if (!std::isfinite(X)) X = 0.0;
                sum[c] += X * X;
                ++count[c];
            }
        }
    double top = 0.0;
    for (size_t c = 0; c < classes; ++c)
        if (count[c] >= kPilotMin) top = std::max(top, sum[c] / double(count[c]));
    if (!(top > 0.0)) return;
    std::vector<float> p(classes, 1.f);
    for (size_t c = 0; c < classes; ++c)
        if (count[c] >= kPilotMin)
            p[c] = std::clamp(float(std::sqrt(sum[c] / double(count[c]) / top)), floor, 1.f);
    secondary.set_survival(std::move(p));
}

// The options a gradient pass traces its paths with, checked: replayable whatever the caller
// set (its paths are the replayable image's: render/path.h, env_nee and tracing_of). Builds the
// exact BVH if the scene has none yet, before the pass's threads start (built by one of them,
// Embree's build would have that thread alone: the others would wait for it).
RenderOptions retraced(const Scene& scene, const RenderOptions& options) {
    check_options(options);
    RenderOptions opt = options;
    opt.replayable = true;
    scene.bvh(Tracing::Exact);
    return opt;
}

}  // namespace

void channel_gradients(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                       const float* adjoint, const SceneGradients& grads) {
    const RenderOptions opt = retraced(scene, options);
    check_layout(layout);
    const float inv_spp = 1.f / float(opt.spp);
    const int nv = layout.num_values;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    const SceneGradients none;  // the other channels see no secondary edges
    SecondaryEdges secondary(scene, opt, radiance ? grads : none);
    if (radiance) calibrate_survival(scene, opt, grads, secondary, adjoint, nv, ro);
    const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
    // Each tile's additions in the tiles' order: the same gradients, bit for bit, whatever the
    // thread count.
    tbb::enumerable_thread_specific<GradSink> sinks([] { return GradSink(false, true); });
    OrderedAdds adds;
    for_each_sample(
        scene, opt, radiance,
        [&](int x, int y, const PathRecord& rec) {
            const float* a = adjoint + (int64_t(y) * scene.out_width + x) * nv;
            if (radiance) {
                Vec3f av(a[ro] * inv_spp, a[ro + 1] * inv_spp, a[ro + 2] * inv_spp);
                if (!is_black(av)) backprop_path(scene, grads, rec, av, sinks.local(), sec);
            }
            if (hit_values && !rec.camera_missed) {
                float ah[kMaxChannelValues];
                bool any = false;
                for (int j = 0; j < nv; ++j) {
                    ah[j] = a[j] * inv_spp;
                    any = any || ah[j] != 0.f;
                }
                const PathVertexRecord& v = rec.vertices[0];
                Ray ray;
                ray.origin = v.origin;
                ray.dir = v.dir;
                if (any) d_hit_channels(scene, layout, grads, rec.film, rec.lens, ray, v.hit, ah, sinks.local());
            }
        },
        [&](int64_t tile) { sinks.local().commit(adds, tile); });
    primary_edge_pass(scene, opt, grads, layout, adjoint, nullptr);
}

void channel_derivative_image(const Scene& scene, const RenderOptions& options, const ChannelLayout& layout,
                              const SceneGradients& dirs, float* out) {
    const RenderOptions opt = retraced(scene, options);
    check_layout(layout);
    const float inv_spp = 1.f / float(opt.spp);
    const int nv = layout.num_values;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    const int64_t n = int64_t(scene.out_width) * scene.out_height * nv;
    std::fill(out, out + n, 0.f);
    const SceneGradients none;  // the other channels see no secondary edges
    SecondaryEdges secondary(scene, opt, radiance ? dirs : none);
    if (radiance) calibrate_survival(scene, opt, dirs, secondary, nullptr, nv, ro);
    const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
    tbb::enumerable_thread_specific<GradSink> sinks([] { return GradSink(true); });
    tbb::enumerable_thread_specific<EdgeTermLog> logs;
    for_each_sample(
        scene, opt, radiance,
        [&](int x, int y, const PathRecord& rec) {
            GradSink& sink = sinks.local();
            float* o = out + (int64_t(y) * scene.out_width + x) * nv;  // each pixel belongs to one tile: no race
            if (radiance) {
                // The three colours in one sweep (backprop_path_colours): each colour's value is
                // that of a sweep with the unit adjoint of its own colour.
                backprop_path_colours(scene, dirs, rec, inv_spp, sink, sec, sec ? &logs.local() : nullptr);
                double p[3];
                sink.take_projections(p);
                for (int c = 0; c < 3; ++c) o[ro + c] += float(p[c]);
            }
            if (hit_values && !rec.camera_missed) {
                const PathVertexRecord& v = rec.vertices[0];
                Ray ray;
                ray.origin = v.origin;
                ray.dir = v.dir;
                // Every value in one pass (a lane per value): value j's the same, bit for bit,
                // as d_hit_channels with the adjoint inv_spp at j alone.
                double p[kMaxChannelValues];
                d_hit_channel_values(scene, layout, dirs, rec.film, rec.lens, ray, v.hit, inv_spp, sink, p);
                for (int j = 0; j < nv; ++j) {
                    if (radiance && j >= ro && j < ro + 3) continue;
                    o[j] += float(p[j]);
                }
            }
        },
        [](int64_t) {});
    primary_edge_pass(scene, opt, dirs, layout, nullptr, out);
}

void render_gradients(const Scene& scene, const RenderOptions& opt, const float* adjoint, const SceneGradients& grads) {
    channel_gradients(scene, opt, ChannelLayout::radiance(), adjoint, grads);
}

void derivative_image(const Scene& scene, const RenderOptions& opt, const SceneGradients& dirs, float* out) {
    channel_derivative_image(scene, opt, ChannelLayout::radiance(), dirs, out);
}

}  // namespace edgepath
