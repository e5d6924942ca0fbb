#include "render/render.h"

#include <atomic>
#include <memory>

#include "render/batch.h"
#include "render/packet.h"
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
    return render_channels(scene, opt, ChannelLayout::radiance(), image, nullptr);
}

RenderStats render_channels(const Scene& scene, const RenderOptions& opt, const ChannelLayout& layout, float* values,
                            int32_t* ids) {
    check_options(opt);
    if (layout.num_ids > 0 && !ids) throw std::invalid_argument("ids: missing (the channels include ids)");
    // The BVH built, if it is not yet, before the threads start (built by one of them, Embree's
    // build would have that thread alone: the others would wait for it).
    const Tracing tracing = tracing_of(opt);
    scene.bvh(tracing);
    const int nv = layout.num_values, ni = layout.num_ids;
    const bool radiance = layout.has(Channel::Radiance), hit_values = layout.has_hit_values();
    const int ro = layout.offset[int(Channel::Radiance)];
    RayTally tally;
    for_each_tile(scene, opt, [&](int64_t, int x0, int y0, int x1, int y1) {
        RayCounters c;
        float v[kMaxChannelValues];
        double sum[kMaxChannelValues] = {};
        if (nv > 0) {
            std::unique_ptr<PathBatch> paths;
            if (radiance) paths = std::make_unique<PathBatch>(scene, opt);
            CameraSample samples[kBatchSize];
            Vec3f L[kBatchSize];
            for_each_camera_batch(scene, opt, x0, y0, x1, y1, samples, kBatchSize, [&](CameraSample* cs, int n) {
                if (radiance) paths->trace(cs, n, L, c);
                for (int i = 0; i < n; ++i) {
                    if (hit_values) eval_hit_channels(scene, layout, cs[i].ray, cs[i].first.found, cs[i].first.hit, v);
                    if (radiance)
                        for (int k = 0; k < 3; ++k) v[ro + k] = L[i][k];
                    else if (!cs[i].outside)
                        ++c.camera;
                    for (int k = 0; k < nv; ++k) sum[k] += v[k];
                    if (cs[i].s + 1 < opt.spp) continue;
                    float* out = values + (int64_t(cs[i].y) * scene.out_width + cs[i].x) * nv;
                    for (int k = 0; k < nv; ++k) {
                        out[k] = float(sum[k] / opt.spp);
                        sum[k] = 0.0;
                    }
                }
            });
        }
        // Ids: of the ray through each pixel's centre.
        for (int y = y0; y < y1 && ni > 0; ++y)
            for (int x = x0; x < x1; ++x) {
                const float fx = float(x + scene.crop_x) + 0.5f, fy = float(y + scene.crop_y) + 0.5f;
                FirstHit first;
                if (scene.camera.sees(fx, fy)) {
                    first = first_hit(scene, scene.camera.generate_ray(fx, fy), opt.hide_emitters, tracing);
                    ++c.camera;
                }
                eval_hit_ids(scene, layout, first.found, first.hit, ids + (int64_t(y) * scene.out_width + x) * ni);
            }
        tally.add(c);
    });
    return tally.stats();
}

}  // namespace edgepath
