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
#include <tbb/enumerable_thread_specific.h>

namespace edgepath {

namespace {

void check_layout(const ChannelLayout& layout) {
    if (layout.num_values == 0)
        throw std::invalid_argument("channels: no continuous channel to differentiate (ids have no derivative)");
}

}  // namespace

void channel_gradients(const Scene& scene, const RenderOptions& opt, const ChannelLayout& layout,
                       const float* adjoint, const SceneGradients& grads) {
    check_options(opt);
    check_layout(layout);
    const float inv_spp = 1.f / float(opt.spp);
    const int nv = layout.num_values;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    const SceneGradients none;  // the other channels see no secondary edges
    const SecondaryEdges secondary(scene, opt, radiance ? grads : none);
    const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
    tbb::enumerable_thread_specific<GradSink> sinks([] { return GradSink(false); });
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
        [&] { sinks.local().flush(); });
    primary_edge_pass(scene, opt, grads, layout, adjoint, nullptr);
}

void channel_derivative_image(const Scene& scene, const RenderOptions& opt, const ChannelLayout& layout,
                              const SceneGradients& dirs, float* out) {
    check_options(opt);
    check_layout(layout);
    const float inv_spp = 1.f / float(opt.spp);
    const int nv = layout.num_values;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    const int64_t n = int64_t(scene.out_width) * scene.out_height * nv;
    std::fill(out, out + n, 0.f);
    const SceneGradients none;  // the other channels see no secondary edges
    const SecondaryEdges secondary(scene, opt, radiance ? dirs : none);
    const SecondaryEdges* sec = secondary.active() ? &secondary : nullptr;
    tbb::enumerable_thread_specific<GradSink> sinks([] { return GradSink(true); });
    tbb::enumerable_thread_specific<EdgeTermLog> logs;
    for_each_sample(
        scene, opt, radiance,
        [&](int x, int y, const PathRecord& rec) {
            GradSink& sink = sinks.local();
            float* o = out + (int64_t(y) * scene.out_width + x) * nv;  // each pixel belongs to one tile: no race
            if (radiance) {
                // One sweep per colour; the edge terms are sampled by the first and replayed by
                // the others.
                EdgeTermLog& log = logs.local();
                log.replaying = false;
                for (int c = 0; c < 3; ++c) {
                    Vec3f e(0.f);
                    e[c] = inv_spp;
                    backprop_path(scene, dirs, rec, e, sink, sec, sec ? &log : nullptr);
                    log.replaying = true;
                    o[ro + c] += float(sink.take_projection());
                }
            }
            if (hit_values && !rec.camera_missed) {
                const PathVertexRecord& v = rec.vertices[0];
                Ray ray;
                ray.origin = v.origin;
                ray.dir = v.dir;
                float e[kMaxChannelValues] = {};
                for (int j = 0; j < nv; ++j) {
                    if (radiance && j >= ro && j < ro + 3) continue;
                    e[j] = inv_spp;
                    d_hit_channels(scene, layout, dirs, rec.film, rec.lens, ray, v.hit, e, sink);
                    e[j] = 0.f;
                    o[j] += float(sink.take_projection());
                }
            }
        },
        [] {});
    primary_edge_pass(scene, opt, dirs, layout, nullptr, out);
}

void render_gradients(const Scene& scene, const RenderOptions& opt, const float* adjoint, const SceneGradients& grads) {
    channel_gradients(scene, opt, ChannelLayout::radiance(), adjoint, grads);
}

void derivative_image(const Scene& scene, const RenderOptions& opt, const SceneGradients& dirs, float* out) {
    channel_derivative_image(scene, opt, ChannelLayout::radiance(), dirs, out);
}

}  // namespace edgepath
