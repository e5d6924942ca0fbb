#include "render/packet.h"

#include <embree3/rtcore.h>

namespace edgepath {

void intersect_packet(const Scene& scene, const Ray* rays, int n, FirstHit* first) {
    static_assert(kPacketSize == 8, "intersect_packet traces RTCRayHit8 packets");
    alignas(32) int valid[kPacketSize];
    alignas(32) RTCRayHit8 rh;
    for (int i = 0; i < kPacketSize; ++i) {
        // Unused lanes repeat the first ray, masked off.
        const Ray& r = rays[i < n ? i : 0];
        valid[i] = i < n ? -1 : 0;
        rh.ray.org_x[i] = r.origin.x;
        rh.ray.org_y[i] = r.origin.y;
        rh.ray.org_z[i] = r.origin.z;
        rh.ray.dir_x[i] = r.dir.x;
        rh.ray.dir_y[i] = r.dir.y;
        rh.ray.dir_z[i] = r.dir.z;
        rh.ray.tnear[i] = r.tmin;
        rh.ray.tfar[i] = r.tmax;
        rh.ray.mask[i] = 0xFFFFFFFFu;
        rh.ray.flags[i] = 0;
        rh.ray.time[i] = 0.f;
        rh.ray.id[i] = unsigned(i);
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcIntersect8(valid, scene.rtc_scene(), &ctx, &rh);
    for (int i = 0; i < n; ++i) {
        FirstHit& f = first[i];
        f.found = rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
        if (!f.found) {
            f.hit = Hit();
            continue;
        }
        f.hit.mesh = int(rh.hit.geomID[i]);
        f.hit.prim = int64_t(rh.hit.primID[i]);
        f.hit.b1 = rh.hit.u[i];
        f.hit.b2 = rh.hit.v[i];
        f.hit.t = rh.ray.tfar[i];
    }
}

}  // namespace edgepath
