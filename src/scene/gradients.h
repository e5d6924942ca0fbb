// Gradient buffers that mirror the scene, and the sink the adjoint sweep writes into.
// A slot is either a gradient buffer (reverse mode: accumulate d loss / d parameter) or a
// direction (forward mode: project each sample's derivative on it, for derivative images).
// Null slots are parameters nobody asked about: the sweep skips their work.
#pragma once
#include <cstdint>
#include <map>
#include <mutex>
#include <vector>
#include "math/adjoint.h"
#include "scene/camera.h"

namespace edgepath {

struct GradSlot {
    float* grad = nullptr;       // reverse mode
    const float* dir = nullptr;  // forward mode
    // Where the slot's values sit in a GradSink's cache (number_slots): a key independent of
    // where the buffer happens to be allocated, so that one thread's sums come out the same,
    // bit for bit, whatever memory the buffers get.
    uint32_t key = 0;
    bool wanted() const { return grad != nullptr || dir != nullptr; }
};

struct SceneGradients {
    struct MeshSlots {
        GradSlot vertices, uvs, normals, emission, colors;
        GradSlot spot;  // kSpotParams values (scene/spot.h), for an emitter with a spot profile
    };
    struct PointLightSlots {
        GradSlot position, intensity;  // 3 values each
        GradSlot spot;                 // kSpotParams values
    };
    struct MaterialSlots {
        GradSlot diffuse, specular, roughness, ior, normal_map;
    };
    std::vector<MeshSlots> meshes;        // one per mesh (may be empty: nothing wanted)
    std::vector<MaterialSlots> materials; // one per material
    std::vector<PointLightSlots> point_lights;  // one per point light (or empty)
    GradSlot envmap;                      // (H, W, 3)
    GradSlot envmap_rotation;             // 9 values: the row-major to_world rotation
    GradSlot camera;                      // kCameraParams values (see scene/camera.h)
};

// Gives every slot of `g` a key of its own (GradSlot::key), in a fixed order.
inline void number_slots(SceneGradients& g) {
    uint32_t key = 0;
    for (GradSlot* s : {&g.camera, &g.envmap, &g.envmap_rotation}) s->key = key++;
    for (auto& m : g.meshes)
        for (GradSlot* s : {&m.vertices, &m.uvs, &m.normals, &m.emission, &m.colors, &m.spot}) s->key = key++;
    for (auto& m : g.materials)
        for (GradSlot* s : {&m.diffuse, &m.specular, &m.roughness, &m.ior, &m.normal_map}) s->key = key++;
    for (auto& l : g.point_lights)
        for (GradSlot* s : {&l.position, &l.intensity, &l.spot}) s->key = key++;
}

inline void atomic_add(float* p, float v) {
    float old, desired;
    __atomic_load(p, &old, __ATOMIC_RELAXED);
    do {
        desired = old + v;
    } while (!__atomic_compare_exchange(p, &old, &desired, true, __ATOMIC_RELAXED, __ATOMIC_RELAXED));
}

// One float addition of a gradient pass: *p += v.
struct GradAdd {
    float* p;
    float v;
};
using GradLog = std::vector<GradAdd>;

// The additions of a pass's work items (tiles, chunks of samples), made in the items' order
// whatever the thread that made each and whenever it finished: item i's additions, in the order
// it made them, once every earlier item's are. Each item's additions are the same whatever the
// thread count, so the sums are the same bit for bit. An item that finishes early is held until
// the items before it are in (parallel_indices, render/tiles.h, starts them in order, so few are
// held at a time). Items are numbered from 0, and each must be committed, empty or not, for
// those after it to be applied.
class OrderedAdds {
public:
    // Item `index`'s additions, taken out of `log` (left empty).
    void commit(int64_t index, GradLog& log) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (index != next_) {
            pending_[index].swap(log);
            log.clear();
            return;
        }
        apply(log);
        log.clear();
        ++next_;
        for (auto it = pending_.find(next_); it != pending_.end(); it = pending_.find(next_)) {
            apply(it->second);
            pending_.erase(it);
            ++next_;
        }
    }
    // The items applied so far, and those held now (for the tests).
    int64_t applied() const { return next_; }
    size_t held() const { return pending_.size(); }

private:
    static void apply(const GradLog& log) {
        for (const GradAdd& a : log) *a.p += a.v;
    }
    std::mutex mutex_;
    int64_t next_ = 0;
    std::map<int64_t, GradLog> pending_;
};

// Receives d(sample value)/d(parameter) contributions. Reverse mode buffers them in a
// set-associative cache (constant textures and the camera get hit by every sample) and flushes
// them to the buffers; forward mode sums value * direction. A sink made `ordered` keeps its
// flushes (and the additions given to add_out) in a log that commit() hands to an OrderedAdds,
// once per work item: the sink's cache is empty between items, so an item's additions do not
// depend on which items the same thread ran before. Otherwise they are atomic additions, in an
// order that depends on the threads' timing.
class GradSink {
public:
    explicit GradSink(bool project, bool ordered = false) : project_(project), ordered_(ordered) {
        for (auto& e : cache_) e = {nullptr, 0.0};
    }
    ~GradSink() { flush(); }

    void add(const GradSlot& slot, int64_t i, float v) {
        if (project_) {
            if (slot.dir) projection_ += double(slot.dir[i]) * v;
            return;
        }
        if (!slot.grad) return;
        float* p = slot.grad + i;
        // The home entry is found from the slot's key and the index, never from the address,
        // so which entries collide does not depend on the allocation. Up to kWays entries from
        // the home one: two hot parameters that collide (a camera parameter and a vertex, say)
        // then both stay in double precision, instead of flushing each other at every sample
        // (float atomic adds of partial sums, in an order that depends on the threads' timing).
        const size_t home = size_t(uint64_t(i) + uint64_t(slot.key) * kKeyStride) & (kCacheSize - 1);
        Entry* free_entry = nullptr;
        for (int k = 0; k < kWays; ++k) {
            Entry& e = cache_[(home + size_t(k)) & (kCacheSize - 1)];
            if (e.ptr == p) {
                e.value += v;
                return;
            }
            if (!e.ptr && !free_entry) free_entry = &e;
        }
        Entry* e = free_entry;
        if (!e) {
            e = &cache_[(home + (evict_++ % kWays)) & (kCacheSize - 1)];
            add_out(e->ptr, float(e->value));
        }
        e->ptr = p;
        e->value = v;
    }
    void add3(const GradSlot& slot, int64_t i, float x, float y, float z) {
        add(slot, 3 * i, x);
        add(slot, 3 * i + 1, y);
        add(slot, 3 * i + 2, z);
    }
    // One value per output colour (math/adjoint.h): forward mode only, into the projections of
    // the three colours (take_projections).
    void add(const GradSlot& slot, int64_t i, const Adj3& v) {
        if (!slot.dir) return;
        const double d = double(slot.dir[i]);
        colour_projection_[0] += d * v.v[0];
        colour_projection_[1] += d * v.v[1];
        colour_projection_[2] += d * v.v[2];
    }
    void add3(const GradSlot& slot, int64_t i, const Adj3& x, const Adj3& y, const Adj3& z) {
        add(slot, 3 * i, x);
        add(slot, 3 * i + 1, y);
        add(slot, 3 * i + 2, z);
    }
    // One value per output value's lane (math/adjoint.h, AdjN): forward mode only, into the
    // lanes' projections (take_lane_projections).
    template <int N>
    void add(const GradSlot& slot, int64_t i, const AdjN<N>& v) {
        static_assert(N <= kMaxAdjLanes);
        if (!slot.dir) return;
        const double d = double(slot.dir[i]);
        for (int j = 0; j < N; ++j) lane_projection_[j] += d * v.v[j];
    }
    template <int N>
    void add3(const GradSlot& slot, int64_t i, const AdjN<N>& x, const AdjN<N>& y, const AdjN<N>& z) {
        add(slot, 3 * i, x);
        add(slot, 3 * i + 1, y);
        add(slot, 3 * i + 2, z);
    }
    // An RGB parameter triple's adjoints, one vector per lane.
    template <class A, int N>
    void add_rgb(const GradSlot& slot, int64_t i, const TVec3<AdjN<N>>& v) {
        add3(slot, i, v.x, v.y, v.z);
    }
    // The RGB adjoint v of an RGB parameter triple: channel c belongs to colour c with Adj3.
    template <class A>
    void add_rgb(const GradSlot& slot, int64_t i, const Vec3f& v) {
        if constexpr (std::is_same_v<A, Adj3>) {
            if (!slot.dir) return;
            for (int c = 0; c < 3; ++c) colour_projection_[c] += double(slot.dir[3 * i + c]) * v[c];
        } else {
            add3(slot, i, v.x, v.y, v.z);
        }
    }

    // *p += v: into the log of an ordered sink, else at once (an atomic addition).
    void add_out(float* p, float v) {
        if (ordered_) {
            // Field by field into the log's own storage: a pair built on the stack and copied
            // as one 16-byte load stalls on its two narrower stores (about 2% of an interior
            // pass, in one-thread runs, went to those copies).
            GradAdd& a = log_.emplace_back();
            a.p = p;
            a.v = v;
        } else
            atomic_add(p, v);
    }
    void flush() {
        for (auto& e : cache_)
            if (e.ptr) {
                add_out(e.ptr, float(e.value));
                e.ptr = nullptr;
            }
        evict_ = 0;
    }
    // An ordered sink's additions since the last commit, flushed, as work item `index`'s.
    void commit(OrderedAdds& adds, int64_t index) {
        flush();
        adds.commit(index, log_);
    }
    double take_projection() {
        double p = projection_;
        projection_ = 0.0;
        return p;
    }
    // The three colours' projections of the Adj3 values added since the last call.
    void take_projections(double out[3]) {
        for (int c = 0; c < 3; ++c) {
            out[c] = colour_projection_[c];
            colour_projection_[c] = 0.0;
        }
    }

    // The first n lanes' projections of the AdjN values added since the last call.
    void take_lane_projections(double* out, int n) {
        for (int j = 0; j < n; ++j) {
            out[j] = lane_projection_[j];
            lane_projection_[j] = 0.0;
        }
    }

private:
    // 4096 entries (64 KiB): a tile's scattered additions (an environment map's texels, a
    // texture's, the vertices a tile sees) mostly stay in it. With 256, on the benchmark scene
    // (every parameter wanted), the interior term spent about a tenth of its time logging
    // evictions; at 4096 it is 9-12% faster (1 and 3 bounces), and a flush per tile (a 16 x 16
    // pixel tile, or 4096 primary-edge samples) reads 64 KiB, a few microseconds.
    static constexpr int kCacheSize = 4096, kWays = 4;
    static constexpr uint64_t kKeyStride = 97;  // slots' first values spread over the cache
    unsigned evict_ = 0;
    struct Entry {
        float* ptr;
        double value;
    };
    bool project_;
    bool ordered_;
    GradLog log_;
    double projection_ = 0.0;
    double colour_projection_[3] = {0.0, 0.0, 0.0};
    double lane_projection_[kMaxAdjLanes] = {};
    Entry cache_[kCacheSize];
};

}  // namespace edgepath
