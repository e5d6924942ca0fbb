// fn(begin, end) over [0, count) in chunks of `chunk` items, in parallel (TBB's default arena)
// where there is more than one chunk, one after another otherwise: for the scene's own updates
// of per-item arrays (each item's result its own, so the same whatever the order). The passes of
// a render use for_each_chunk (render/tiles.h), which keeps to the options' thread count.
#pragma once
#include <cstdint>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace edgepath {

template <class Fn>
void over_chunks(int64_t count, int64_t chunk, Fn&& fn) {
    if (count <= chunk) {
        if (count > 0) fn(int64_t(0), count);
        return;
    }
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, count, chunk),
                      [&](const tbb::blocked_range<int64_t>& r) { fn(r.begin(), r.end()); });
}

}  // namespace edgepath
