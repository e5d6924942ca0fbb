// edgepath._core: the nanobind module. No logic here: it turns plain Python descriptions
// (dicts of numbers and CPU arrays, which python/edgepath builds and validates) into the core's
// SceneDesc as zero-copy views, calls the core, and hands results back as arrays. A SceneCache
// holds a core scene between calls; the core decides what an update rebuilds.
//
// Arrays arrive through DLPack (torch tensors, numpy arrays) and are never converted here:
// a view that is not C-contiguous, on the CPU and of the exact dtype is refused with a
// ValueError naming the field. std::invalid_argument from the core becomes ValueError
// (nanobind's default translation), edgepath::IoError becomes OSError.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <future>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "edgepath.h"
#include "io/image.h"
#include "io/obj.h"
#include "scene/spot.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using FloatView = nb::ndarray<const float, nb::c_contig, nb::device::cpu>;
using IndexView = nb::ndarray<const int32_t, nb::c_contig, nb::device::cpu>;
using ImageOut = nb::ndarray<float, nb::c_contig, nb::device::cpu>;

[[noreturn]] void fail(const std::string& field, const std::string& what) {
    throw std::invalid_argument(field + ": " + what);
}

// Keeps every array view alive (and referenced) while the core uses its memory. Views are
// handles: copying one only adds a reference.
struct Views {
    std::vector<FloatView> floats;
    std::vector<IndexView> indices;
};

nb::handle item(const nb::dict& d, const char* key, const std::string& field) {
    if (!d.contains(key)) fail(field + "." + key, "missing");
    return d[key];
}

bool has(const nb::dict& d, const char* key) { return d.contains(key) && !d[key].is_none(); }

template <typename T>
T scalar(const nb::dict& d, const char* key, const std::string& field) {
    T value;
    if (!nb::try_cast(item(d, key, field), value))
        fail(field + "." + key, "expected a number");
    return value;
}

void vec3(const nb::dict& d, const char* key, const std::string& field, float out[3]) {
    std::vector<float> v;
    if (!nb::try_cast(item(d, key, field), v) || v.size() != 3)
        fail(field + "." + key, "expected a sequence of 3 numbers");
    for (int i = 0; i < 3; ++i) out[i] = v[i];
}

// A float array of `ndim` dimensions whose last dimension is `last` (if > 0).
FloatView float_view(Views& views, nb::handle obj, const std::string& field, size_t ndim,
                     size_t last) {
    FloatView view;
    if (!nb::try_cast(obj, view, false))
        fail(field, "expected a C-contiguous float32 CPU array (use tensor.detach().contiguous())");
    if (view.ndim() != ndim || (last > 0 && view.shape(ndim - 1) != last))
        fail(field, "unexpected array shape with " + std::to_string(view.ndim()) + " dimensions");
    views.floats.push_back(view);
    return view;
}

IndexView index_view(Views& views, nb::handle obj, const std::string& field) {
    IndexView view;
    if (!nb::try_cast(obj, view, false))
        fail(field, "expected a C-contiguous int32 CPU array");
    if (view.ndim() != 2 || view.shape(1) != 3) fail(field, "expected shape (num_triangles, 3)");
    views.indices.push_back(view);
    return view;
}

// (H, W, C) array -> TextureDesc.
edgepath::TextureDesc texture(Views& views, nb::handle obj, const std::string& field) {
    const FloatView v = float_view(views, obj, field, 3, 0);
    edgepath::TextureDesc t;
    t.data = v.data();
    t.height = static_cast<int>(v.shape(0));
    t.width = static_cast<int>(v.shape(1));
    t.channels = static_cast<int>(v.shape(2));
    return t;
}

edgepath::CameraDesc camera_desc(const nb::dict& d) {
    const std::string f = "camera";
    edgepath::CameraDesc c;
    vec3(d, "position", f, c.position);
    vec3(d, "look_at", f, c.look_at);
    vec3(d, "up", f, c.up);
    c.fov = scalar<float>(d, "fov", f);
    c.ortho_scale = scalar<float>(d, "ortho_scale", f);
    c.aperture_radius = scalar<float>(d, "aperture_radius", f);
    c.focus_distance = scalar<float>(d, "focus_distance", f);
    c.type = static_cast<edgepath::CameraType>(scalar<int>(d, "type", f));
    c.height = scalar<int>(d, "height", f);
    c.width = scalar<int>(d, "width", f);
    if (has(d, "crop_window")) {
        std::vector<int> crop;
        if (!nb::try_cast(d["crop_window"], crop) || crop.size() != 4)
            fail("camera.crop_window", "expected (x, y, width, height)");
        c.crop_x = crop[0];
        c.crop_y = crop[1];
        c.crop_width = crop[2];
        c.crop_height = crop[3];
    }
    c.filter = static_cast<edgepath::FilterType>(scalar<int>(d, "filter", f));
    c.filter_stddev = scalar<float>(d, "filter_stddev", f);
    if (has(d, "filter_radius")) c.filter_radius = scalar<float>(d, "filter_radius", f);
    return c;
}

edgepath::MaterialDesc material_desc(Views& views, const nb::dict& d, const std::string& f) {
    edgepath::MaterialDesc m;
    m.diffuse = texture(views, item(d, "diffuse", f), f + ".diffuse");
    m.specular = texture(views, item(d, "specular", f), f + ".specular");
    m.roughness = texture(views, item(d, "roughness", f), f + ".roughness");
    m.two_sided = scalar<bool>(d, "two_sided", f);
    if (has(d, "kind")) m.kind = static_cast<edgepath::MaterialKind>(scalar<int>(d, "kind", f));
    if (has(d, "ior")) m.ior = texture(views, item(d, "ior", f), f + ".ior");
    if (has(d, "nonlinear")) m.nonlinear = scalar<bool>(d, "nonlinear", f);
    if (has(d, "normal_map")) m.normal_map = texture(views, d["normal_map"], f + ".normal_map");
    return m;
}

// `n` numbers from the list d[key] into out.
void floats(const nb::dict& d, const char* key, const std::string& f, float* out, size_t n) {
    std::vector<float> v;
    if (!nb::try_cast(item(d, key, f), v) || v.size() != n)
        fail(f + "." + key, "expected " + std::to_string(n) + " numbers");
    std::copy(v.begin(), v.end(), out);
}

edgepath::MeshDesc mesh_desc(Views& views, const nb::dict& d, const std::string& f) {
    edgepath::MeshDesc m;
    const FloatView vertices = float_view(views, item(d, "vertices", f), f + ".vertices", 2, 3);
    m.vertices = vertices.data();
    m.num_vertices = static_cast<int64_t>(vertices.shape(0));
    const IndexView indices = index_view(views, item(d, "indices", f), f + ".indices");
    m.indices = indices.data();
    m.num_triangles = static_cast<int64_t>(indices.shape(0));
    if (has(d, "uvs")) {
        const FloatView uvs = float_view(views, d["uvs"], f + ".uvs", 2, 2);
        m.uvs = uvs.data();
        m.num_uvs = static_cast<int64_t>(uvs.shape(0));
    }
    if (has(d, "uv_indices")) {
        const IndexView uv_indices = index_view(views, d["uv_indices"], f + ".uv_indices");
        if (uv_indices.shape(0) != indices.shape(0))
            fail(f + ".uv_indices", "must have as many rows as indices");
        m.uv_indices = uv_indices.data();
    }
    if (has(d, "normals")) {
        const FloatView normals = float_view(views, d["normals"], f + ".normals", 2, 3);
        m.normals = normals.data();
        m.num_normals = static_cast<int64_t>(normals.shape(0));
    }
    if (has(d, "normal_indices")) {
        const IndexView normal_indices =
            index_view(views, d["normal_indices"], f + ".normal_indices");
        if (normal_indices.shape(0) != indices.shape(0))
            fail(f + ".normal_indices", "must have as many rows as indices");
        m.normal_indices = normal_indices.data();
    }
    if (has(d, "colors")) {
        const FloatView colors = float_view(views, d["colors"], f + ".colors", 2, 3);
        if (int64_t(colors.shape(0)) != m.num_vertices)
            fail(f + ".colors", "has " + std::to_string(colors.shape(0)) + " rows but there are " +
                                    std::to_string(m.num_vertices) + " vertices");
        m.colors = colors.data();
    }
    m.material = scalar<int>(d, "material", f);
    if (has(d, "emission")) m.emission = texture(views, d["emission"], f + ".emission");
    m.two_sided_emission = scalar<bool>(d, "two_sided_emission", f);
    if (has(d, "spot_profile")) {
        m.spot = true;
        floats(d, "spot_profile", f, m.spot_profile, edgepath::kSpotParams);
    }
    if (has(d, "sample_solid_angle")) m.sample_solid_angle = scalar<bool>(d, "sample_solid_angle", f);
    if (has(d, "sample_spherical_triangle"))
        m.sample_spherical_triangle = scalar<bool>(d, "sample_spherical_triangle", f);
    if (has(d, "moves")) m.moves = scalar<bool>(d, "moves", f);
    return m;
}

edgepath::PointLightDesc point_light_desc(const nb::dict& d, const std::string& f) {
    edgepath::PointLightDesc l;
    floats(d, "position", f, l.position, 3);
    floats(d, "intensity", f, l.intensity, 3);
    if (has(d, "spot_profile")) {
        l.spot = true;
        floats(d, "spot_profile", f, l.spot_profile, edgepath::kSpotParams);
    }
    return l;
}

edgepath::EnvmapDesc envmap_desc(Views& views, const nb::dict& d) {
    edgepath::EnvmapDesc e;
    e.values = texture(views, item(d, "values", "envmap"), "envmap.values");
    std::vector<float> to_world;
    if (!nb::try_cast(item(d, "to_world", "envmap"), to_world) || to_world.size() != 9)
        fail("envmap.to_world", "expected 9 numbers (a row-major 3x3 rotation)");
    for (int i = 0; i < 9; ++i) e.to_world[i] = to_world[i];
    e.scale = scalar<float>(d, "scale", "envmap");
    return e;
}

// A described scene: the SceneDesc and the array views it points into.
struct Described {
    Views views;
    edgepath::SceneDesc desc;
};

void describe(Described& out, const nb::dict& camera, const nb::list& materials,
              const nb::list& meshes, const nb::object& envmap, const nb::list& point_lights) {
    out.desc.camera = camera_desc(camera);
    for (size_t i = 0; i < materials.size(); ++i)
        out.desc.materials.push_back(material_desc(out.views, nb::cast<nb::dict>(materials[i]),
                                                   "materials[" + std::to_string(i) + "]"));
    for (size_t i = 0; i < meshes.size(); ++i)
        out.desc.meshes.push_back(mesh_desc(out.views, nb::cast<nb::dict>(meshes[i]),
                                            "meshes[" + std::to_string(i) + "]"));
    if (!envmap.is_none()) {
        out.desc.has_envmap = true;
        out.desc.envmap = envmap_desc(out.views, nb::cast<nb::dict>(envmap));
    }
    for (size_t i = 0; i < point_lights.size(); ++i)
        out.desc.point_lights.push_back(
            point_light_desc(nb::cast<nb::dict>(point_lights[i]), "point_lights[" + std::to_string(i) + "]"));
}

edgepath::RenderOptions render_options(const nb::dict& d) {
    const std::string f = "options";
    edgepath::RenderOptions o;
    o.spp = scalar<int>(d, "spp", f);
    o.max_bounces = scalar<int>(d, "max_bounces", f);
    o.seed = scalar<uint64_t>(d, "seed", f);
    o.num_threads = scalar<int>(d, "num_threads", f);
    o.sampling = static_cast<edgepath::LightSampling>(scalar<int>(d, "sampling", f));
    o.primary_edges = scalar<bool>(d, "primary_edges", f);
    o.secondary_edges = scalar<bool>(d, "secondary_edges", f);
    if (has(d, "hide_emitters")) o.hide_emitters = scalar<bool>(d, "hide_emitters", f);
    if (has(d, "replayable")) o.replayable = scalar<bool>(d, "replayable", f);
    if (has(d, "secondary_survival")) o.secondary_survival = scalar<float>(d, "secondary_survival", f);
    o.edge_samples = scalar<int64_t>(d, "edge_samples", f);
    o.edge_sampling = static_cast<edgepath::EdgeSampling>(scalar<int>(d, "edge_sampling", f));
    return o;
}

// How often the calling thread looks for signals while the core works.
constexpr std::chrono::milliseconds kSignalPoll(20);

// Runs `call` (a core call taking `opt`) on a thread of its own, the GIL released, while this
// thread checks for signals every kSignalPoll: a signal handler that raises (Ctrl-C's
// KeyboardInterrupt) cancels the core call (RenderOptions::cancel), which stops within a
// sample; once it has, the Python exception propagates. The core's own exceptions propagate as
// usual.
template <class Call>
auto interruptible(edgepath::RenderOptions& opt, Call&& call) -> decltype(call()) {
    std::atomic<bool> cancel{false};
    opt.cancel = &cancel;
    std::packaged_task<decltype(call())()> task(std::forward<Call>(call));
    auto result = task.get_future();
    bool interrupted = false;
    {
        nb::gil_scoped_release release;
        std::thread worker(std::move(task));
        while (result.wait_for(kSignalPoll) != std::future_status::ready) {
            nb::gil_scoped_acquire acquire;
            if (PyErr_CheckSignals() != 0) {
                interrupted = true;
                cancel = true;
                break;
            }
        }
        worker.join();
    }
    opt.cancel = nullptr;
    if (interrupted) throw nb::python_error();  // the handler's exception, still pending
    return result.get();
}

// A core scene kept across calls (Python: Scene._core_cache): each call updates it from the
// call's description, which rebuilds only what changed (edgepath::update_scene).
struct SceneCache {
    std::mutex mutex;
    std::shared_ptr<edgepath::Scene> scene;
};

// One of the kept scene's counts (scene_build_counts, scene_hierarchy_counts; zeros before its
// first build) as a dict of builds, refits and reuses. Waits for a call that holds the scene.
nb::dict cache_counts(SceneCache& c, edgepath::SceneBuildCounts (*count)(const edgepath::Scene&)) {
    edgepath::SceneBuildCounts n;
    {
        nb::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(c.mutex);
        if (c.scene) n = count(*c.scene);
    }
    nb::dict d;
    d["builds"] = n.builds;
    d["refits"] = n.refits;
    d["reuses"] = n.reuses;
    return d;
}

// The built scene one call uses: the cache's, updated and held (locked) for the call, or a
// scene of its own when there is no cache or another thread holds it.
struct CallScene {
    std::unique_lock<std::mutex> lock;
    std::shared_ptr<edgepath::Scene> scene;
    edgepath::Scene& operator*() const { return *scene; }
};

// Builds or updates the scene (GIL released) and warns, once per mesh and count, about the
// degenerate triangles it skips.
CallScene build(const edgepath::SceneDesc& desc, SceneCache* cache) {
    CallScene c;
    {
        nb::gil_scoped_release release;
        if (cache) c.lock = std::unique_lock<std::mutex>(cache->mutex, std::try_to_lock);
        if (c.lock.owns_lock() && cache->scene) {
            try {
                edgepath::update_scene(*cache->scene, desc);
            } catch (...) {
                cache->scene.reset();  // half updated: built afresh next time
                throw;
            }
            c.scene = cache->scene;
        } else {
            c.scene = edgepath::build_scene(desc);
            if (c.lock.owns_lock()) cache->scene = c.scene;
        }
    }
    for (size_t i = 0; i < desc.meshes.size(); ++i) {
        const int64_t n = edgepath::degenerate_triangles(*c.scene, int(i));
        if (n > 0 && PyErr_WarnFormat(PyExc_RuntimeWarning, 1,
                                      "meshes[%zu]: %lld of %lld triangles are degenerate (zero area) and are "
                                      "skipped: they render as nothing and get zero gradients",
                                      i, (long long)n, (long long)desc.meshes[i].num_triangles) != 0)
            throw nb::python_error();
    }
    return c;
}

// An (H, W, 3) float32 image buffer of the size the scene renders.
ImageOut image_buffer(nb::handle obj, const edgepath::Scene& scene, const std::string& field) {
    ImageOut out;
    if (!nb::try_cast(obj, out, false) || out.ndim() != 3 || out.shape(2) != 3)
        fail(field, "expected a C-contiguous float32 CPU array of shape (H, W, 3)");
    const size_t height = edgepath::image_height(scene), width = edgepath::image_width(scene);
    if (out.shape(0) != height || out.shape(1) != width)
        fail(field, "has shape (" + std::to_string(out.shape(0)) + ", " +
                        std::to_string(out.shape(1)) + ", 3) but the camera renders (" +
                        std::to_string(height) + ", " + std::to_string(width) + ", 3)");
    return out;
}

nb::dict stats_dict(const edgepath::RenderStats& stats) {
    nb::dict result;
    result["camera_rays"] = stats.camera_rays;
    result["shadow_rays"] = stats.shadow_rays;
    result["bounce_rays"] = stats.bounce_rays;
    return result;
}

nb::dict render(const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                nb::object envmap, nb::handle image, const nb::dict& options, SceneCache* cache,
                 const nb::list& point_lights) {
    Described d;
    describe(d, camera, materials, meshes, envmap, point_lights);
    edgepath::RenderOptions opt = render_options(options);
    const CallScene scene = build(d.desc, cache);
    const ImageOut out = image_buffer(image, *scene, "image");
    return stats_dict(interruptible(opt, [&] { return edgepath::render(*scene, opt, out.data()); }));
}

// ---- many views ------------------------------------------------------------------------------
// One scene (built or updated once) seen by several cameras of one film size: `cameras` is a
// list of camera dicts; view k renders with cameras[k] and the options of the call.
std::vector<edgepath::CameraDesc> camera_descs(const nb::list& cameras) {
    if (cameras.size() == 0) fail("cameras", "no view");
    std::vector<edgepath::CameraDesc> out;
    for (size_t k = 0; k < cameras.size(); ++k) out.push_back(camera_desc(nb::cast<nb::dict>(cameras[k])));
    return out;
}

// (V, H, W, C) float32 buffer: V views of the size the scene renders.
template <class View>
View views_buffer(nb::handle obj, const edgepath::Scene& scene, size_t views, size_t channels,
                  const std::string& field, const char* what) {
    View out;
    const size_t height = edgepath::image_height(scene), width = edgepath::image_width(scene);
    if (!nb::try_cast(obj, out, false) || out.ndim() != 4 || out.shape(0) != views || out.shape(1) != height ||
        out.shape(2) != width || out.shape(3) != channels)
        fail(field, std::string("expected ") + what + " C-contiguous float32 CPU array of shape (" +
                        std::to_string(views) + ", " + std::to_string(height) + ", " + std::to_string(width) +
                        ", " + std::to_string(channels) + ")");
    return out;
}

// The core names a camera's fields "camera.<field>": view k's are "cameras[k].<field>".
[[noreturn]] void rethrow_for_view(const std::invalid_argument& e, size_t k) {
    const std::string what = e.what();
    if (what.rfind("camera", 0) != 0) throw;
    throw std::invalid_argument("cameras[" + std::to_string(k) + "]" + what.substr(6));
}

// The scene for a call over `views`, seen by views[0], every view's camera validated.
CallScene build_views(const edgepath::SceneDesc& desc, const std::vector<edgepath::CameraDesc>& views,
                      SceneCache* cache) {
    CallScene scene;
    try {
        scene = build(desc, cache);
    } catch (const std::invalid_argument& e) {
        rethrow_for_view(e, 0);
    }
    for (size_t k = 1; k < views.size(); ++k) try {
            edgepath::set_scene_camera(*scene, views[k]);
        } catch (const std::invalid_argument& e) {
            rethrow_for_view(e, k);
        }
    return scene;
}

// The views' own seeds (options "view_seeds": one per view), or none: every view takes the
// options' seed.
std::vector<uint64_t> view_seeds(const nb::dict& options, size_t views) {
    std::vector<uint64_t> seeds;
    if (!has(options, "view_seeds")) return seeds;
    if (!nb::try_cast(options["view_seeds"], seeds) || seeds.size() != views)
        fail("options.view_seeds", "expected one seed (a non-negative integer) per view, " + std::to_string(views) +
                                       " in all");
    return seeds;
}

// Renders view k into images[k]; the counters are summed over the views.
nb::dict render_views(const nb::list& cameras, const nb::list& materials, const nb::list& meshes,
                      nb::object envmap, nb::handle images, const nb::dict& options, SceneCache* cache,
                 const nb::list& point_lights) {
    const std::vector<edgepath::CameraDesc> views = camera_descs(cameras);
    Described d;
    describe(d, nb::cast<nb::dict>(cameras[0]), materials, meshes, envmap, point_lights);
    edgepath::RenderOptions opt = render_options(options);
    const std::vector<uint64_t> seeds = view_seeds(options, views.size());
    const CallScene scene = build_views(d.desc, views, cache);
    const ImageOut out = views_buffer<ImageOut>(images, *scene, views.size(), 3, "images", "a");
    const size_t pixels = out.size() / views.size();
    const edgepath::RenderStats stats = interruptible(opt, [&] {
        edgepath::RenderStats sum;
        for (size_t k = 0; k < views.size(); ++k) {
            edgepath::set_scene_camera(*scene, views[k]);
            if (!seeds.empty()) opt.seed = seeds[k];
            const edgepath::RenderStats s = edgepath::render(*scene, opt, out.data() + k * pixels);
            sum.camera_rays += s.camera_rays;
            sum.shadow_rays += s.shadow_rays;
            sum.bounce_rays += s.bounce_rays;
        }
        return sum;
    });
    return stats_dict(stats);
}

// ---- gradient slots --------------------------------------------------------------------------
// `slots` mirrors the scene: {"camera": a, "envmap": a, "envmap_rotation": a,
// "meshes": [{"vertices": a, "uvs": a, "normals": a, "emission": a, "colors": a, "spot_profile": a} or
// None, ...],
// "materials": [{"diffuse": a, "specular": a, "roughness": a, "ior": a, "normal_map": a} or None, ...],
// "point_lights": [{"position": a, "intensity": a, "spot_profile": a} or None, ...]}, any entry None or
// absent. Reverse mode: writable buffers the gradients are added into; forward mode: directions.
// Each array must have exactly as many values as the parameter it stands for.
using GradOut = nb::ndarray<float, nb::c_contig, nb::device::cpu>;

template <class View>
const View& checked(nb::handle obj, int64_t size, const std::string& name, const char* what,
                    std::vector<View>& keep) {
    View v;
    if (!nb::try_cast(obj, v, false))
        fail(name, std::string("expected ") + what + " C-contiguous float32 CPU array");
    if (int64_t(v.size()) != size)
        fail(name, "has " + std::to_string(v.size()) + " values, the parameter " + std::to_string(size));
    keep.push_back(v);
    return keep.back();
}

struct SlotViews {
    bool reverse;
    std::vector<GradOut> outs;
    std::vector<FloatView> dirs;

    edgepath::GradSlot slot(const nb::dict& d, const char* key, int64_t size, const std::string& field) {
        edgepath::GradSlot s;
        if (!has(d, key)) return s;
        const std::string name = field + "." + key;
        if (size == 0) fail(name, "the scene has no such parameter");
        nb::handle obj = d[key];
        if (reverse)
            s.grad = checked(obj, size, name, "a writable", outs).data();
        else
            s.dir = checked(obj, size, name, "a", dirs).data();
        return s;
    }
};

edgepath::SceneGradients gradient_slots(SlotViews& views, const nb::dict& d, const edgepath::SceneDesc& desc) {
    edgepath::SceneGradients g;
    g.camera = views.slot(d, "camera", edgepath::kCameraParams, "gradients");
    g.envmap = views.slot(d, "envmap", desc.has_envmap ? desc.envmap.values.num_values() : 0, "gradients");
    g.envmap_rotation = views.slot(d, "envmap_rotation", desc.has_envmap ? 9 : 0, "gradients");
    if (has(d, "meshes")) {
        nb::list meshes = nb::cast<nb::list>(d["meshes"]);
        if (meshes.size() != desc.meshes.size()) fail("gradients.meshes", "must have one entry per mesh");
        g.meshes.resize(meshes.size());
        for (size_t i = 0; i < meshes.size(); ++i) {
            if (meshes[i].is_none()) continue;
            const nb::dict m = nb::cast<nb::dict>(meshes[i]);
            const edgepath::MeshDesc& md = desc.meshes[i];
            const std::string f = "gradients.meshes[" + std::to_string(i) + "]";
            g.meshes[i].vertices = views.slot(m, "vertices", md.num_vertices * 3, f);
            g.meshes[i].uvs = views.slot(m, "uvs", md.uvs ? md.num_uvs * 2 : 0, f);
            g.meshes[i].normals = views.slot(m, "normals", md.normals ? md.num_normals * 3 : 0, f);
            g.meshes[i].emission = views.slot(m, "emission", md.emission.num_values(), f);
            g.meshes[i].colors = views.slot(m, "colors", md.colors ? md.num_vertices * 3 : 0, f);
            g.meshes[i].spot = views.slot(m, "spot_profile", md.spot ? edgepath::kSpotParams : 0, f);
        }
    }
    if (has(d, "point_lights")) {
        nb::list lights = nb::cast<nb::list>(d["point_lights"]);
        if (lights.size() != desc.point_lights.size())
            fail("gradients.point_lights", "must have one entry per point light");
        g.point_lights.resize(lights.size());
        for (size_t i = 0; i < lights.size(); ++i) {
            if (lights[i].is_none()) continue;
            const nb::dict l = nb::cast<nb::dict>(lights[i]);
            const std::string f = "gradients.point_lights[" + std::to_string(i) + "]";
            g.point_lights[i].position = views.slot(l, "position", 3, f);
            g.point_lights[i].intensity = views.slot(l, "intensity", 3, f);
            g.point_lights[i].spot = views.slot(l, "spot_profile", desc.point_lights[i].spot ? edgepath::kSpotParams : 0, f);
        }
    }
    if (has(d, "materials")) {
        nb::list materials = nb::cast<nb::list>(d["materials"]);
        if (materials.size() != desc.materials.size())
            fail("gradients.materials", "must have one entry per material");
        g.materials.resize(materials.size());
        for (size_t i = 0; i < materials.size(); ++i) {
            if (materials[i].is_none()) continue;
            const nb::dict m = nb::cast<nb::dict>(materials[i]);
            const edgepath::MaterialDesc& md = desc.materials[i];
            const std::string f = "gradients.materials[" + std::to_string(i) + "]";
            g.materials[i].diffuse = views.slot(m, "diffuse", md.diffuse.num_values(), f);
            g.materials[i].specular = views.slot(m, "specular", md.specular.num_values(), f);
            g.materials[i].roughness = views.slot(m, "roughness", md.roughness.num_values(), f);
            g.materials[i].ior = views.slot(m, "ior", md.ior.num_values(), f);
            g.materials[i].normal_map = views.slot(m, "normal_map", md.normal_map.num_values(), f);
        }
    }
    return g;
}

edgepath::ChannelLayout channel_layout(const std::vector<std::string>& names);  // below

// What the gradient entry points share, in this order: the scene description, the options, the
// channel layout (given `channels`; else radiance), the slots (reverse mode: gradient buffers,
// forward mode: directions), then the built scene. Not copyable: the slots point into the views.
struct GradientCall {
    Described d;
    edgepath::RenderOptions opt;
    edgepath::ChannelLayout layout = edgepath::ChannelLayout::radiance();
    SlotViews views;
    edgepath::SceneGradients slots;
    CallScene scene;

    GradientCall(bool reverse, const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                 nb::object envmap, const nb::dict& options, const std::vector<std::string>* channels,
                 const nb::dict& slot_dict, SceneCache* cache,
                 const nb::list& point_lights)
        : views{reverse, {}, {}} {
        describe(d, camera, materials, meshes, envmap, point_lights);
        opt = render_options(options);
        if (channels) layout = channel_layout(*channels);
        slots = gradient_slots(views, slot_dict, d.desc);
        edgepath::number_slots(slots);
        scene = build(d.desc, cache);
    }
    GradientCall(const GradientCall&) = delete;
    GradientCall& operator=(const GradientCall&) = delete;

    // The adjoint: (H, W, values per pixel) float32, as the scene renders.
    FloatView adjoint(nb::handle obj, const char* like) const {
        FloatView a;
        if (!nb::try_cast(obj, a, false) || a.ndim() != 3 || a.shape(2) != size_t(layout.num_values) ||
            a.shape(0) != size_t(edgepath::image_height(*scene)) ||
            a.shape(1) != size_t(edgepath::image_width(*scene)))
            fail("adjoint", std::string("expected a C-contiguous float32 CPU array shaped like ") + like);
        return a;
    }
};

void render_gradients(const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                      nb::object envmap, nb::handle adjoint, const nb::dict& grads, const nb::dict& options,
                      SceneCache* cache,
                 const nb::list& point_lights) {
    GradientCall c(true, camera, materials, meshes, envmap, options, nullptr, grads, cache, point_lights);
    const FloatView a = c.adjoint(adjoint, "the image");
    interruptible(c.opt, [&] { edgepath::render_gradients(*c.scene, c.opt, a.data(), c.slots); });
}

// The gradient pass of render_views: `adjoints` (V, H, W, 3); the scene's gradients (`grads`,
// without "camera") summed over the views into one set of buffers, view k's camera gradient
// into camera_grads[k] (None: not wanted).
void render_views_gradients(const nb::list& cameras, const nb::list& materials, const nb::list& meshes,
                            nb::object envmap, nb::handle adjoints, const nb::dict& grads,
                            const nb::list& camera_grads, const nb::dict& options, SceneCache* cache,
                 const nb::list& point_lights) {
    const std::vector<edgepath::CameraDesc> views = camera_descs(cameras);
    if (grads.contains("camera")) fail("gradients.camera", "give the cameras' gradients in camera_grads");
    if (camera_grads.size() != views.size()) fail("camera_grads", "must have one entry per view");
    GradientCall c(true, nb::cast<nb::dict>(cameras[0]), materials, meshes, envmap, options, nullptr, grads, cache, point_lights);
    const std::vector<uint64_t> seeds = view_seeds(options, views.size());
    std::vector<edgepath::GradSlot> camera_slots;
    for (size_t k = 0; k < views.size(); ++k) {
        nb::dict one;
        if (!camera_grads[k].is_none()) one["camera"] = camera_grads[k];
        camera_slots.push_back(c.views.slot(one, "camera", edgepath::kCameraParams,
                                            "camera_grads[" + std::to_string(k) + "]"));
        camera_slots.back().key = c.slots.camera.key;
    }
    const FloatView a = views_buffer<FloatView>(adjoints, *c.scene, views.size(), 3, "adjoint", "a");
    const size_t pixels = a.size() / views.size();
    interruptible(c.opt, [&] {
        for (size_t k = 0; k < views.size(); ++k) {
            edgepath::set_scene_camera(*c.scene, views[k]);
            c.slots.camera = camera_slots[k];
            if (!seeds.empty()) c.opt.seed = seeds[k];
            edgepath::render_gradients(*c.scene, c.opt, a.data() + k * pixels, c.slots);
        }
    });
}

void derivative_image(const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                      nb::object envmap, const nb::dict& directions, nb::handle image, const nb::dict& options,
                      SceneCache* cache,
                 const nb::list& point_lights) {
    GradientCall c(false, camera, materials, meshes, envmap, options, nullptr, directions, cache, point_lights);
    const ImageOut out = image_buffer(image, *c.scene, "image");
    interruptible(c.opt, [&] { edgepath::derivative_image(*c.scene, c.opt, c.slots, out.data()); });
}

// ---- output channels -------------------------------------------------------------------------
// `channels`: a list of channel names (render/channels.h); the float image holds the continuous
// ones in that order, the int32 image the ids.
using IdsOut = nb::ndarray<int32_t, nb::c_contig, nb::device::cpu>;

edgepath::ChannelLayout channel_layout(const std::vector<std::string>& names) {
    std::vector<edgepath::Channel> list;
    for (size_t i = 0; i < names.size(); ++i)
        list.push_back(edgepath::channel_from_name(names[i], "channels[" + std::to_string(i) + "]"));
    return edgepath::ChannelLayout(list);
}

// An (H, W, C) buffer of the size the scene renders.
template <class Out>
Out channel_buffer(nb::handle obj, const edgepath::Scene& scene, int channels, const std::string& field,
                   const char* dtype) {
    Out out;
    const size_t height = edgepath::image_height(scene), width = edgepath::image_width(scene);
    if (!nb::try_cast(obj, out, false) || out.ndim() != 3 || out.shape(0) != height ||
        out.shape(1) != width || out.shape(2) != size_t(channels))
        fail(field, std::string("expected a C-contiguous ") + dtype + " CPU array of shape (" +
                        std::to_string(height) + ", " + std::to_string(width) + ", " +
                        std::to_string(channels) + ")");
    return out;
}

nb::dict render_channels(const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                         nb::object envmap, const std::vector<std::string>& channels, nb::handle values,
                         nb::handle ids, const nb::dict& options, SceneCache* cache,
                 const nb::list& point_lights) {
    Described d;
    describe(d, camera, materials, meshes, envmap, point_lights);
    edgepath::RenderOptions opt = render_options(options);
    const edgepath::ChannelLayout layout = channel_layout(channels);
    const CallScene scene = build(d.desc, cache);
    const ImageOut v = channel_buffer<ImageOut>(values, *scene, layout.num_values, "values", "float32");
    const IdsOut i = channel_buffer<IdsOut>(ids, *scene, layout.num_ids, "ids", "int32");
    return stats_dict(
        interruptible(opt, [&] { return edgepath::render_channels(*scene, opt, layout, v.data(), i.data()); }));
}

void channel_gradients(const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                       nb::object envmap, const std::vector<std::string>& channels, nb::handle adjoint,
                       const nb::dict& grads, const nb::dict& options, SceneCache* cache,
                 const nb::list& point_lights) {
    GradientCall c(true, camera, materials, meshes, envmap, options, &channels, grads, cache, point_lights);
    const FloatView a = c.adjoint(adjoint, "the channels' values");
    interruptible(c.opt, [&] { edgepath::channel_gradients(*c.scene, c.opt, c.layout, a.data(), c.slots); });
}

void channel_derivative_image(const nb::dict& camera, const nb::list& materials, const nb::list& meshes,
                              nb::object envmap, const std::vector<std::string>& channels,
                              const nb::dict& directions, nb::handle values, const nb::dict& options,
                              SceneCache* cache,
                 const nb::list& point_lights) {
    GradientCall c(false, camera, materials, meshes, envmap, options, &channels, directions, cache, point_lights);
    const ImageOut out = channel_buffer<ImageOut>(values, *c.scene, c.layout.num_values, "values", "float32");
    interruptible(c.opt, [&] { edgepath::channel_derivative_image(*c.scene, c.opt, c.layout, c.slots, out.data()); });
}

// Moves `values` into a numpy array of the given shape (owned by a capsule).
template <typename T>
nb::object to_numpy(std::vector<T>&& values, std::initializer_list<size_t> shape) {
    auto* storage = new std::vector<T>(std::move(values));
    nb::capsule owner(storage, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    return nb::cast(nb::ndarray<nb::numpy, T>(storage->data(), shape, owner));
}

template <typename T>
nb::object to_numpy_or_none(std::vector<T>&& values, size_t columns) {
    if (values.empty()) return nb::none();
    const size_t rows = values.size() / columns;
    return to_numpy(std::move(values), {rows, columns});
}

nb::object imread(const std::string& path) {
    edgepath::Image image;
    {
        nb::gil_scoped_release release;
        image = edgepath::read_image(path);
    }
    return to_numpy(std::move(image.pixels), {size_t(image.height), size_t(image.width),
                                              size_t(image.channels)});
}

void imwrite(const std::string& path, nb::handle array) {
    FloatView view;
    if (!nb::try_cast(array, view, false) || (view.ndim() != 2 && view.ndim() != 3))
        fail("image", "expected a C-contiguous float32 CPU array of shape (H, W) or (H, W, C)");
    const int channels = view.ndim() == 3 ? static_cast<int>(view.shape(2)) : 1;
    nb::gil_scoped_release release;
    edgepath::write_image(path, view.data(), static_cast<int>(view.shape(0)),
                          static_cast<int>(view.shape(1)), channels);
}

nb::list load_obj(const std::string& path) {
    std::vector<edgepath::ObjMesh> meshes;
    {
        nb::gil_scoped_release release;
        meshes = edgepath::load_obj(path);
    }
    nb::list result;
    for (edgepath::ObjMesh& m : meshes) {
        const edgepath::ObjMaterial& mat = m.material;
        nb::dict material;
        material["name"] = mat.name;
        material["defined"] = mat.defined;
        material["diffuse"] = std::vector<float>(mat.diffuse, mat.diffuse + 3);
        material["specular"] = std::vector<float>(mat.specular, mat.specular + 3);
        material["emission"] = std::vector<float>(mat.emission, mat.emission + 3);
        material["roughness"] = mat.roughness;
        material["diffuse_texture"] = mat.diffuse_texture;
        nb::dict mesh;
        mesh["positions"] = to_numpy_or_none(std::move(m.positions), 3);
        mesh["indices"] = to_numpy_or_none(std::move(m.indices), 3);
        mesh["uvs"] = to_numpy_or_none(std::move(m.uvs), 2);
        mesh["uv_indices"] = to_numpy_or_none(std::move(m.uv_indices), 3);
        mesh["normals"] = to_numpy_or_none(std::move(m.normals), 3);
        mesh["normal_indices"] = to_numpy_or_none(std::move(m.normal_indices), 3);
        mesh["material"] = material;
        result.append(mesh);
    }
    return result;
}

}  // namespace

NB_MODULE(_core, m) {
    m.doc() = "edgepath core bindings (internal; use the edgepath package)";
    // Scenes still alive when the interpreter exits (a module-level scene, an autograd graph in
    // a reference cycle) hold SceneCache instances; nanobind would report them as leaks.
    nb::set_leak_warnings(false);

    nb::register_exception_translator([](const std::exception_ptr& p, void*) {
        try {
            std::rethrow_exception(p);
        } catch (const edgepath::IoError& e) {
            // Messages quote bytes from files: bytes that are not UTF-8 are escaped, not a
            // UnicodeDecodeError in place of the error.
            const std::string_view text = e.what();
            PyObject* message = PyUnicode_DecodeUTF8(text.data(), static_cast<Py_ssize_t>(text.size()),
                                                     "backslashreplace");
            if (message) {
                PyErr_SetObject(PyExc_OSError, message);
                Py_DECREF(message);
            }
        }
    });

    nb::class_<SceneCache>(m, "SceneCache",
                           "A core scene kept across calls: pass it as `cache` to the render and "
                           "gradient functions, which update it from their description.")
        .def(nb::init<>())
        .def(
            "counts", [](SceneCache& c) { return cache_counts(c, edgepath::scene_build_counts); },
            "How often the kept scene was built, refitted and reused (zeros before its first "
            "build; a failed update drops it and starts the counts again).")
        .def(
            "hierarchy_counts", [](SceneCache& c) { return cache_counts(c, edgepath::scene_hierarchy_counts); },
            "How often gradient passes on the kept scene built, refitted and reused its edge "
            "hierarchy (zeros before the first, and after a failed update).");

    m.def("render", &render, "camera"_a, "materials"_a, "meshes"_a, "envmap"_a.none(),
          "image"_a, "options"_a, "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Renders the described scene into `image` (H, W, 3) float32, in place. Returns the "
          "render counters as a dict.");
    m.def("render_views", &render_views, "cameras"_a, "materials"_a, "meshes"_a,
          "envmap"_a.none(), "images"_a, "options"_a, "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Renders the scene once per camera into `images` (V, H, W, 3) float32, in place; one "
          "scene build; options[\"view_seeds\"] (optional): a seed per view, instead of "
          "options[\"seed\"] for all. Returns the render counters summed over the views.");
    m.def("render_gradients", &render_gradients, "camera"_a, "materials"_a, "meshes"_a,
          "envmap"_a.none(), "adjoint"_a, "gradients"_a, "options"_a, "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Adds d(sum(adjoint * image))/d(parameter) into the buffers of `gradients`.");
    m.def("render_views_gradients", &render_views_gradients, "cameras"_a, "materials"_a,
          "meshes"_a, "envmap"_a.none(), "adjoint"_a, "gradients"_a, "camera_grads"_a,
          "options"_a, "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "render_gradients over the views of render_views: the scene's gradients summed over "
          "the views, view k's camera gradient into camera_grads[k].");
    m.def("derivative_image", &derivative_image, "camera"_a, "materials"_a, "meshes"_a,
          "envmap"_a.none(), "directions"_a, "image"_a, "options"_a, "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Writes the derivative of the image along `directions` into `image` (H, W, 3).");
    m.def("render_channels", &render_channels, "camera"_a, "materials"_a, "meshes"_a,
          "envmap"_a.none(), "channels"_a, "values"_a, "ids"_a, "options"_a,
          "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Renders the named channels: the continuous ones into `values` (H, W, C) float32, the "
          "ids into `ids` (H, W, K) int32, in place. Returns the render counters as a dict.");
    m.def("channel_gradients", &channel_gradients, "camera"_a, "materials"_a, "meshes"_a,
          "envmap"_a.none(), "channels"_a, "adjoint"_a, "gradients"_a, "options"_a,
          "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Adds d(sum(adjoint * values))/d(parameter) into the buffers of `gradients`.");
    m.def("channel_derivative_image", &channel_derivative_image, "camera"_a, "materials"_a,
          "meshes"_a, "envmap"_a.none(), "channels"_a, "directions"_a, "values"_a, "options"_a,
          "cache"_a.none() = nb::none(), "point_lights"_a = nb::list(),
          "Writes the derivative of the channels' values along `directions` into `values`.");
    m.def("imread", &imread, "path"_a,
          "Reads a PNG/JPEG (linearised) or EXR file as a float32 (H, W, C) numpy array.");
    m.def("imwrite", &imwrite, "path"_a, "image"_a,
          "Writes a float32 (H, W) or (H, W, C) array as PNG (sRGB, 8-bit) or EXR (linear).");
    m.def("load_obj", &load_obj, "path"_a,
          "Loads an OBJ file as a list of per-material meshes (dicts of numpy arrays).");
}
