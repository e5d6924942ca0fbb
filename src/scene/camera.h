// The camera: perspective (horizontal fov) or orthographic, given by position / look_at / up.
// See scene/desc.h for the mapping from film points to rays.
#pragma once
#include <cmath>
#include "math/ray.h"
#include "scene/desc.h"

namespace edgepath {

struct Camera {
    Vec3f position, forward, right, up;
    float tx = 1.f;  // tan(fov / 2) for perspective, half view width for orthographic
    CameraType type = CameraType::Perspective;
    int width = 0, height = 0;  // full film

    static Camera from_desc(const CameraDesc& d) {
        Camera c;
        c.position = Vec3f::load(d.position);
        c.forward = normalize(Vec3f::load(d.look_at) - c.position);
        c.right = normalize(cross(c.forward, Vec3f::load(d.up)));
        c.up = cross(c.right, c.forward);
        c.type = d.type;
        c.tx = d.type == CameraType::Perspective ? std::tan(d.fov * 0.5f * 3.14159265358979f / 180.f) : d.ortho_scale;
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

    Ray generate_ray(float px, float py) const {
        Vec2f s = screen(px, py);
        Ray r;
        if (type == CameraType::Perspective) {
            r.origin = position;
            r.dir = normalize(forward + right * s.x + up * s.y);
        } else {
            r.origin = position + right * s.x + up * s.y;
            r.dir = forward;
        }
        return r;
    }
};

}  // namespace edgepath
