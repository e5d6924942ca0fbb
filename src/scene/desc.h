// Scene description: plain views over caller-owned memory. This is the border of the core:
// the Python bindings (or a C++ program) fill these structs, `Scene::build` validates them
// once and builds everything the kernels need. Nothing here owns or modifies memory.
#pragma once
#include <atomic>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace edgepath {

// A float array of shape (height, width, channels), row-major, contiguous. A constant is a
// 1x1 texture. Lookups are bilinear with texel centres at ((i + 0.5) / width, (j + 0.5) / height),
// wrapping; v = 0 is row 0 (the top row of an image file).
struct TextureDesc {
    const float* data = nullptr;
    int height = 0, width = 0, channels = 0;
    bool empty() const { return data == nullptr; }
    int64_t num_values() const { return data ? int64_t(height) * width * channels : 0; }
};

// Standard: the diffuse + GGX model. Conductor: a smooth mirror, reflectance `specular` at
// normal incidence (Schlick); `diffuse` and `roughness` unused. Dielectric: glass with
// relative index of refraction `ior` (inside over outside), reflecting and refracting by the
// Fresnel equations; smooth where `roughness` is 0, elsewhere rough with it as GGX alpha
// (Walter et al. 2007); `diffuse` and `specular` unused, always two-sided. Plastic: a diffuse
// base under a dielectric coating of relative index `ior` (Mitsuba 3's `plastic` where
// `roughness` is 0, `roughplastic` with GGX alpha `roughness` elsewhere; scene/plastic.h):
// the coating reflects `specular` times its Fresnel reflectance, the base `diffuse` seen
// through it. Its `roughness` and `ior` are constants (one value each).
enum class MaterialKind { Standard = 0, Conductor = 1, Dielectric = 2, Plastic = 3 };

struct MaterialDesc {
    TextureDesc diffuse;    // 3 channels, Lambertian albedo
    TextureDesc specular;   // 3 channels, GGX lobe reflectance at normal incidence (Schlick)
    TextureDesc roughness;  // 1 channel, GGX alpha (Dielectric: 0 where smooth)
    TextureDesc ior;        // 1 channel, relative index of refraction (Dielectric, Plastic)
    // 3 channels, tangent-space normal map (scene/normal_map.h); empty: none. Needs no uvs (the
    // barycentrics stand in) but follows them where given.
    TextureDesc normal_map;
    MaterialKind kind = MaterialKind::Standard;
    bool two_sided = false; // false: black seen from the back (as Mitsuba's BSDFs)
    // Plastic: the base's multiple internal reflections divide its albedo kd by 1 - kd R
    // (Mitsuba's `nonlinear`, colours saturate) rather than by 1 - R.
    bool nonlinear = false;
};

struct MeshDesc {
    const float* vertices = nullptr;     // (num_vertices, 3)
    int64_t num_vertices = 0;
    const int32_t* indices = nullptr;    // (num_triangles, 3)
    int64_t num_triangles = 0;
    const float* uvs = nullptr;          // (num_uvs, 2) or null
    int64_t num_uvs = 0;
    const int32_t* uv_indices = nullptr; // (num_triangles, 3), or null: use `indices`
    const float* normals = nullptr;      // (num_normals, 3) shading normals, or null
    int64_t num_normals = 0;
    const int32_t* normal_indices = nullptr;  // (num_triangles, 3), or null: use `indices`
    // (num_vertices, 3) vertex colours, or null: interpolated by the barycentrics (indexed by
    // `indices`), they multiply the material's diffuse reflectance.
    const float* colors = nullptr;
    int material = 0;                    // index into SceneDesc::materials
    TextureDesc emission;                // 3 channels; empty: not an emitter
    bool two_sided_emission = false;     // false: emits on the side of the face normal only
    // Emission scaled in each outgoing direction by a spot profile (scene/spot.h): its axis,
    // cutoff angle and beam width (radians), when `spot` is set.
    bool spot = false;
    float spot_profile[5] = {0, 0, 1, 0.349066f, 0.261799f};
    // An emitter sampled by solid angle: uniformly in the cone of directions of its bounding
    // sphere (the box's centre, the farthest vertex), towards its first triangle along the
    // direction. Meant for small convex lights around a point (a sphere light): from outside,
    // every sample lands on the side it shows. Otherwise (and from inside the sphere, where
    // it is not sampled) by area, triangle by triangle.
    bool sample_solid_angle = false;
    // An emitter sampled triangle by triangle with a direction uniform in the solid angle the
    // triangle subtends (a spherical triangle,
    // sampling/spherical_triangle.h), where that angle is neither tiny nor near a hemisphere;
    // elsewhere by area. A mesh of at most 16 triangles (a quad) picks its triangle by the
    // solid angle each shows the shading point (none behind a one-sided face), a larger one
    // by power as area sampling does. For large lights near what they light (a quad over a floor), whose
    // area samples' density dist^2 / cos varies widely over the light. Ignored when
    // sample_solid_angle is set.
    bool sample_spherical_triangle = false;
    // A hint: the vertices will move between the calls of a kept scene (they are being
    // optimised). A scene built with such a mesh takes at once the form a scene takes once its
    // vertices have moved (a refittable BVH, an edge list that keeps its nearly flat edges), so
    // that the first move refits instead of rebuilding everything. Its renders and gradients are
    // those of that form (unbiased alike, not bit for bit a static build's).
    bool moves = false;
};

// A light at a point (a delta light, as Mitsuba's `point` and `spot`): it radiates `intensity`
// (W/sr) in every direction, or in a spot profile (scene/spot.h) when `spot` is set. Found only
// by next-event estimation; its shadows have no boundary terms.
struct PointLightDesc {
    float position[3] = {0, 0, 0};
    float intensity[3] = {1, 1, 1};
    bool spot = false;
    float spot_profile[5] = {0, 0, 1, 0.349066f, 0.261799f};
};

// The ranges the kernels (and Embree) assume, checked when a scene is built. Coordinates:
// vertex positions, the camera's position, look_at and up, and an orthographic camera's half
// extents. Embree's float ray-triangle test forms products of three lengths (a distance times
// twice a triangle's area): within +-1e12 they stay below about 4.2e37, under float's 3.4e38;
// beyond about 2e12 a large triangle far from the ray's origin overflows to Inf and is missed
// (at 1e16, the former bound, a box 3e12 wide was seen through). Within the bound every hit
// point, offset ray origin and squared distance stays finite as well. Radiance: emitted
// radiance (times the environment's scale), so that a path's throughput times it stays finite.
constexpr float kMaxCoordinate = 1e12f;
// The least extent of a scene's vertices (the largest side of their bounding box; 0, every
// vertex at one point, renders nothing and is allowed): below it float products of three
// lengths (Embree's test, the re-solved hits) underflow: a scene 6e-14 units across had
// gradients 16 to 37 times too small (its image was right).
constexpr float kMinExtent = 1e-10f;
constexpr float kMaxRadiance = 1e16f;
// Roughness (GGX alpha): its square must stay finite (beyond about 1.8e19 the lobe's density is
// infinity over infinity, a NaN image). Far beyond any lobe's use: above a few units the specular
// lobe is already all but black.
constexpr float kMaxRoughness = 1e16f;
// The film's pixel count: a pixel's index fits in int32, and the default number of primary
// edge samples (pixels times spp) in int64.
constexpr int64_t kMaxPixels = (int64_t(1) << 31) - 1;

enum class CameraType { Perspective = 0, Orthographic = 1, ThinLens = 2, Fisheye = 3, Panorama = 4 };
enum class FilterType { Box = 0, Gaussian = 1, Tent = 2 };

// Camera frame: forward = normalize(look_at - position), right = normalize(cross(forward, up)),
// image up = cross(right, forward). Film point (px, py) in pixels of the full film (py downward)
// maps to the direction forward + (2 px / W - 1) tx right + (1 - 2 py / H) tx (H / W) up,
// tx = tan(fov / 2) (horizontal fov). Orthographic: origin shifted by the same offsets with
// tx replaced by `ortho_scale` (half the width of the view), direction = forward. Thin lens: the
// perspective camera's film, with rays from a point a of the aperture (a disk of radius
// `aperture_radius` around the position in the plane of right and up, drawn per camera sample)
// through the film point's point on the plane of focus at depth `focus_distance` (along
// forward): direction focus_distance (forward + sx right + sy up) - a (Mitsuba's thinlens).
// Fisheye (equidistant): with nx = 2 px / W - 1, ny = (1 - 2 py / H) H / W and r = |(nx, ny)|,
// the direction at angle theta = r fov / 2 from forward, towards nx right + ny up (fov: the full
// angle across the film's width, up to 360 degrees); film points with r > 1 (outside the image
// circle) see nothing (black, not traced). Panorama (equirectangular): longitude
// phi = (2 px / W - 1) pi, latitude lat = (1 - 2 py / H) pi / 2, direction
// cos(lat) (sin(phi) right + cos(phi) forward) + sin(lat) up; fov unused.
struct CameraDesc {
    float position[3] = {0, 0, 0};
    float look_at[3] = {0, 0, 1};
    float up[3] = {0, 1, 0};
    float fov = 45.f;          // degrees, horizontal
    float ortho_scale = 1.f;
    float aperture_radius = 0.f;  // thin lens
    float focus_distance = 1.f;   // thin lens
    CameraType type = CameraType::Perspective;
    int width = 0, height = 0; // full film, pixels
    // Crop window in pixels of the full film; width/height 0 means the whole film.
    int crop_x = 0, crop_y = 0, crop_width = 0, crop_height = 0;
    FilterType filter = FilterType::Box;  // box: one pixel wide
    float filter_stddev = 0.5f;           // Gaussian: stddev (pixels); cut at 4 stddev
    float filter_radius = 1.f;            // Tent: radius (pixels)
};

// Lat-long environment map, Mitsuba's convention: local direction d maps to
// u = atan2(d.x, -d.z) / (2 pi), v = acos(d.y) / pi; texel column i sits at u = (i + 0.5) / W
// (wrapping),
// row j at v = j / (H - 1); bilinear. world = to_world * local.
struct EnvmapDesc {
    TextureDesc values;                     // (H, W, 3) radiance
    float to_world[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major rotation
    float scale = 1.f;
};

struct SceneDesc {
    CameraDesc camera;
    std::vector<MaterialDesc> materials;
    std::vector<MeshDesc> meshes;
    bool has_envmap = false;
    EnvmapDesc envmap;
    std::vector<PointLightDesc> point_lights;
};

enum class LightSampling { MIS = 0, LightOnly = 1, BSDFOnly = 2 };
// How edge samples are distributed. Importance: silhouettes only, by clipped film length,
// stratified. Uniform: every edge by world length, independent samples (the baseline).
enum class EdgeSampling { Importance = 0, Uniform = 1 };

struct RenderOptions {
    int spp = 16;
    int max_bounces = 1;    // scattering events: 0 = emitters seen directly, 1 = direct light
    uint64_t seed = 0;
    int num_threads = 0;    // 0: all cores
    LightSampling sampling = LightSampling::MIS;
    // Boundary terms of the gradient (edge sampling). Switching them off leaves the interior
    // term only: faster, and wrong wherever visibility moves (for comparison and debugging).
    bool primary_edges = true;     // silhouettes seen by the camera
    bool secondary_edges = true;   // silhouettes seen from shading points
    int64_t edge_samples = 0;      // primary edge samples; 0: one per output pixel per spp
    EdgeSampling edge_sampling = EdgeSampling::Importance;
    // Below 1: the secondary edge term is sampled at a path vertex with a probability (Russian
    // roulette, the term divided by it: unbiased) set per class of vertices (the mesh it lies
    // on, its depth) by a small pilot pass, in proportion to the root mean square of the term's
    // gradient there, and no lower than this floor. 1 (the default): at every vertex, no pilot.
    // (Measured at equal time it did not lower the error on the benchmark's scenes: docs.)
    float secondary_survival = 1.f;
    // Emitters seen directly by the camera are hidden, as by Mitsuba's hide_emitters: area
    // lights are transparent to camera rays (which go on to what lies behind them) and the
    // environment seen directly is black; seen after a bounce both stay. The gradient follows
    // the image: no term for hidden emission, and the edges see what the image shows.
    bool hide_emitters = false;
    // The image's paths are those a gradient pass with the same seed retraces, and those of a
    // derivative image with the same seed (the default). False, for an image no gradient will
    // follow, lets its paths sample the environment by its light above its mean, and leave a
    // uniform sky to the BSDF's samples (render/path.h, env_nee): less noise, a shadow ray fewer
    // a vertex under a uniform sky, but other paths than the gradient pass's.
    bool replayable = true;
    // Optional: another thread sets it to stop the call. The loops stop taking work within a
    // sample and the call throws Cancelled; its outputs are then unspecified.
    const std::atomic<bool>* cancel = nullptr;

    bool cancelled() const { return cancel && cancel->load(std::memory_order_relaxed); }
};

// Thrown by a call whose RenderOptions::cancel was set.
struct Cancelled : std::runtime_error {
    Cancelled() : std::runtime_error("cancelled") {}
};

// Counters a render reports (for benchmarks).
struct RenderStats {
    uint64_t camera_rays = 0, shadow_rays = 0, bounce_rays = 0;
};

}  // namespace edgepath
