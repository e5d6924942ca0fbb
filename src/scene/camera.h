// The camera: perspective (horizontal fov), thin lens (a perspective camera whose rays start on
// a disk and meet on the plane of focus), orthographic, fisheye (equidistant) or panorama
// (equirectangular), given by position / look_at / up.
// See scene/desc.h for the mapping from film points to rays.
#pragma once
#include <cmath>
#include "math/ray.h"
#include "math/vec_diff.h"
#include "sampling/warp.h"
#include "scene/desc.h"

namespace edgepath {

// Whether rays leave from an eye (all but the orthographic camera: film points are directions).
inline bool has_eye(CameraType t) { return t != CameraType::Orthographic; }

// Whether the film is a non-linear map of the direction from the camera's position (fisheye and
// panorama): edges project to curves.
inline bool is_spherical(CameraType t) { return t == CameraType::Fisheye || t == CameraType::Panorama; }

constexpr double kCameraPi = 3.14159265358979323846;

// The direction of film point (px, py) of a fisheye or panorama (scene/desc.h) in the camera's
// axes: d = a right + b up + c forward (unit). `half_fov`: half the fisheye's fov, in radians.
// False outside a fisheye's image circle.
template <class T>
bool spherical_direction(CameraType type, T half_fov, int width, int height, T px, T py, T& a, T& b, T& c) {
    if (type == CameraType::Fisheye) {
        const T nx = 2 * px / T(width) - 1, ny = (1 - 2 * py / T(height)) * T(height) / T(width);
        const T r = std::sqrt(nx * nx + ny * ny);
        if (!(r <= T(1))) return false;
        const T theta = r * half_fov;
        // sin(theta) / r, its limit half_fov at the centre
        const T s = r > T(1e-7) ? std::sin(theta) / r : half_fov;
        a = nx * s;
        b = ny * s;
        c = std::cos(theta);
        return true;
    }
    const T phi = (2 * px / T(width) - 1) * T(kCameraPi), lat = (1 - 2 * py / T(height)) * T(kCameraPi / 2);
    a = std::cos(lat) * std::sin(phi);
    b = std::sin(lat);
    c = std::cos(lat) * std::cos(phi);
    return true;
}

// The lens sample of a pinhole: the centre of the aperture.
constexpr float kLensCentre = 0.5f;

struct Camera {
    Vec3f position, forward, right, up;
    float tx = 1.f;  // tan(fov / 2) for perspective and thin lens, half view width for orthographic
    float half_fov = 0.f;  // fov / 2 in radians (the fisheye's)
    CameraType type = CameraType::Perspective;
    float aperture = 0.f, focus = 1.f;  // thin lens: aperture radius, focus distance
    int width = 0, height = 0;  // full film

    static Camera from_desc(const CameraDesc& d) {
        Camera c;
        c.position = Vec3f::load(d.position);
        c.forward = normalize(Vec3f::load(d.look_at) - c.position);
        c.right = normalize(cross(c.forward, Vec3f::load(d.up)));
        c.up = cross(c.right, c.forward);
        c.type = d.type;
        c.half_fov = float(double(d.fov) * kCameraPi / 360.0);
        c.tx = d.type == CameraType::Orthographic ? d.ortho_scale
               : is_spherical(d.type)             ? 1.f
                                                  : std::tan(c.half_fov);
        c.aperture = d.aperture_radius;
        c.focus = d.focus_distance;
        c.width = d.width;
        c.height = d.height;
        return c;
    }

    // Screen offsets of film point (px, py) (full-film pixels, py downward).
    Vec2f screen(float px, float py) const {
        float sx = (2.f * px / float(width) - 1.f) * tx;
        float sy = (1.f - 2.f * py / float(height)) * tx * float(height) / float(width);
        return {sx, sy};
    }

    // The offset of lens sample (lu, lv) (the unit square) from the camera's position: a point of
    // the aperture's disk in the plane of right and up. Zero for the other cameras.
    Vec3f lens_offset(float lu, float lv) const {
        if (type != CameraType::ThinLens) return Vec3f(0.f);
        const Vec2f l = square_to_disk(lu, lv);
        return (right * l.x + up * l.y) * aperture;
    }

    // Whether film point (px, py) sees the scene: false outside a fisheye's image circle (black,
    // no ray traced).
    bool sees(float px, float py) const {
        if (type != CameraType::Fisheye) return true;
        const float nx = 2.f * px / float(width) - 1.f, ny = (1.f - 2.f * py / float(height)) * float(height) / float(width);
        return nx * nx + ny * ny <= 1.f;
    }

    // The ray of film point (px, py) and lens sample (lu, lv) (used by the thin lens only). Where
    // the camera does not see (sees()), the ray along forward.
    Ray generate_ray(float px, float py, float lu = kLensCentre, float lv = kLensCentre) const {
        Vec2f s = screen(px, py);
        Ray r;
        if (is_spherical(type)) {
            float a = 0.f, b = 0.f, c = 1.f;
            spherical_direction(type, half_fov, width, height, px, py, a, b, c);
            r.origin = position;
            r.dir = normalize(right * a + up * b + forward * c);
        } else if (type == CameraType::Perspective) {
            r.origin = position;
            r.dir = normalize(forward + right * s.x + up * s.y);
        } else if (type == CameraType::ThinLens) {
            // From the lens point towards the film point's point on the plane of focus.
            const Vec3f a = lens_offset(lu, lv);
            r.origin = position + a;
            r.dir = normalize((forward + right * s.x + up * s.y) * focus - a);
        } else {
            r.origin = position + right * s.x + up * s.y;
            r.dir = forward;
        }
        return r;
    }
};


// The camera as a differentiable function of its parameters (pose, fov or orthographic scale,
// aperture radius and focus distance).
template <class T>
struct TCameraParams {
    TVec3<T> position, look_at, up;
    T fov = 45, ortho_scale = 1, aperture_radius = 0, focus_distance = 1;
    CameraType type = CameraType::Perspective;
    int width = 1, height = 1;

    static TCameraParams from_desc(const CameraDesc& d) {
        TCameraParams c;
        c.position = TVec3<T>(TVec3<float>::load(d.position));
        c.look_at = TVec3<T>(TVec3<float>::load(d.look_at));
        c.up = TVec3<T>(TVec3<float>::load(d.up));
        c.fov = T(d.fov);
        c.ortho_scale = T(d.ortho_scale);
        c.aperture_radius = T(d.aperture_radius);
        c.focus_distance = T(d.focus_distance);
        c.type = d.type;
        c.width = d.width;
        c.height = d.height;
        return c;
    }
};

// Gradient slots of the camera, in this order: position[3], look_at[3], up[3], fov, ortho_scale,
// aperture_radius, focus_distance.
constexpr int kCameraParams = 13;

// The ray of film point (px, py) and lens sample (lu, lv) (the thin lens's; a constant of the
// sample, as the film point is). The same as Camera::generate_ray.
template <class T>
void camera_ray(const TCameraParams<T>& c, T px, T py, float lu, float lv, TVec3<T>& o, TVec3<T>& d) {
    TVec3<T> f = normalize(c.look_at - c.position);
    TVec3<T> r = normalize(cross(f, c.up));
    TVec3<T> u = cross(r, f);
    if (is_spherical(c.type)) {
        T a = T(0), b = T(0), cf = T(1);
        spherical_direction(c.type, c.fov * T(kCameraPi / 360.0), c.width, c.height, px, py, a, b, cf);
        o = c.position;
        d = r * a + u * b + f * cf;
        return;
    }
    T tx = has_eye(c.type) ? std::tan(c.fov * T(3.14159265358979323846 / 360.0)) : c.ortho_scale;
    T sx = (2 * px / T(c.width) - 1) * tx;
    T sy = (1 - 2 * py / T(c.height)) * tx * T(c.height) / T(c.width);
    if (c.type == CameraType::Perspective) {
        o = c.position;
        d = normalize(f + r * sx + u * sy);
    } else if (c.type == CameraType::ThinLens) {
        const Vec2f l = square_to_disk(lu, lv);
        TVec3<T> a = (r * T(l.x) + u * T(l.y)) * c.aperture_radius;
        o = c.position + a;
        d = normalize((f + r * sx + u * sy) * c.focus_distance - a);
    } else {
        o = c.position + r * sx + u * sy;
        d = f;
    }
}

template <class T>
void camera_ray(const TCameraParams<T>& c, T px, T py, TVec3<T>& o, TVec3<T>& d) {
    camera_ray(c, px, py, kLensCentre, kLensCentre, o, d);
}

// Adds the adjoint of camera_ray for output adjoints (d_o, d_d) to grad[kCameraParams]. A: the
// adjoints' scalar (T, or math/adjoint.h's lanes: each lane computed as T's code computes it).
template <class T, class A = T>
void d_camera_ray(const TCameraParams<T>& c, T px, T py, float lu, float lv, const TVec3<A>& d_o,
                  const TVec3<A>& d_d, A* grad) {
    TVec3<T> F = c.look_at - c.position;
    TVec3<T> f = normalize(F);
    TVec3<T> R = cross(f, c.up);
    TVec3<T> r = normalize(R);
    TVec3<T> u = cross(r, f);
    const bool persp = has_eye(c.type);
    T tx = persp ? std::tan(c.fov * T(3.14159265358979323846 / 360.0)) : c.ortho_scale;
    T ax = 2 * px / T(c.width) - 1, ay = (1 - 2 * py / T(c.height)) * T(c.height) / T(c.width);
    T sx = ax * tx, sy = ay * tx;
    TVec3<A> dposition(A(0)), df(A(0)), dr(A(0)), du(A(0));
    A dsx = A(0), dsy = A(0);
    if (is_spherical(c.type)) {
        // o = position; d = r a + u b + f cf, (a, b, cf) of the film point (and the fisheye's fov)
        const T half_fov = c.fov * T(kCameraPi / 360.0);
        T a = T(0), b = T(0), cf = T(1);
        spherical_direction(c.type, half_fov, c.width, c.height, px, py, a, b, cf);
        dposition += d_o;
        dr += d_d * a;
        du += d_d * b;
        df += d_d * cf;
        if (c.type == CameraType::Fisheye) {
            // theta = r half_fov: a = nx sin(theta) / r, b = ny sin(theta) / r, cf = cos(theta)
            const T nx = 2 * px / T(c.width) - 1, ny = (1 - 2 * py / T(c.height)) * T(c.height) / T(c.width);
            const T rr = std::sqrt(nx * nx + ny * ny), theta = rr * half_fov;
            const A dhalf = std::cos(theta) * (dot(d_d, r) * nx + dot(d_d, u) * ny) - std::sin(theta) * rr * dot(d_d, f);
            grad[9] += dhalf * T(kCameraPi / 360.0);
        }
    } else if (c.type == CameraType::ThinLens) {
        // a = (r lx + u ly) aperture_radius; o = position + a; w = f + r sx + u sy;
        // d = normalize(w focus_distance - a)
        const Vec2f l = square_to_disk(lu, lv);
        const TVec3<T> lens = r * T(l.x) + u * T(l.y);
        const TVec3<T> a = lens * c.aperture_radius, w = f + r * sx + u * sy;
        const TVec3<A> dD = d_normalize(w * c.focus_distance - a, d_d);
        const TVec3<A> dw = dD * c.focus_distance, da = d_o - dD;
        grad[12] += dot(dD, w);
        grad[11] += dot(da, lens);
        dposition += d_o;
        dr += da * (c.aperture_radius * T(l.x)) + dw * sx;
        du += da * (c.aperture_radius * T(l.y)) + dw * sy;
        df += dw;
        dsx = dot(dw, r);
        dsy = dot(dw, u);
    } else if (persp) {
        // o = position; d = normalize(f + r sx + u sy)
        dposition += d_o;
        TVec3<A> dD = d_normalize(f + r * sx + u * sy, d_d);
        df += dD;
        dr += dD * sx;
        du += dD * sy;
        dsx = dot(dD, r);
        dsy = dot(dD, u);
    } else {
        // o = position + r sx + u sy; d = f
        dposition += d_o;
        dr += d_o * sx;
        du += d_o * sy;
        dsx = dot(d_o, r);
        dsy = dot(d_o, u);
        df += d_d;
    }
    // sx = ax tx, sy = ay tx
    A dtx = dsx * ax + dsy * ay;
    // tx = tan(fov pi / 360) or ortho_scale
    if (is_spherical(c.type))
        ;  // no screen offsets
    else if (persp)
        grad[9] += dtx * (1 + tx * tx) * T(3.14159265358979323846 / 360.0);
    else
        grad[10] += dtx;
    // u = cross(r, f)
    d_cross(r, f, du, dr, df);
    // r = normalize(R), R = cross(f, up)
    TVec3<A> dR = d_normalize(R, dr);
    TVec3<A> dup(A(0));
    d_cross(f, c.up, dR, df, dup);
    // f = normalize(look_at - position)
    TVec3<A> dF = d_normalize(F, df);
    for (int k = 0; k < 3; ++k) {
        grad[k] += dposition[k] - dF[k];
        grad[3 + k] += dF[k];
        grad[6 + k] += dup[k];
    }
}

template <class T>
void d_camera_ray(const TCameraParams<T>& c, T px, T py, const TVec3<T>& d_o, const TVec3<T>& d_d, T* grad) {
    d_camera_ray(c, px, py, kLensCentre, kLensCentre, d_o, d_d, grad);
}

}  // namespace edgepath
