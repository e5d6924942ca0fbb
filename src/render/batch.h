// The forward pass's paths advanced together, bounce by bounce (a wavefront): at each bounce
// every live path of a batch is shaded (its BSDF sample, its light samples), then the batch's
// shadow rays are traced by Embree packets of kLanes, then its continuation rays, and then each
// path adds what its shadow rays let through and the light its continuation meets. Embree
// traces these incoherent rays faster in packets than one by one on wide vector units (its
// native packet width on AVX-512 is 16).
//
// Each path keeps its own random stream and adds to its radiance in the order trace_path does:
// the radiance of every path is trace_path's, bit for bit (Render.BatchedPathsMatchTracePath),
// so an image does not depend on how the paths are grouped. The gradient pass records its
// camera paths here too (trace()'s records: what trace_path records, bit for bit), and the
// primary edge pass traces its side paths (not recorded) here (edges/primary.cpp).
#pragma once
#include <memory>
#include <vector>

#include "render/packet.h"
#include "render/path.h"
#include "scene/desc.h"
#include "scene/scene.h"

namespace edgepath {

// Rays per Embree packet (rtcIntersect16, rtcOccluded16).
constexpr int kLanes = 16;
// Paths advanced together: whole packets of camera rays (kPacketSize) and of continuations.
// Measured against 16 and 32 (and 128, 256): the fewest CPU seconds.
constexpr int kBatchSize = 64;
static_assert(kBatchSize % kPacketSize == 0 && kBatchSize % kLanes == 0, "a batch is made of whole packets");

// What a tile's pass needs to trace batches: the paths' state and the ray packets, allocated once
// (for the scene's point light count) and reused batch after batch.
class PathBatch {
public:
    PathBatch(const Scene& scene, const RenderOptions& opt);
    ~PathBatch();
    PathBatch(const PathBatch&) = delete;
    PathBatch& operator=(const PathBatch&) = delete;

    // L[i] = the radiance of camera sample samples[i], i < n <= kBatchSize: trace_path's for
    // its ray, stream and first hit (black outside the image), bit for bit. Advances the
    // samples' streams as trace_path does and adds its rays to `counters`. With `records` (n of
    // them; the options replayable, as a gradient pass's are), also records each path into
    // records[i] as trace_path records it (every vertex, light sample and weight the same, bit
    // for bit; for a sample outside the image, camera_missed and emitters_hidden set, no vertex);
    // their film, lens and stream are left to the caller.
    void trace(CameraSample* samples, int n, Vec3f* L, RayCounters& counters, PathRecord* records = nullptr);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace edgepath
