#include "scene/scene.h"


#include <cmath>
#include <limits>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>

#include "scene/chunks.h"
#include "scene/geometry.h"
#include "scene/normal_map.h"

namespace edgepath {

namespace {

// Triangles per chunk of the update's parallel sweeps (over_chunks).
constexpr int64_t kTriangleChunk = 16384;

RTCDevice shared_device() {
    static RTCDevice device = [] {
        RTCDevice d = rtcNewDevice(nullptr);
        if (!d) throw std::runtime_error("Embree: could not create a device");
        return d;
    }();
    return device;
}

[[noreturn]] void fail(const std::string& field, const std::string& what) {
    throw std::invalid_argument(field + ": " + what);
}

template <class T>
std::string str(const T& v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

void check_finite(const float* data, int64_t n, const std::string& field) {
    for (int64_t i = 0; i < n; ++i)
        if (!std::isfinite(data[i])) fail(field, "value " + str(data[i]) + " at flat index " + str(i) + " is not finite");
}

void check_non_negative(const float* data, int64_t n, const std::string& field) {
    for (int64_t i = 0; i < n; ++i)
        if (data[i] < 0.f) fail(field, "value " + str(data[i]) + " at flat index " + str(i) + " is negative");
}

void check_texture(const TextureDesc& t, int channels, const std::string& field, bool non_negative) {
    if (t.data == nullptr) fail(field, "missing");
    if (t.height < 1 || t.width < 1) fail(field, "empty texture of size " + str(t.height) + "x" + str(t.width));
    if (t.channels != channels)
        fail(field, "expected " + str(channels) + " channels, got " + str(t.channels));
    const int64_t n = t.num_values();
    check_finite(t.data, n, field);
    if (non_negative) check_non_negative(t.data, n, field);
}

// A spot profile (scene/spot.h): a finite, nonzero axis and 0 <= beam width < cutoff <= pi.
void check_spot(const float* p, const std::string& field) {
    check_finite(p, kSpotParams, field);
    if (!(length(Vec3f(p[0], p[1], p[2])) > 0.f)) fail(field, "the axis is zero");
    if (!(p[3] > 0.f && p[3] <= 3.14159265f))
        fail(field, "the cutoff angle must be in (0, pi] radians, got " + str(p[3]));
    if (!(p[4] >= 0.f && p[4] < p[3]))
        fail(field, "the beam width must be in [0, cutoff angle) radians, got " + str(p[4]));
}

void check_indices(const int32_t* idx, int64_t num_triangles, int64_t bound, const std::string& field,
                   const std::string& what) {
    for (int64_t i = 0; i < num_triangles * 3; ++i)
        if (idx[i] < 0 || idx[i] >= bound)
            fail(field, "index " + str(idx[i]) + " out of range for " + str(bound) + " " + what + " (triangle " +
                            str(i / 3) + ")");
}

// Finite values within +-kMaxCoordinate: a point (n = 3) or n / 3 vertices.
void check_coordinates(const float* v, int64_t n, const std::string& field) {
    for (int64_t i = 0; i < n; ++i) {
        const bool finite = std::isfinite(v[i]);
        if (finite && std::abs(v[i]) <= kMaxCoordinate) continue;
        const std::string value = "value " + str(v[i]) + (n > 3 ? " of vertex " + str(i / 3) : std::string());
        fail(field, value + (finite ? " is out of range (|x| <= " + str(kMaxCoordinate) + ")" : " is not finite"));
    }
}

// Radiance values at most kMaxRadiance (after `scale`).
void check_radiance(const TextureDesc& t, float scale, const std::string& field) {
    for (int64_t i = 0; i < t.num_values(); ++i)
        if (t.data[i] * double(scale) > kMaxRadiance)
            fail(field, "radiance " + str(t.data[i] * double(scale)) + " at flat index " + str(i) +
                            " is out of range (at most " + str(kMaxRadiance) + ")");
}

void validate_camera(const CameraDesc& c) {
    if (int(c.type) < 0 || int(c.type) > int(CameraType::Panorama))
        fail("camera.camera_type", "unknown camera type " + str(int(c.type)));
    check_coordinates(c.position, 3, "camera.position");
    check_coordinates(c.look_at, 3, "camera.look_at");
    check_coordinates(c.up, 3, "camera.up");
    if (c.width < 1 || c.height < 1 || int64_t(c.width) * c.height > kMaxPixels)
        fail("camera.resolution", "must be positive with at most " + str(kMaxPixels) + " pixels, got (" +
                                      str(c.height) + ", " + str(c.width) + ")");
    Vec3f f = Vec3f::load(c.look_at) - Vec3f::load(c.position);
    if (!(length(f) > 0.f)) fail("camera.look_at", "equals camera.position");
    Vec3f r = cross(normalize(f), Vec3f::load(c.up));
    if (!(length(r) > 1e-6f)) fail("camera.up", "is zero or parallel to the viewing direction");
    if ((c.type == CameraType::Perspective || c.type == CameraType::ThinLens) && !(c.fov > 0.f && c.fov < 180.f))
        fail("camera.fov", "must be in (0, 180) degrees, got " + str(c.fov));
    if (c.type == CameraType::Fisheye && !(c.fov > 0.f && c.fov <= 360.f))
        fail("camera.fov", "must be in (0, 360] degrees for a fisheye, got " + str(c.fov));
    if (c.type == CameraType::ThinLens) {
        if (!(c.aperture_radius >= 0.f && c.aperture_radius <= kMaxCoordinate))
            fail("camera.aperture_radius", "must be at least 0 and at most " + str(kMaxCoordinate) + ", got " +
                                               str(c.aperture_radius));
        if (!(c.focus_distance > 0.f && c.focus_distance <= kMaxCoordinate))
            fail("camera.focus_distance", "must be positive and at most " + str(kMaxCoordinate) + ", got " +
                                              str(c.focus_distance));
    }
    if (c.type == CameraType::Orthographic &&
        !(c.ortho_scale > 0.f && c.ortho_scale <= kMaxCoordinate &&
          double(c.ortho_scale) * c.height / c.width <= kMaxCoordinate))
        fail("camera.ortho_scale", "must be positive with half extents at most " + str(kMaxCoordinate) + ", got " +
                                       str(c.ortho_scale));
    if (c.filter == FilterType::Gaussian && !(c.filter_stddev > 0.f && c.filter_stddev < 100.f))
        fail("camera.filter_stddev", "must be positive, got " + str(c.filter_stddev));
    if (c.filter == FilterType::Tent && !(c.filter_radius >= 0.5f && c.filter_radius < 100.f))
        fail("camera.filter_radius", "must be in [0.5, 100) pixels, got " + str(c.filter_radius));
    const int64_t cw = c.crop_width ? c.crop_width : c.width, ch = c.crop_height ? c.crop_height : c.height;
    if (c.crop_x < 0 || c.crop_y < 0 || cw < 1 || ch < 1 || c.crop_x + cw > c.width || c.crop_y + ch > c.height)
        fail("camera.crop_window", "(" + str(c.crop_x) + ", " + str(c.crop_y) + ", " + str(cw) + ", " + str(ch) +
                                       ") does not fit in the film of " + str(c.width) + "x" + str(c.height));
}

// The rows of a 3x3 row-major matrix are orthonormal (to a tolerance that lets an optimised
// rotation drift a little) and it does not mirror.
bool is_rotation(const float* m) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double d = 0;
            for (int k = 0; k < 3; ++k) d += double(m[3 * i + k]) * m[3 * j + k];
            if (std::abs(d - (i == j ? 1.0 : 0.0)) > 1e-2) return false;
        }
    return dot(cross(Vec3d(Vec3f::load(m)), Vec3d(Vec3f::load(m + 3))), Vec3d(Vec3f::load(m + 6))) > 0.0;
}

void validate_mesh(const MeshDesc& m, int i, int num_materials) {
    std::string f = "meshes[" + str(i) + "]";
    if (m.num_vertices < 1 || m.vertices == nullptr) fail(f + ".vertices", "mesh has no vertices");
    if (m.num_triangles < 1 || m.indices == nullptr) fail(f + ".indices", "mesh has no triangles");
    check_coordinates(m.vertices, m.num_vertices * 3, f + ".vertices");
    check_indices(m.indices, m.num_triangles, m.num_vertices, f + ".indices", "vertices");
    if (m.uvs) {
        check_finite(m.uvs, m.num_uvs * 2, f + ".uvs");
        if (m.uv_indices)
            check_indices(m.uv_indices, m.num_triangles, m.num_uvs, f + ".uv_indices", "uvs");
        else if (m.num_uvs != m.num_vertices)
            fail(f + ".uvs", "has " + str(m.num_uvs) + " rows but there are " + str(m.num_vertices) +
                                 " vertices and no uv_indices");
    } else if (m.uv_indices) {
        fail(f + ".uv_indices", "given without uvs");
    }
    if (m.normals) {
        check_finite(m.normals, m.num_normals * 3, f + ".normals");
        if (m.normal_indices)
            check_indices(m.normal_indices, m.num_triangles, m.num_normals, f + ".normal_indices", "normals");
        else if (m.num_normals != m.num_vertices)
            fail(f + ".normals", "has " + str(m.num_normals) + " rows but there are " + str(m.num_vertices) +
                                     " vertices and no normal_indices");
        // Only the normals some triangle uses must have a direction: a vertex no face uses (real
        // scans have them) has no meaningful normal, and normal computations give it zero.
        const int32_t* used = m.normal_indices ? m.normal_indices : m.indices;
        for (int64_t k = 0; k < 3 * m.num_triangles; ++k)
            if (!(length(Vec3f::load(m.normals + 3 * int64_t(used[k]))) > 0.f))
                fail(f + ".normals", "normal " + str(used[k]) + " (of triangle " + str(k / 3) + ") is zero");
    } else if (m.normal_indices) {
        fail(f + ".normal_indices", "given without normals");
    }
    if (m.colors) {
        check_finite(m.colors, m.num_vertices * 3, f + ".colors");
        check_non_negative(m.colors, m.num_vertices * 3, f + ".colors");
    }
    if (m.material < 0 || m.material >= num_materials)
        fail(f + ".material", "index " + str(m.material) + " out of range for " + str(num_materials) + " materials");
    if (!m.emission.empty()) {
        check_texture(m.emission, 3, f + ".emission", true);
        check_radiance(m.emission, 1.f, f + ".emission");
    }
    if (m.spot) check_spot(m.spot_profile, f + ".spot_profile");
}

}  // namespace

const std::vector<Edge>& Scene::edges() const {
    if (edges_ready_.load(std::memory_order_acquire)) return edges_;
    std::lock_guard<std::mutex> lock(edges_mutex_);
    if (!edges_ready_.load(std::memory_order_relaxed)) {
        auto desc_of = [&](size_t i) {
            const Mesh& m = meshes[i];
            MeshDesc d;
            d.vertices = m.vertices;
            d.num_vertices = m.num_vertices;
            d.indices = m.indices;
            d.num_triangles = m.num_triangles;
            d.normals = m.normals;
            d.normal_indices = m.normal_indices;
            d.uvs = m.uvs;
            d.uv_indices = m.uv_indices;
            d.colors = m.colors;
            return d;
        };
        // A scene whose vertices move keeps its nearly flat edges (marked): the same list from
        // step to step, so that the edge hierarchy is refit. Its list is brought up to date in
        // place where every mesh's pairs of faces are those it was built with (a move nearly
        // always leaves them so); it is built anew otherwise.
        bool refreshed = moving_ && edge_lists_.size() == meshes.size();
        // (The degenerate triangles: those update() found, kept per mesh.)
        for (size_t i = 0; i < meshes.size() && refreshed; ++i)
            refreshed = edge_lists_[i].refresh(desc_of(i), kept_[i].degenerate, edges_);
        if (!refreshed) {
            edges_.clear();
            edge_lists_.assign(moving_ ? meshes.size() : 0, MeshEdgeList());
            for (size_t i = 0; i < meshes.size(); ++i) {
                if (moving_)
                    edge_lists_[i].build(desc_of(i), kept_[i].degenerate, int32_t(i), edges_);
                else
                    build_mesh_edges(desc_of(i), int32_t(i), edges_);
            }
        }
        edges_ready_.store(true, std::memory_order_release);
    }
    return edges_;
}

const Scene::EdgeMeasures& Scene::edge_measures() const {
    if (measures_ready_.load(std::memory_order_acquire)) return measures_;
    const std::vector<Edge>& all = edges();
    std::lock_guard<std::mutex> lock(measures_mutex_);
    if (!measures_ready_.load(std::memory_order_relaxed)) {
        measures_.length.assign(all.size(), 0.f);
        measures_.smooth_weight.assign(all.size(), 0.0);
        over_chunks(int64_t(all.size()), 16384, [&](int64_t begin, int64_t end) {
            for (int64_t i = begin; i < end; ++i) {
                const Edge& e = all[size_t(i)];
                const Mesh& m = meshes[size_t(e.mesh)];
                measures_.length[size_t(i)] = length(m.vertex(e.v1) - m.vertex(e.v0));
                if (e.kind != EdgeKind::Smooth) continue;
                // The faces' unit normals as the scene keeps them: m.unit_face_normal(f).
                const float c = dot(m.triangle_data[e.f0].ng, m.triangle_data[e.f1].ng);
                measures_.smooth_weight[size_t(i)] = std::acos(std::clamp(double(c), -1.0, 1.0)) / kPi;
            }
        });
        measures_.sampled.assign(meshes.size(), 0);
        for (size_t i = 0; i < all.size(); ++i)
            measures_.sampled[size_t(all[i].mesh)] += !all[i].flat && measures_.length[i] > 0.f;
        measures_ready_.store(true, std::memory_order_release);
    }
    return measures_;
}

Scene::HierarchyStats Scene::hierarchy_stats() const {
    std::lock_guard<std::mutex> lock(hierarchies_->mutex);
    return hierarchy_stats_;
}

Scene::~Scene() { drop_bvhs(); }

namespace {

// The vertices' extent (their coordinates are finite and in range): 0 or at least kMinExtent.
void check_extent(const SceneDesc& desc) {
    Vec3f lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
    for (const MeshDesc& m : desc.meshes)
        for (int64_t i = 0; i < m.num_vertices; ++i) {
            const Vec3f v = Vec3f::load(m.vertices + 3 * i);
            lo = min(lo, v);
            hi = max(hi, v);
        }
    const double extent = max_component(Vec3d(hi) - Vec3d(lo));
    if (extent > 0.0 && extent < kMinExtent)
        fail("meshes", "the vertices span " + str(extent) + " units (the largest side of their bounding box), less than " +
                           str(kMinExtent) + ": float products of lengths would underflow; scale the scene up");
}

void validate(const SceneDesc& desc) {
    for (size_t i = 0; i < desc.point_lights.size(); ++i) {
        const PointLightDesc& l = desc.point_lights[i];
        const std::string f = "point_lights[" + str(i) + "]";
        check_finite(l.position, 3, f + ".position");
        for (int k = 0; k < 3; ++k)
            if (!(std::abs(l.position[k]) <= kMaxCoordinate))
                fail(f + ".position", "value " + str(l.position[k]) + " is beyond " + str(kMaxCoordinate));
        check_finite(l.intensity, 3, f + ".intensity");
        check_non_negative(l.intensity, 3, f + ".intensity");
        for (int k = 0; k < 3; ++k)
            if (!(l.intensity[k] <= kMaxRadiance))
                fail(f + ".intensity", "value " + str(l.intensity[k]) + " is beyond " + str(kMaxRadiance));
        if (l.spot) check_spot(l.spot_profile, f + ".spot_profile");
    }
    validate_camera(desc.camera);
    if (desc.meshes.empty()) fail("meshes", "the scene has no meshes");
    for (size_t i = 0; i < desc.materials.size(); ++i) {
        std::string f = "materials[" + str(i) + "]";
        check_texture(desc.materials[i].diffuse, 3, f + ".diffuse", true);
        check_texture(desc.materials[i].specular, 3, f + ".specular", true);
        check_texture(desc.materials[i].roughness, 1, f + ".roughness", true);
        for (int64_t k = 0; k < desc.materials[i].roughness.num_values(); ++k)
            if (!(desc.materials[i].roughness.data[k] <= kMaxRoughness))
                fail(f + ".roughness", "value " + str(desc.materials[i].roughness.data[k]) + " at flat index " + str(k) +
                                           " is out of range (at most " + str(kMaxRoughness) + ")");
        const MaterialDesc& md = desc.materials[i];
        if (!md.normal_map.empty()) check_texture(md.normal_map, 3, f + ".normal_map", false);
        if (int(md.kind) < 0 || int(md.kind) > int(MaterialKind::Plastic))
            fail(f + ".kind", "unknown material kind " + str(int(md.kind)));
        if (md.kind == MaterialKind::Dielectric || md.kind == MaterialKind::Plastic) {
            check_texture(md.ior, 1, f + ".ior", true);
            for (int64_t k = 0; k < md.ior.num_values(); ++k)
                if (!(md.ior.data[k] >= kMinIor && md.ior.data[k] <= kMaxIor))
                    fail(f + ".ior", "value " + str(md.ior.data[k]) + " at flat index " + str(k) + " is outside [" +
                                         str(kMinIor) + ", " + str(kMaxIor) + "]");
        }
        if (md.kind == MaterialKind::Plastic) {
            // The coating's tables are built for one roughness and one index.
            if (md.roughness.num_values() != 1)
                fail(f + ".roughness", "a plastic's roughness must be one value, got " +
                                           str(md.roughness.num_values()));
            if (md.ior.num_values() != 1)
                fail(f + ".ior", "a plastic's ior must be one value, got " + str(md.ior.num_values()));
            if (std::abs(md.ior.data[0] - 1.f) < kMinCoatIndexContrast)
                fail(f + ".ior", "a plastic's coating needs an index other than 1, got " + str(md.ior.data[0]));
            // Nonlinear: kd / (1 - kd R) stays finite and positive for albedos up to 1 (R < 1).
            if (md.nonlinear)
                for (int64_t k = 0; k < md.diffuse.num_values(); ++k)
                    if (md.diffuse.data[k] > 1.f)
                        fail(f + ".diffuse", "a nonlinear plastic's diffuse must be at most 1, got " +
                                                 str(md.diffuse.data[k]) + " at flat index " + str(k));
        }
    }
    for (size_t i = 0; i < desc.meshes.size(); ++i) {
        const MeshDesc& m = desc.meshes[i];
        validate_mesh(m, int(i), int(desc.materials.size()));
        // Vertex colours multiply a nonlinear plastic's diffuse: at most 1 too.
        if (m.colors && desc.materials[size_t(m.material)].kind == MaterialKind::Plastic &&
            desc.materials[size_t(m.material)].nonlinear)
            for (int64_t k = 0; k < m.num_vertices * 3; ++k)
                if (m.colors[k] > 1.f)
                    fail("meshes[" + str(i) + "].colors", "on a nonlinear plastic, colours must be at most 1, got " +
                                                              str(m.colors[k]) + " at flat index " + str(k));
    }
    check_extent(desc);
    if (desc.has_envmap) {
        check_texture(desc.envmap.values, 3, "envmap.values", true);
        check_finite(desc.envmap.to_world, 9, "envmap.to_world");
        if (!is_rotation(desc.envmap.to_world)) fail("envmap.to_world", "is not a rotation");
        if (!(desc.envmap.scale >= 0.f && std::isfinite(desc.envmap.scale)))
            fail("envmap.scale", "must be finite and non-negative, got " + str(desc.envmap.scale));
        check_radiance(desc.envmap.values, desc.envmap.scale, "envmap.values");
    }
}

template <class T>
std::vector<T> copy_of(const T* data, int64_t n) {
    return data ? std::vector<T>(data, data + n) : std::vector<T>();
}

template <class T>
bool same(const std::vector<T>& kept, const T* data, int64_t n) {
    if (!data) return kept.empty();
    return kept.size() == size_t(n) && std::equal(kept.begin(), kept.end(), data);
}

}  // namespace

std::shared_ptr<Scene> Scene::build(const SceneDesc& desc) {
    std::shared_ptr<Scene> s(new Scene());
    s->hierarchies_ = std::make_unique<KeptHierarchies>();
    s->update(desc);
    return s;
}

Scene::Update Scene::update(const SceneDesc& desc) {
    validate(desc);
    const size_t n = desc.meshes.size();
    bool same_topology = updated_ && kept_.size() == n;
    bool same_vertices = same_topology, same_shading = same_topology;
    for (size_t i = 0; i < n && same_topology; ++i) {
        const MeshDesc& md = desc.meshes[i];
        const Kept& k = kept_[i];
        same_topology = md.num_vertices == k.num_vertices && same(k.indices, md.indices, 3 * md.num_triangles) &&
                        same(k.uv_indices, md.uv_indices, 3 * md.num_triangles) &&
                        same(k.normal_indices, md.normal_indices, 3 * md.num_triangles) &&
                        (md.uvs == nullptr) == (k.num_uvs < 0) && (md.uvs == nullptr || md.num_uvs == k.num_uvs) &&
                        (md.normals == nullptr) == (k.num_normals < 0) &&
                        (md.normals == nullptr || md.num_normals == k.num_normals);
        if (!same_topology) break;
        same_vertices = same_vertices && same(k.vertices, md.vertices, 3 * md.num_vertices);
        same_shading = same_shading && same(k.uvs, md.uvs, 2 * md.num_uvs) &&
                       same(k.normals, md.normals, 3 * md.num_normals) &&
                       same(k.colors, md.colors, 3 * md.num_vertices);
    }
    set_views(desc);
    Update what = !same_topology ? Update::Built : !same_vertices ? Update::Refit : Update::Reused;
    // Which triangles are degenerate (skipped by the BVHs, a NaN vertex in their index buffers:
    // prepare_bvh) depends on the positions; a change of that is a build, as is the first move (a
    // scene whose vertices have moved once is built for refitting from then on).
    std::vector<std::vector<uint8_t>> degenerate(n);
    if (what != Update::Reused) {
        for (size_t i = 0; i < n; ++i) {
            Mesh& m = meshes[i];
            degenerate[i].resize(size_t(m.num_triangles));
            uint8_t* flags = degenerate[i].data();
            over_chunks(m.num_triangles, kTriangleChunk, [&](int64_t b, int64_t e) {
                for (int64_t t = b; t < e; ++t) flags[t] = m.is_degenerate(t);
            });
            m.num_degenerate = 0;
            for (int64_t t = 0; t < m.num_triangles; ++t) m.num_degenerate += flags[t];
            if (what == Update::Refit && degenerate[i] != kept_[i].degenerate) what = Update::Built;
        }
        if (what == Update::Refit && !moving_) what = Update::Built;
        // (A mesh whose vertices are known to move: that form from the first build.)
        bool hinted = false;
        for (const MeshDesc& md : desc.meshes) hinted = hinted || md.moves;
        moving_ = moving_ || same_topology || hinted;
    }
    if (what != Update::Reused || !same_shading) {
        // The edge list depends on positions (welding, creases), uvs and normals: rebuilt on use,
        // from the meshes' kept lists where only the positions changed.
        edges_ready_.store(false, std::memory_order_relaxed);
        measures_ready_.store(false, std::memory_order_relaxed);
        if (what == Update::Built || !same_shading) edge_lists_.clear();
        ++geometry_version_;
        kept_.resize(n);
        for (size_t i = 0; i < n; ++i) {
            const MeshDesc& md = desc.meshes[i];
            Kept& k = kept_[i];
            k.num_vertices = md.num_vertices;
            k.vertices = copy_of(md.vertices, 3 * md.num_vertices);
            k.indices = copy_of(md.indices, 3 * md.num_triangles);
            k.uv_indices = copy_of(md.uv_indices, 3 * md.num_triangles);
            k.normal_indices = copy_of(md.normal_indices, 3 * md.num_triangles);
            k.num_uvs = md.uvs ? md.num_uvs : -1;
            k.uvs = copy_of(md.uvs, 2 * md.num_uvs);
            k.num_normals = md.normals ? md.num_normals : -1;
            k.normals = copy_of(md.normals, 3 * md.num_normals);
            k.colors = copy_of(md.colors, 3 * md.num_vertices);
            if (what != Update::Reused) k.degenerate = std::move(degenerate[i]);
            k.triangle_data.resize(size_t(md.num_triangles));
            over_chunks(md.num_triangles, kTriangleChunk, [&](int64_t b, int64_t e) {
                for (int64_t t = b; t < e; ++t) {
                    TriangleData& td = k.triangle_data[size_t(t)];
                    const int32_t* tri = md.indices + 3 * t;
                    td.v0 = Vec3f::load(md.vertices + 3 * int64_t(tri[0]));
                    td.v1 = Vec3f::load(md.vertices + 3 * int64_t(tri[1]));
                    td.v2 = Vec3f::load(md.vertices + 3 * int64_t(tri[2]));
                    td.ng = cross_normal(td.v1 - td.v0, td.v2 - td.v0);
                    td.largest_edge = triangle_largest_edge(td.v0, td.v1, td.v2);
                }
            });
        }
    }
    for (size_t i = 0; i < n; ++i) meshes[i].triangle_data = kept_[i].triangle_data.data();
    updated_ = true;
    if (what == Update::Built) drop_bvhs();
    if (what == Update::Refit) {
        std::lock_guard<std::mutex> lock(bvh_mutex_);
        for (BvhSlot& slot : bvh_) slot.ready.store(false, std::memory_order_relaxed);  // refitted on use
    }
    build_lights();
    if (what == Update::Reused) {
        std::lock_guard<std::mutex> lock(bvh_mutex_);
        ++stats_.reuses;
    }
    return what;
}

void Scene::set_camera(const CameraDesc& cd) {
    validate_camera(cd);
    camera = Camera::from_desc(cd);
    camera_params = TCameraParams<float>::from_desc(cd);
    filter.build(cd.filter, cd.filter_stddev, cd.filter_radius);
    crop_x = cd.crop_x;
    crop_y = cd.crop_y;
    out_width = cd.crop_width ? cd.crop_width : cd.width;
    out_height = cd.crop_height ? cd.crop_height : cd.height;
}

void Scene::set_views(const SceneDesc& desc) {
    set_camera(desc.camera);
    materials.clear();
    for (const MaterialDesc& md : desc.materials) {
        Material m;
        m.diffuse = Texture(md.diffuse);
        m.specular = Texture(md.specular);
        m.roughness = Texture(md.roughness);
        m.kind = md.kind;
        if (md.kind == MaterialKind::Dielectric || md.kind == MaterialKind::Plastic) m.ior = Texture(md.ior);
        if (md.kind == MaterialKind::Plastic) {
            const float roughness = md.roughness.data[0];
            m.coat = coat_table(ggx_alpha(roughness), md.ior.data[0], !(roughness > 0.f));
            m.nonlinear = md.nonlinear;
        }
        m.normal_map = Texture(md.normal_map);
        m.two_sided = md.two_sided || md.kind == MaterialKind::Dielectric;
        materials.push_back(m);
    }

    meshes.resize(desc.meshes.size());
    for (size_t i = 0; i < desc.meshes.size(); ++i) {
        const MeshDesc& md = desc.meshes[i];
        Mesh& m = meshes[i];
        m.vertices = md.vertices;
        m.num_vertices = md.num_vertices;
        m.indices = md.indices;
        m.num_triangles = md.num_triangles;
        m.uvs = md.uvs;
        m.uv_indices = md.uvs ? (md.uv_indices ? md.uv_indices : md.indices) : nullptr;
        m.normals = md.normals;
        m.normal_indices = md.normals ? (md.normal_indices ? md.normal_indices : md.indices) : nullptr;
        m.colors = md.colors;
        m.material = md.material;
        m.emission = Texture(md.emission);
        m.two_sided_emission = md.two_sided_emission;
        m.spot = md.spot;
        m.solid_angle = md.sample_solid_angle;
        m.spherical_triangle = md.sample_spherical_triangle && !md.sample_solid_angle;
        std::copy(md.spot_profile, md.spot_profile + kSpotParams, m.spot_profile);
    }
    point_lights = desc.point_lights;

    has_envmap = desc.has_envmap;
    envmap = Envmap();
    env_sampled = false;
    if (desc.has_envmap) {
        envmap.build(desc.envmap);
        env_sampled = envmap.dist.valid() && envmap.scale > 0.f;
    }
}

RTCScene Scene::prepare_bvh(Tracing tracing) const {
    std::lock_guard<std::mutex> lock(bvh_mutex_);
    BvhSlot& slot = bvh_[int(tracing)];
    if (slot.ready.load(std::memory_order_relaxed)) return slot.rtc;
    RTCDevice device = shared_device();
    if (slot.rtc) {
        // Held since before the vertices moved (refittable: update() drops it otherwise): to
        // the kept positions.
        for (size_t i = 0; i < kept_.size(); ++i) {
            RTCGeometry g = rtcGetGeometry(slot.rtc, unsigned(i));
            float* vb = static_cast<float*>(rtcGetGeometryBufferData(g, RTC_BUFFER_TYPE_VERTEX, 0));
            std::copy(kept_[i].vertices.begin(), kept_[i].vertices.end(), vb);
            rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
            rtcCommitGeometry(g);
        }
        rtcCommitScene(slot.rtc);
        if (rtcGetDeviceError(device) != RTC_ERROR_NONE) throw std::runtime_error("Embree: scene refit failed");
        ++stats_.refits;
        slot.ready.store(true, std::memory_order_release);
        return slot.rtc;
    }
    RTCScene rtc = rtcNewScene(device);
    // The context filter serves intersect_excluding, whose queries are exact; others pass none.
    RTCSceneFlags flags = tracing == Tracing::Exact
                              ? RTCSceneFlags(RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION)
                              : RTC_SCENE_FLAG_NONE;
    if (moving_) flags = RTCSceneFlags(flags | RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneFlags(rtc, flags);
    // Refittable: Embree's two-level BVH, one SAH-built BVH per mesh (RTC_BUILD_QUALITY_REFIT)
    // under a top level over the meshes. The scene's quality must be low for that: at the
    // default (medium) quality a dynamic scene is rebuilt whole at every commit (measured on a
    // 100k-triangle mesh: 200 ms a commit, against 20 ms at low quality).
    if (moving_) rtcSetSceneBuildQuality(rtc, RTC_BUILD_QUALITY_LOW);
    for (size_t i = 0; i < kept_.size(); ++i) {
        const Kept& k = kept_[i];
        const size_t triangles = k.degenerate.size();
        RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
        if (moving_) rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_REFIT);
        // The mesh's vertices and one more, NaN, after them (a refit copies the first ones only).
        float* vb = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                                3 * sizeof(float), size_t(k.num_vertices) + 1));
        std::copy(k.vertices.begin(), k.vertices.end(), vb);
        std::fill(vb + 3 * k.num_vertices, vb + 3 * k.num_vertices + 3, std::numeric_limits<float>::quiet_NaN());
        uint32_t* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                      3 * sizeof(uint32_t), triangles));
        // A degenerate triangle has the NaN vertex for all three corners: Embree's builders leave
        // out a triangle with a vertex that is not finite, so no ray hits it, and it keeps its
        // primitive id, so hits index the caller's triangles. (Collapsed to its first vertex
        // instead, it was a box of zero size: degenerate triangles clustered apart from the rest,
        // at a vertex far from the others, failed an assertion of the two-level builder a moving
        // mesh gets, which aborted the process.)
        const uint32_t invalid = uint32_t(k.num_vertices);
        for (size_t t = 0; t < triangles; ++t)
            for (int c = 0; c < 3; ++c) ib[3 * t + c] = k.degenerate[t] ? invalid : uint32_t(k.indices[3 * t + c]);
        rtcCommitGeometry(g);
        rtcAttachGeometryByID(rtc, g, unsigned(i));
        rtcReleaseGeometry(g);
    }
    rtcCommitScene(rtc);
    if (rtcGetDeviceError(device) != RTC_ERROR_NONE) {
        rtcReleaseScene(rtc);
        throw std::runtime_error("Embree: scene build failed");
    }
    slot.rtc = rtc;
    ++stats_.builds;
    slot.ready.store(true, std::memory_order_release);
    return rtc;
}

void Scene::drop_bvhs() {
    std::lock_guard<std::mutex> lock(bvh_mutex_);
    for (BvhSlot& slot : bvh_) {
        if (slot.rtc) rtcReleaseScene(slot.rtc);
        slot.rtc = nullptr;
        slot.ready.store(false, std::memory_order_relaxed);
    }
}

void Scene::build_lights() {
    lights.clear();
    emitter_boxes.clear();
    std::vector<double> light_weights;
    for (size_t i = 0; i < meshes.size(); ++i) {
        Mesh& m = meshes[i];
        m.light_offset = -1;
        if (!m.is_emitter()) continue;
        m.light_offset = int64_t(lights.size());
        m.spherical_by_mesh = m.spherical_triangle && m.num_triangles <= kSphericalPickMax;
        double power = luminance(texture_mean3(m.emission)) * (m.two_sided_emission ? 2.0 : 1.0);
        double total = 0.0;
        Vec3f lo, hi;  // the box of the triangles' vertices
        for (int64_t t = 0; t < m.num_triangles; ++t) {
            Vec3f a = m.vertex(m.indices[3 * t]), b = m.vertex(m.indices[3 * t + 1]), c = m.vertex(m.indices[3 * t + 2]);
            float area = m.is_degenerate(t) ? 0.f : m.triangle_area(t);
            total += area;
            if (t == 0) lo = hi = a;
            for (const Vec3f& v : {a, b, c}) {
                lo = min(lo, v);
                hi = max(hi, v);
            }
            if (m.solid_angle || m.spherical_by_mesh) continue;
            lights.push_back({int(i), t, area});
            light_weights.push_back(area * power);
        }
        if (m.num_triangles > 0) {
            // Wider by a thousandth of its size and of its distance from the origin: far more
            // than the rounding of a hit's distance or of may_meet_emitter's.
            const float pad = 1e-3f * (max_component(hi - lo) + std::max(max_abs_component(lo), max_abs_component(hi)));
            emitter_boxes.push_back({lo - Vec3f(pad), hi + Vec3f(pad)});
        }
        if (m.solid_angle) {
            // One entry for the mesh, weighted by its power as its triangles would be.
            m.sphere_center = (lo + hi) * 0.5f;
            m.sphere_radius = 0.f;
            for (int64_t t = 0; t < 3 * m.num_triangles; ++t)
                m.sphere_radius = std::max(m.sphere_radius, length(m.vertex(m.indices[t]) - m.sphere_center));
            // Float rounding of the distances: the sphere must contain every vertex.
            m.sphere_radius *= 1.f + 1e-6f;
            lights.push_back({int(i), -1, float(total)});
            light_weights.push_back(total * power);
        } else if (m.spherical_by_mesh) {
            // One entry for the mesh; its triangle is picked from the shading point.
            lights.push_back({int(i), -1, float(total)});
            light_weights.push_back(total * power);
        }
    }
    light_distribution = Distribution1D();
    light_distribution.build(light_weights);
}

int Scene::may_meet_emitter(const float* const origin[3], const float* const dir[3], int n, int* may) const {
    // Slabs by reciprocal directions: a zero direction's slab gives t = +-inf (the box missed
    // or the whole line inside it) or NaN (the origin on the slab's plane), which the max and
    // min below ignore: the box is then taken as met, never wrongly missed.
    constexpr int kChunk = 16;
    int count = 0;
    for (int begin = 0; begin < n; begin += kChunk) {
        const int m = std::min(kChunk, n - begin);
        float inv[3][kChunk];
        int met[kChunk] = {};
        for (int a = 0; a < 3; ++a)
            for (int i = 0; i < m; ++i) inv[a][i] = 1.f / dir[a][begin + i];
        for (const Box& b : emitter_boxes)
            for (int i = 0; i < m; ++i) {
                float t0 = 0.f, t1 = std::numeric_limits<float>::infinity();
                for (int a = 0; a < 3; ++a) {
                    const float o = origin[a][begin + i];
                    const float near = (b.lo[a] - o) * inv[a][i], far = (b.hi[a] - o) * inv[a][i];
                    t0 = std::max(t0, std::min(near, far));
                    t1 = std::min(t1, std::max(near, far));
                }
                met[i] |= t0 <= t1;
            }
        for (int i = 0; i < m; ++i) {
            may[begin + i] = met[i] ? -1 : 0;
            count += met[i];
        }
    }
    return count;
}

void Scene::resolve_barycentrics(const Vec3f& origin, const Vec3f& dir, Hit& hit) const {
    const Mesh& m = meshes[size_t(hit.mesh)];
    const int32_t* tri = m.indices + 3 * hit.prim;
    TriangleHit<double> h;
    if (!intersect_triangle(Vec3d(origin), Vec3d(dir), Vec3d(m.vertex(tri[0])), Vec3d(m.vertex(tri[1])),
                            Vec3d(m.vertex(tri[2])), h) ||
        !std::isfinite(h.b1) || !std::isfinite(h.b2))
        return;
    double b1 = h.b1, b2 = h.b2;
    clamp_into_triangle(b1, b2);
    hit.b1 = float(b1);
    hit.b2 = float(b2);
}

// The hit of an answered query, if any.
bool Scene::hit_of(const RTCRayHit& rh, Hit& hit) const {
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
    hit.mesh = int(rh.hit.geomID);
    hit.prim = int64_t(rh.hit.primID);
    hit.b1 = rh.hit.u;
    hit.b2 = rh.hit.v;
    hit.t = rh.ray.tfar;
    settle_hit(Vec3f(rh.ray.org_x, rh.ray.org_y, rh.ray.org_z), Vec3f(rh.ray.dir_x, rh.ray.dir_y, rh.ray.dir_z), hit);
    return true;
}

bool Scene::intersect(const Ray& ray, Hit& hit, Tracing tracing) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh = to_rtc_ray_hit(ray);
    rtcIntersect1(bvh(tracing), &ctx, &rh);
    return hit_of(rh, hit);
}

namespace {
// An intersection context that rejects two faces of one mesh (Embree passes the context to the
// filter, which finds the faces after it).
struct ExcludingContext {
    RTCIntersectContext rtc;
    unsigned mesh;
    unsigned f0, f1;
};

void reject_excluded(const RTCFilterFunctionNArguments* args) {
    const ExcludingContext* c = reinterpret_cast<const ExcludingContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const unsigned geom = RTCHitN_geomID(args->hit, args->N, i), prim = RTCHitN_primID(args->hit, args->N, i);
        if (geom == c->mesh && (prim == c->f0 || prim == c->f1)) args->valid[i] = 0;
    }
}
}  // namespace

bool Scene::intersect_excluding(const Ray& ray, int mesh, int64_t f0, int64_t f1, Hit& hit) const {
    ExcludingContext c;
    rtcInitIntersectContext(&c.rtc);
    c.rtc.filter = reject_excluded;
    c.mesh = unsigned(mesh);
    c.f0 = f0 < 0 ? RTC_INVALID_GEOMETRY_ID : unsigned(f0);
    c.f1 = f1 < 0 ? RTC_INVALID_GEOMETRY_ID : unsigned(f1);
    RTCRayHit rh = to_rtc_ray_hit(ray);
    rtcIntersect1(bvh(Tracing::Exact), &c.rtc, &rh);
    return hit_of(rh, hit);
}

bool Scene::occluded(const Ray& ray, Tracing tracing) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay r = to_rtc_ray(ray);
    rtcOccluded1(bvh(tracing), &ctx, &r);
    return r.tfar < 0.f;
}

SurfacePoint Scene::surface_point(int mesh, int64_t prim, float b1, float b2) const {
    const Mesh& m = meshes[mesh];
    SurfacePoint sp;
    surface_point_base(mesh, prim, b1, b2, sp);
    const float b0 = 1.f - b1 - b2;
    if (m.normals) {
        const int32_t* ni = m.normal_indices + 3 * prim;
        Vec3f n = Vec3f::load(m.normals + 3 * ni[0]) * b0 + Vec3f::load(m.normals + 3 * ni[1]) * b1 +
                  Vec3f::load(m.normals + 3 * ni[2]) * b2;
        float l = length(n);
        sp.ns = l > 0.f ? n / l : sp.ng;
    }
    if (m.uvs) {
        const int32_t* ti = m.uv_indices + 3 * prim;
        const float *t0 = m.uvs + 2 * ti[0], *t1 = m.uvs + 2 * ti[1], *t2 = m.uvs + 2 * ti[2];
        sp.uv = Vec2f(t0[0] * b0 + t1[0] * b1 + t2[0] * b2, t0[1] * b0 + t1[1] * b1 + t2[1] * b2);
    }
    const Texture& normal_map = materials[size_t(m.material)].normal_map;
    if (!normal_map.empty()) {
        Vec3f dpdu;
        const bool has_dpdu = triangle_dpdu(mesh, prim, dpdu);
        sp.ns = map_normal(sp.ns, has_dpdu, dpdu, eval_texture3(normal_map, sp.uv));
    }
    return sp;
}

Vec3f Scene::unmapped_normal(int mesh, int64_t prim, float b1, float b2) const {
    const Mesh& m = meshes[size_t(mesh)];
    const Vec3f ng = m.triangle_data[prim].ng;
    if (!m.normals) return ng;
    const int32_t* ni = m.normal_indices + 3 * prim;
    const Vec3f n = Vec3f::load(m.normals + 3 * ni[0]) * (1.f - b1 - b2) + Vec3f::load(m.normals + 3 * ni[1]) * b1 +
                    Vec3f::load(m.normals + 3 * ni[2]) * b2;
    const float l = length(n);
    return l > 0.f ? n / l : ng;
}

bool Scene::triangle_dpdu(int mesh, int64_t prim, Vec3f& dpdu) const {
    const Mesh& m = meshes[size_t(mesh)];
    const int32_t* tri = m.indices + 3 * prim;
    const Vec3f v0 = m.vertex(tri[0]);
    Vec2f d1(1.f, 0.f), d2(0.f, 1.f);  // without uvs: uv = (b1, b2)
    if (m.uvs) {
        const int32_t* ti = m.uv_indices + 3 * prim;
        const float *t0 = m.uvs + 2 * ti[0], *t1 = m.uvs + 2 * ti[1], *t2 = m.uvs + 2 * ti[2];
        d1 = Vec2f(t1[0] - t0[0], t1[1] - t0[1]);
        d2 = Vec2f(t2[0] - t0[0], t2[1] - t0[1]);
    }
    return edgepath::triangle_dpdu(m.vertex(tri[1]) - v0, m.vertex(tri[2]) - v0, d1, d2, dpdu);
}

Vec3f Scene::diffuse_reflectance(const SurfacePoint& sp) const {
    const Mesh& mesh = meshes[sp.mesh];
    const Vec3f kd = eval_texture3(materials[mesh.material].diffuse, sp.uv);
    return mesh.colors ? kd * mesh.color(sp.prim, sp.b1, sp.b2) : kd;
}

BsdfParams Scene::bsdf_params(const SurfacePoint& sp) const {
    const Material& m = materials[meshes[sp.mesh].material];
    BsdfParams p;
    p.diffuse = diffuse_reflectance(sp);
    p.specular = eval_texture3(m.specular, sp.uv);
    const float roughness = eval_texture1(m.roughness, sp.uv);
    p.alpha = ggx_alpha(roughness);
    p.two_sided = m.two_sided;
    p.kind = m.kind;
    if (m.kind == MaterialKind::Dielectric || m.kind == MaterialKind::Plastic) {
        p.eta = eval_texture1(m.ior, sp.uv);
        p.rough = roughness > 0.f;
    }
    if (m.kind == MaterialKind::Plastic) {
        p.coat = m.coat.get();
        p.nonlinear = m.nonlinear;
    }
    return p;
}

Vec3f Scene::emitted(const SurfacePoint& sp, const Vec3f& w) const {
    const Mesh& m = meshes[sp.mesh];
    if (!m.is_emitter()) return Vec3f(0.f);
    // The emitting side is that of the face normal: deciding it by the interpolated shading
    // normal would switch emission off along curves inside triangles near silhouettes, which
    // move with the geometry but lie on no edge.
    if (!m.two_sided_emission && dot(sp.ng, w) <= 0.f) return Vec3f(0.f);
    return eval_texture3(m.emission, sp.uv) * spot_scale(m.spot, m.spot_profile, w);
}

bool Scene::sample_env(float u1, float u2, LightSample& ls, bool compensated) const {
    if (!env_sampled) return false;
    Vec3f dir, radiance;
    float pdf;
    if (!envmap.sample(u1, u2, dir, pdf, compensated, &radiance)) return false;
    ls.dir = dir;
    ls.dist = std::numeric_limits<float>::infinity();
    ls.radiance = radiance;
    ls.pdf = pdf;
    ls.hit = Hit();
    return ls.pdf > 0.f;
}

bool Scene::light_cone(const Mesh& m, const Vec3f& p, Vec3f& axis, float& one_minus_cos) const {
    const Vec3f to = m.sphere_center - p;
    const float d2 = length_squared(to);
    const float r2 = m.sphere_radius * m.sphere_radius;
    if (!(d2 > r2)) return false;
    axis = to / std::sqrt(d2);
    // 1 - sqrt(1 - s) without the cancellation: s / (1 + sqrt(1 - s)), s = r^2 / d^2.
    const float s = r2 / d2;
    one_minus_cos = s / (1.f + std::sqrt(1.f - s));
    return one_minus_cos > 0.f;
}

bool Scene::sample_area_light(const Vec3f& p, float u0, float u1, float u2, LightSample& ls) const {
    if (!light_distribution.valid()) return false;
    float u;
    const int li = pick_light(u0, u);
    const EmissiveTriangle& lt = lights[li];
    if (lt.prim < 0 && meshes[size_t(lt.mesh)].solid_angle) {
        // By solid angle: a direction uniform in the bounding sphere's cone, then the first of
        // the mesh's triangles along it.
        const Mesh& m = meshes[size_t(lt.mesh)];
        Vec3f axis;
        float omc;
        if (!light_cone(m, p, axis, omc)) return false;
        const float cos_t = 1.f - u1 * omc;
        const float sin_t = std::sqrt(std::max(0.f, u1 * omc * (2.f - u1 * omc)));
        const float phi = 2.f * kPi * u2;
        const Vec3f d = Frame(axis).to_world(Vec3f(std::cos(phi) * sin_t, std::sin(phi) * sin_t, cos_t));
        TriangleHit<float> best;
        int64_t prim = -1;
        for (int64_t t = 0; t < m.num_triangles; ++t) {
            if (m.is_degenerate(t)) continue;
            const int32_t* tri = m.indices + 3 * t;
            TriangleHit<float> h;
            if (!intersect_triangle(p, d, m.vertex(tri[0]), m.vertex(tri[1]), m.vertex(tri[2]), h)) continue;
            if (h.b1 < 0.f || h.b2 < 0.f || h.b1 + h.b2 > 1.f || !(h.t > 0.f)) continue;
            if (prim < 0 || h.t < best.t) {
                best = h;
                prim = t;
            }
        }
        if (prim < 0) return false;
        SurfacePoint q = surface_point(lt.mesh, prim, best.b1, best.b2);
        ls.radiance = emitted(q, -d);
        if (is_black(ls.radiance)) return false;
        ls.dir = d;
        ls.dist = best.t;
        ls.hit.mesh = lt.mesh;
        ls.hit.prim = prim;
        ls.hit.b1 = best.b1;
        ls.hit.b2 = best.b2;
        ls.hit.t = best.t;
        ls.p = q.p;
        ls.p_error = q.p_error;
        ls.ng = q.ng;
        ls.pdf = light_distribution.pmf(li) / (2.f * kPi * omc);
        return ls.pdf > 0.f && std::isfinite(ls.pdf);
    }
    const Mesh& lm = meshes[size_t(lt.mesh)];
    if (lt.prim < 0) {
        // A small mesh sampled by spherical triangles: its triangle by the solid angle each
        // shows p (u, now within the mesh's bin, picks it).
        double w[kSphericalPickMax];
        SphericalTriangle tris[kSphericalPickMax];
        const double total = spherical_pick_weights(lm, Vec3d(p), w, tris);
        if (!(total > 0)) return false;
        const double target = double(u) * total;
        double acc = 0;
        int64_t prim = -1;
        for (int64_t t = 0; t < lm.num_triangles; ++t) {
            if (!(w[t] > 0)) continue;
            prim = t;
            acc += w[t];
            if (target < acc) break;
        }
        if (prim < 0) return false;
        return sample_light_triangle(lt.mesh, prim, p, u1, u2, double(light_distribution.pmf(li)) * w[prim] / total, ls,
                                     &tris[prim]);
    }
    return sample_light_triangle(lt.mesh, lt.prim, p, u1, u2, double(light_distribution.pmf(li)), ls);
}

double Scene::spherical_pick_weights(const Mesh& m, const Vec3d& p, double* w, SphericalTriangle* tris) const {
    double total = 0;
    for (int64_t t = 0; t < m.num_triangles; ++t) {
        w[t] = 0;
        tris[t] = SphericalTriangle();
        if (m.is_degenerate(t)) continue;
        const int32_t* tri = m.indices + 3 * t;
        const Vec3d v0(m.vertex(tri[0])), v1(m.vertex(tri[1])), v2(m.vertex(tri[2]));
        const Vec3d n = cross(v1 - v0, v2 - v0);
        // A one-sided emitter lights only the side of its face normal.
        const double side = dot(n, p - v0);
        if (m.two_sided_emission ? side == 0 : !(side > 0)) continue;
        SphericalTriangle& st = tris[t];
        st = SphericalTriangle(p, v0, v1, v2);
        if (st.usable()) {
            w[t] = st.solid_angle;
        } else {
            // Too small or too large to sample by solid angle: its projected area over the
            // squared distance, from the centroid, at most a hemisphere.
            const Vec3d d = (v0 + v1 + v2) / 3.0 - p;
            const double d2 = dot(d, d);
            w[t] = std::min(2.0 * M_PI, 0.5 * std::abs(dot(n, d)) / (d2 * std::sqrt(d2)));
        }
        if (!std::isfinite(w[t])) w[t] = 0;
        total += w[t];
    }
    return total;
}

bool Scene::sample_light_triangle(int mesh, int64_t prim, const Vec3f& p, float u1, float u2, double pmf,
                                  LightSample& ls, const SphericalTriangle* seen) const {
    const Mesh& lm = meshes[size_t(mesh)];
    if (lm.spherical_triangle) {
        const int32_t* tri = lm.indices + 3 * prim;
        const Vec3d v0(lm.vertex(tri[0])), v1(lm.vertex(tri[1])), v2(lm.vertex(tri[2])), pd(p);
        const SphericalTriangle st = seen ? *seen : SphericalTriangle(pd, v0, v1, v2);
        if (st.usable()) {
            // A direction uniform in the triangle's solid angle, then where it meets the
            // triangle (clamped into it against rounding).
            const Vec3d w = st.sample(u1, u2);
            TriangleHit<double> h;
            if (!intersect_triangle(pd, w, v0, v1, v2, h) || !(h.t > 0)) return false;
            double b1 = h.b1, b2 = h.b2;
            clamp_into_triangle(b1, b2);
            SurfacePoint q = surface_point(mesh, prim, float(b1), float(b2));
            const Vec3f d(w);
            ls.radiance = emitted(q, -d);
            if (is_black(ls.radiance)) return false;
            ls.dir = d;
            ls.dist = float(h.t);
            ls.hit.mesh = mesh;
            ls.hit.prim = prim;
            ls.hit.b1 = float(b1);
            ls.hit.b2 = float(b2);
            ls.hit.t = float(h.t);
            ls.p = q.p;
            ls.p_error = q.p_error;
            ls.ng = q.ng;
            ls.pdf = float(pmf / st.solid_angle);
            return ls.pdf > 0.f && std::isfinite(ls.pdf);
        }
    }
    Vec2f b = square_to_triangle(u1, u2);
    SurfacePoint q = surface_point(mesh, prim, b.x, b.y);
    Vec3f d = q.p - p;
    float dist2 = length_squared(d);
    if (!(dist2 > 0.f)) return false;
    float dist = std::sqrt(dist2);
    d = d / dist;
    float cos_l = std::abs(dot(q.ng, d));
    if (!(cos_l > 0.f)) return false;
    ls.radiance = emitted(q, -d);
    if (is_black(ls.radiance)) return false;
    ls.dir = d;
    ls.dist = dist;
    ls.hit.mesh = mesh;
    ls.hit.prim = prim;
    ls.hit.b1 = b.x;
    ls.hit.b2 = b.y;
    ls.hit.t = dist;
    ls.p = q.p;
    ls.p_error = q.p_error;
    ls.ng = q.ng;
    ls.pdf = float(pmf) / light_triangle_area(lm, prim) * dist2 / cos_l;
    return ls.pdf > 0.f && std::isfinite(ls.pdf);
}

float Scene::light_pdf(const Vec3f& p, const SurfacePoint& q) const {
    const Mesh& m = meshes[q.mesh];
    if (m.light_offset < 0 || !light_distribution.valid()) return 0.f;
    if (m.solid_angle) {
        Vec3f axis;
        float omc;
        if (!light_cone(m, p, axis, omc)) return 0.f;
        return light_distribution.pmf(int(m.light_offset)) / (2.f * kPi * omc);
    }
    double pmf;
    SphericalTriangle st;
    if (m.spherical_by_mesh) {
        // The pick sample_area_light makes from the same point.
        double w[kSphericalPickMax];
        SphericalTriangle tris[kSphericalPickMax];
        const double total = spherical_pick_weights(m, Vec3d(p), w, tris);
        if (!(total > 0) || !(w[q.prim] > 0)) return 0.f;
        pmf = double(light_distribution.pmf(int(m.light_offset))) * w[q.prim] / total;
        st = tris[q.prim];
    } else {
        pmf = double(light_distribution.pmf(int(m.light_offset + q.prim)));
        if (m.spherical_triangle) {
            const int32_t* tri = m.indices + 3 * q.prim;
            st = SphericalTriangle(Vec3d(p), Vec3d(m.vertex(tri[0])), Vec3d(m.vertex(tri[1])),
                                   Vec3d(m.vertex(tri[2])));
        }
    }
    // The same choice as sample_light_triangle's, from the same point and corners.
    if (st.usable()) return float(pmf / st.solid_angle);
    Vec3f d = q.p - p;
    float dist2 = length_squared(d);
    float cos_l = std::abs(dot(q.ng, d)) / std::sqrt(dist2);
    if (!(cos_l > 0.f)) return 0.f;
    return float(pmf) / light_triangle_area(m, q.prim) * dist2 / cos_l;
}

}  // namespace edgepath
