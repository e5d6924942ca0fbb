// Parallel loop over the output image in tiles (oneTBB), shared by every pass.
#pragma once
#include <algorithm>
#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "render/batch.h"
#include "render/packet.h"
#include "render/path.h"
#include "scene/desc.h"
#include "scene/scene.h"

namespace edgepath {

// Primary edge samples are drawn in chunks indexed by int64: the count must leave room for
// rounding up to whole chunks.
constexpr int64_t kMaxEdgeSamples = int64_t(1) << 62;

inline void check_options(const RenderOptions& opt) {
    if (opt.spp < 1) throw std::invalid_argument("spp: must be at least 1, got " + std::to_string(opt.spp));
    if (opt.edge_samples < 0 || opt.edge_samples > kMaxEdgeSamples)
        throw std::invalid_argument("edge_samples: must be in [0, 2**62], got " + std::to_string(opt.edge_samples));
    if (!(opt.secondary_survival > 0.f && opt.secondary_survival <= 1.f))
        throw std::invalid_argument("secondary_survival: must be in (0, 1], got " + std::to_string(opt.secondary_survival));
    if (opt.max_bounces < 0)
        throw std::invalid_argument("max_bounces: must be non-negative, got " + std::to_string(opt.max_bounces));
}

// Threads a pass runs on: num_threads, at most the machine's (more would only wait).
inline int thread_count(const RenderOptions& opt) {
    const int cores = tbb::info::default_concurrency();
    return opt.num_threads > 0 ? std::min(opt.num_threads, cores) : cores;
}

// The task arena of a pass with `threads` threads: one per thread count, made on first use and
// kept for the life of the process. (oneTBB keeps 7-15 KiB for every arena that was created
// and destroyed with workers in it: an arena per call leaked that much per call. The arenas are
// never destroyed, nor is the map that holds them, so that none is torn down at exit after
// oneTBB itself.)
inline tbb::task_arena& pass_arena(int threads) {
    static std::mutex mutex;
    static std::map<int, std::unique_ptr<tbb::task_arena>>& arenas = *new std::map<int, std::unique_ptr<tbb::task_arena>>;
    std::lock_guard<std::mutex> lock(mutex);
    std::unique_ptr<tbb::task_arena>& arena = arenas[threads];
    if (!arena) arena = std::make_unique<tbb::task_arena>(threads);
    return *arena;
}

inline void throw_if_cancelled(const RenderOptions& opt) {
    if (opt.cancelled()) throw Cancelled();
}

// Calls fn(i) for i in [0, count) on opt.num_threads threads, each taking the next index not
// yet taken, so that the indices start in increasing order (work items finish close to their
// order: OrderedAdds, scene/gradients.h, then holds few of them at a time). Once opt is
// cancelled no item starts (fn should stop early too) and this throws Cancelled.
// An item that throws stops the others from starting new items; the exception then propagates.
template <class Fn>
void parallel_indices(const RenderOptions& opt, int64_t count, Fn&& fn) {
    const int threads = thread_count(opt);
    std::atomic<int64_t> next{0};
    std::atomic<bool> failed{false};
    pass_arena(threads).execute([&] {
        tbb::parallel_for(0, threads, [&](int) {
            for (int64_t i = next.fetch_add(1, std::memory_order_relaxed); i < count;
                 i = next.fetch_add(1, std::memory_order_relaxed)) {
                if (opt.cancelled() || failed.load(std::memory_order_relaxed)) return;
                try {
                    fn(i);
                } catch (...) {
                    failed.store(true, std::memory_order_relaxed);
                    throw;
                }
            }
        });
    });
    throw_if_cancelled(opt);
}

constexpr int kTileSize = 16;

// The number of tiles of the output image, and the index for_each_tile gives each.
inline int64_t tile_count(const Scene& scene) {
    return int64_t((scene.out_width + kTileSize - 1) / kTileSize) * ((scene.out_height + kTileSize - 1) / kTileSize);
}

// Calls tile_fn(tile, x0, y0, x1, y1) for the tiles of the output image (tile: its index, in
// [0, tile_count(scene)), row by row), in parallel on opt.num_threads. Once opt is cancelled no
// tile starts (tile_fn should stop early too) and this throws Cancelled.
template <class TileFn>
void for_each_tile(const Scene& scene, const RenderOptions& opt, TileFn&& tile_fn) {
    const int W = scene.out_width, H = scene.out_height;
    const int tiles_x = (W + kTileSize - 1) / kTileSize;
    parallel_indices(opt, tile_count(scene), [&](int64_t tile) {
        const int x0 = int(tile % tiles_x) * kTileSize, y0 = int(tile / tiles_x) * kTileSize;
        tile_fn(tile, x0, y0, std::min(x0 + kTileSize, W), std::min(y0 + kTileSize, H));
    });
}

// Calls fn(begin, end) over [0, n) in chunks of `chunk` (chunk c: [c chunk, (c + 1) chunk)), in
// parallel on opt.num_threads; once opt is cancelled no chunk starts and this throws Cancelled.
template <class ChunkFn>
void for_each_chunk(const RenderOptions& opt, int64_t n, int64_t chunk, ChunkFn&& fn) {
    parallel_indices(opt, (n + chunk - 1) / chunk, [&](int64_t c) { fn(c * chunk, std::min(n, (c + 1) * chunk)); });
}

// Runs fn(x, y, record) for every camera sample of every output pixel (x, y), in parallel, with
// the random numbers of render() for the same options (replayable ones, as a gradient pass's
// are: render/path.h, tracing_of); tile_end(tile) after each tile, on the thread that ran it
// (tile: for_each_tile's index), fn called for a tile's samples in their order. With
// `full_paths` the whole path is traced and recorded (the radiance's gradient), a batch of
// paths at a time (PathBatch: trace_path's records, bit for bit); without, only the camera
// ray's first hit (record.vertices holds it, or record.camera_missed).
template <class SampleFn, class TileEnd>
void for_each_sample(const Scene& scene, const RenderOptions& opt, bool full_paths, SampleFn&& fn,
                     TileEnd&& tile_end) {
    for_each_tile(scene, opt, [&](int64_t tile, int x0, int y0, int x1, int y1) {
        RayCounters c;
        // A record's stream, film and lens: the sample's.
        auto identify = [&](const CameraSample& cs, PathRecord& rec) {
            rec.stream = mix64(mix64(opt.seed ^ 0x736563ull) ^ (cs.pixel * uint64_t(opt.spp) + uint64_t(cs.s)));
            rec.film = cs.film;
            rec.lens = cs.lens;
        };
        bool done;
        if (full_paths) {
            PathBatch paths(scene, opt);
            CameraSample samples[kBatchSize];
            Vec3f L[kBatchSize];
            std::vector<PathRecord> records(kBatchSize);
            // Room for the usual path; a longer one (max_bounces may be up to 2^31 - 1) grows it once.
            for (PathRecord& rec : records) rec.vertices.reserve(size_t(std::min(opt.max_bounces, 63)) + 1);
            done = for_each_camera_batch(scene, opt, x0, y0, x1, y1, samples, kBatchSize, [&](CameraSample* cs, int n) {
                paths.trace(cs, n, L, c, records.data());
                for (int i = 0; i < n; ++i) {
                    identify(cs[i], records[size_t(i)]);
                    fn(cs[i].x, cs[i].y, records[size_t(i)]);
                }
            });
        } else {
            PathRecord rec;
            rec.vertices.reserve(1);
            done = for_each_camera_sample(scene, opt, x0, y0, x1, y1, [&](CameraSample& cs) {
                identify(cs, rec);
                rec.vertices.clear();
                rec.escaped = false;
                if (cs.outside) {
                    // Outside the image: black, nothing to differentiate.
                    rec.camera_missed = rec.emitters_hidden = true;
                } else {
                    rec.camera_missed = !cs.first.found;
                    if (!rec.camera_missed) {
                        rec.vertices.emplace_back();
                        rec.vertices.back().hit = cs.first.hit;
                        rec.vertices.back().origin = cs.ray.origin;
                        rec.vertices.back().dir = cs.ray.dir;
                    }
                }
                fn(cs.x, cs.y, rec);
            });
        }
        if (!done) return;
        tile_end(tile);
    });
}

}  // namespace edgepath
