// Lanes of Embree's ray packets (RTCRayHit16, RTCRay16), as the camera's packets
// (render/packet.cpp) and the forward pass's batches (render/batch.cpp) fill and read them.
#pragma once
#include <embree3/rtcore.h>

#include "math/ray.h"
#include "scene/scene.h"

namespace edgepath {

// The number of lanes of a packet type.
template <class RayN>
constexpr int lanes_of() {
    return int(sizeof(RayN::org_x) / sizeof(RayN::org_x[0]));
}

// Lane i of packet r: the ray `ray`'s origin, direction and extent, the lane's other fields
// (mask, flags, time, id) left as they are.
template <class RayN>
inline void set_ray_extent(RayN& r, int i, const Ray& ray) {
    r.org_x[i] = ray.origin.x;
    r.org_y[i] = ray.origin.y;
    r.org_z[i] = ray.origin.z;
    r.dir_x[i] = ray.dir.x;
    r.dir_y[i] = ray.dir.y;
    r.dir_z[i] = ray.dir.z;
    r.tnear[i] = ray.tmin;
    r.tfar[i] = ray.tmax;
}

// Lane i's fields that every ray here has the same: all of Embree's mask bits, no flags, time
// 0, the lane's number as its id. Embree only reads them: a packet that keeps them from one
// trace to the next needs them set once (set_packet_constants), then set_ray_extent.
template <class RayN>
inline void set_lane_constants(RayN& r, int i) {
    r.mask[i] = 0xFFFFFFFFu;
    r.flags[i] = 0;
    r.time[i] = 0.f;
    r.id[i] = unsigned(i);
}
template <class RayN>
inline void set_packet_constants(RayN& r) {
    for (int i = 0; i < int(sizeof(r.org_x) / sizeof(r.org_x[0])); ++i) set_lane_constants(r, i);
}

// Lane i of packet r: the ray `ray`.
template <class RayN>
inline void set_ray_lane(RayN& r, int i, const Ray& ray) {
    set_ray_extent(r, i, ray);
    set_lane_constants(r, i);
}

// Lanes [0, n) of r on in `valid`; the others off, each a copy of lane 0 (a valid ray, should
// Embree read it; their constant fields as set_ray_lane or set_packet_constants left them).
template <class RayN>
inline void close_packet(RayN& r, int* valid, int n) {
    constexpr int lanes = lanes_of<RayN>();
    for (int i = 0; i < lanes; ++i) valid[i] = i < n ? -1 : 0;
    Ray first;
    first.origin = Vec3f(r.org_x[0], r.org_y[0], r.org_z[0]);
    first.dir = Vec3f(r.dir_x[0], r.dir_y[0], r.dir_z[0]);
    first.tmin = r.tnear[0];
    first.tmax = r.tfar[0];
    for (int i = n; i < lanes; ++i) set_ray_extent(r, i, first);
}

// Every lane of rh's hits: none yet.
template <class RayHitN>
inline void clear_hits(RayHitN& rh) {
    for (int i = 0; i < lanes_of<decltype(rh.ray)>(); ++i) {
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
}

// Whether lane i of a traced packet met a surface, and then (into h) what it met (its
// barycentrics settled: Scene::settle_hit).
template <class RayHitN>
inline bool lane_hit(const Scene& scene, const RayHitN& rh, int i, Hit& h) {
    if (rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) return false;
    h.mesh = int(rh.hit.geomID[i]);
    h.prim = int64_t(rh.hit.primID[i]);
    h.b1 = rh.hit.u[i];
    h.b2 = rh.hit.v[i];
    h.t = rh.ray.tfar[i];
    scene.settle_hit(Vec3f(rh.ray.org_x[i], rh.ray.org_y[i], rh.ray.org_z[i]),
                     Vec3f(rh.ray.dir_x[i], rh.ray.dir_y[i], rh.ray.dir_z[i]), h);
    return true;
}

}  // namespace edgepath
