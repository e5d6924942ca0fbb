#include "render/packet.h"

#include "render/embree_lanes.h"

namespace edgepath {

void intersect_packet(const Scene& scene, Tracing tracing, const Ray* rays, int n, FirstHit* first) {
    static_assert(kPacketSize == lanes_of<RTCRay16>(), "intersect_packet traces RTCRayHit16 packets");
    alignas(64) int valid[kPacketSize];
    alignas(64) RTCRayHit16 rh;
    set_packet_constants(rh.ray);
    for (int i = 0; i < n; ++i) set_ray_extent(rh.ray, i, rays[i]);
    close_packet(rh.ray, valid, n);  // unused lanes repeat the first ray, masked off
    clear_hits(rh);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcIntersect16(valid, scene.bvh(tracing), &ctx, &rh);
    for (int i = 0; i < n; ++i) {
        FirstHit& f = first[i];
        f.hit = Hit();
        f.found = lane_hit(scene, rh, i, f.hit);
    }
}

}  // namespace edgepath
