// Forward-rendering benchmark. Builds a procedural scene of about 114k triangles (a glossy
// teapot, glossy and diffuse spheres, boxes on a textured floor, a rectangular area light and a
// procedural sky), renders it at a few bounce counts and thread counts, and compares the
// renderer's time with the time Embree alone takes to trace the same numbers of rays of the same
// kinds. The ratio "Embree only / renderer" says how close the renderer is to being bound by ray
// traversal; the goal is at least 0.5.
//
// The Embree-only rays are generated before timing: camera rays exactly as the renderer makes
// them (same film samples, same tile order); shadow rays from the camera rays' hit points to
// emitter samples (Scene::sample_area_light or sample_env) on the visible side of the surface;
// bounce rays from the same hit points in cosine-distributed directions. Their counts are the
// renderer's RenderStats. Deeper path vertices are stood in for by first hits, so at several
// bounces the Embree-only rays are somewhat more coherent than the renderer's. They are traced
// one by one, where the renderer traces its shadow and bounce rays in packets of 16 across a
// batch of paths (render/batch.h), which Embree takes faster.
//
// Renderer and Embree-only runs alternate within each timed run, so both see the same machine
// load; fractions are medians of per-run fractions, in wall time and in process CPU time (the
// steadier of the two on a busy machine).
//
//   edgepath_bench [--runs N] [--spp N] [--size N] [--threads N] [--bounces 1,3]
//                  [--no-all-cores] [--teapot N] [--image out.png] [--csv out.csv] [--render-only]
//                  [--forward-only]
//   edgepath_bench --backward-memory [--size N] [--spp N]
//   edgepath_bench --secondary-only [--size N] [--spp N] [--seeds N] [--threads N]
//   edgepath_bench --backward-only [--secondary-survival P]   (the secondary term's roulette by
//                  class, RenderOptions::secondary_survival, in the backward table)
//   edgepath_bench --survival-compare [--secondary-survival P] [--size N] [--spp N] [--seeds N]
//                  [--bounces 1,3]   (that roulette against none on the benchmark scene: the
//                  variance over seeds of every gradient, times the pass's CPU time)
//   edgepath_bench --digest [--size N] [--spp N] [--threads N] [--bounces 1,3] [--secondary-survival P]
//                  (one gradient pass and one derivative image per bounce count on the benchmark
//                  scene, and one of each on the single triangle: a hash of every output value,
//                  for bit-for-bit comparisons of two builds; the same whatever --threads)
//
// --render-only skips the Embree-only measurements, so that a profiler run (perf record) sees
// the renderer alone. --forward-only stops after the forward tables (A/B runs of two builds).
//
// Output: machine and scene information, then one table per measurement family. Each number
// is also kept as a (section, config, metric, value, unit) record, written by --csv, so new
// measurements (backward pass, memory) are new records and new tables, not a new format.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <embree3/rtcore.h>
#include <sys/resource.h>
#include <time.h>
#include <tbb/blocked_range.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "edgepath.h"
#include "edges/hierarchy.h"
#include "io/image.h"
#include "math/frame.h"
#include "render/packet.h"
#include "render/path.h"
#include "sampling/rng.h"
#include "sampling/warp.h"
#include "scene/scene.h"
#include "support/shapes.h"
#include "support/teapot.h"

namespace {

using namespace edgepath;
using Clock = std::chrono::steady_clock;

// ---------------------------------------------------------------------------------------------
// Options

struct Options {
    int runs = 5;              // timed runs per measurement (the median is reported)
    int spp = 4;
    int size = 256;            // image width = height
    int threads = 2;           // the fixed thread count measured
    bool all_cores = true;     // also measure with every core
    std::vector<int> bounces = {1, 3};
    int teapot_subdivisions = 32;
    std::string image_path;    // optional: writes the last rendered image
    std::string csv_path;      // optional: writes every record
    bool render_only = false;  // skip the Embree-only runs (for profilers)
    bool backward_memory = false;  // only: peak RSS of one backward pass (--size, --spp)
    bool secondary_only = false;   // only: secondary-edge samplers' equal-time MSE (--size, --spp)
    bool backward_only = false;    // only: the backward-pass timings (for profilers)
    bool forward_only = false;     // only: the forward-pass tables (for A/B runs of two builds)
    bool edges_only = false;       // only: the million-edge extraction, hierarchy and vertex step
    int seeds = 8;                 // --secondary-only: renders per sampler
    int only_case = -1;            // --secondary-only: just this scene (0: a, 1: b, 2: b', 3: c)
    float secondary_survival = 1.f;  // RenderOptions::secondary_survival of the backward table
    bool survival_compare = false;   // only: the roulette by class against none, at equal time
    bool digest = false;             // only: hashes of the gradient passes' outputs
};

[[noreturn]] void usage(const char* msg, int status = 2) {
    std::fprintf(status ? stderr : stdout,
                 "%s\nusage: edgepath_bench [--runs N] [--spp N] [--size N] [--threads N] [--bounces 1,3]\n"
                 "                      [--no-all-cores] [--teapot N] [--image out.png] [--csv out.csv]\n"
                 "                      [--backward-memory]  (alone: peak RSS of one backward pass)\n"
                 "                      [--secondary-only [--seeds N] [--case 0-3]]  (alone: secondary-edge samplers' MSE)\n"
                 "                      [--render-only] [--backward-only] [--forward-only]\n"
                 "                      [--secondary-survival P]  (the backward table's roulette floor, default 1)\n"
                 "                      [--survival-compare]  (alone: that roulette against none at equal time)\n"
                 "                      [--digest]  (alone: hashes of gradient passes' outputs, to compare builds)\n"
                 "                      [--edges-only]  (alone: a million edges extracted, their hierarchy built and refit)\n",
                 msg);
    std::exit(status);
}

int parse_int(const char* s, const char* flag, int lo, int hi) {
    char* end = nullptr;
    long v = std::strtol(s, &end, 10);
    if (end == s || *end != '\0' || v < lo || v > hi)
        usage((std::string(flag) + ": expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
               "], got '" + s + "'")
                  .c_str());
    return int(v);
}

Options parse_options(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&]() -> const char* {
            if (i + 1 >= argc) usage((a + ": missing value").c_str());
            return argv[++i];
        };
        if (a == "--runs") o.runs = parse_int(value(), "--runs", 1, 1000);
        else if (a == "--spp") o.spp = parse_int(value(), "--spp", 1, 1 << 16);
        else if (a == "--size") o.size = parse_int(value(), "--size", 1, 1 << 14);
        else if (a == "--threads") o.threads = parse_int(value(), "--threads", 1, 4096);
        else if (a == "--teapot") o.teapot_subdivisions = parse_int(value(), "--teapot", 1, 1024);
        else if (a == "--no-all-cores") o.all_cores = false;
        else if (a == "--render-only") o.render_only = true;
        else if (a == "--backward-memory") o.backward_memory = true;
        else if (a == "--secondary-only") o.secondary_only = true;
        else if (a == "--backward-only") o.backward_only = true;
        else if (a == "--survival-compare") o.survival_compare = true;
        else if (a == "--forward-only") o.forward_only = true;
        else if (a == "--edges-only") o.edges_only = true;
        else if (a == "--digest") o.digest = true;
        else if (a == "--seeds") o.seeds = parse_int(value(), "--seeds", 2, 1000);
        else if (a == "--case") o.only_case = parse_int(value(), "--case", 0, 3);
        else if (a == "--secondary-survival") {
            const char* v = value();
            char* end = nullptr;
            o.secondary_survival = std::strtof(v, &end);
            if (end == v || *end != '\0' || !(o.secondary_survival > 0.f && o.secondary_survival <= 1.f))
                usage((std::string("--secondary-survival: expected a number in (0, 1], got '") + v + "'").c_str());
        }
        else if (a == "--image") o.image_path = value();
        else if (a == "--csv") o.csv_path = value();
        else if (a == "--bounces") {
            o.bounces.clear();
            std::stringstream ss(value());
            std::string item;
            while (std::getline(ss, item, ',')) o.bounces.push_back(parse_int(item.c_str(), "--bounces", 0, 64));
            if (o.bounces.empty()) usage("--bounces: empty list");
        } else if (a == "-h" || a == "--help") usage("edgepath forward benchmark", 0);
        else usage(("unknown argument '" + a + "'").c_str());
    }
    return o;
}

// ---------------------------------------------------------------------------------------------
// Results: records, and tables printed from them

struct Record {
    std::string section, config, metric;
    double value;
    std::string unit;
};

class Table {
public:
    explicit Table(std::vector<std::string> header) : header_(std::move(header)) {}
    void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
    void print(const std::string& title) const {
        std::vector<size_t> w(header_.size());
        for (size_t c = 0; c < header_.size(); ++c) {
            w[c] = header_[c].size();
            for (const auto& r : rows_) w[c] = std::max(w[c], c < r.size() ? r[c].size() : 0);
        }
        std::printf("\n%s\n", title.c_str());
        auto line = [&](const std::vector<std::string>& r) {
            std::string s;
            for (size_t c = 0; c < header_.size(); ++c) {
                const std::string& cell = c < r.size() ? r[c] : std::string();
                s += (c ? "  " : "") + std::string(w[c] - cell.size(), ' ') + cell;
            }
            std::printf("%s\n", s.c_str());
        };
        line(header_);
        size_t total = 0;
        for (size_t c = 0; c < w.size(); ++c) total += w[c] + (c ? 2 : 0);
        std::printf("%s\n", std::string(total, '-').c_str());
        for (const auto& r : rows_) line(r);
    }

private:
    std::vector<std::string> header_;
    std::vector<std::vector<std::string>> rows_;
};

std::string fmt(double v, int decimals) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
    return buf;
}

std::string grouped(uint64_t v) {
    std::string s = std::to_string(v), out;
    for (size_t i = 0; i < s.size(); ++i) {
        if (i && (s.size() - i) % 3 == 0) out += ',';
        out += s[i];
    }
    return out;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Wall time of one call of f, in milliseconds.
double time_once(const std::function<void()>& f) {
    auto t0 = Clock::now();
    f();
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// CPU time of the whole process (all threads), in milliseconds. On a busy machine it is a
// steadier measure of work done than wall time.
double process_cpu_ms() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

struct Timing {
    double wall_ms, cpu_ms;
};

Timing time_once_cpu(const std::function<void()>& f) {
    double c0 = process_cpu_ms();
    double w = time_once(f);
    return {w, process_cpu_ms() - c0};
}

// Runs f once to warm up, then `runs` times; returns the median wall time in milliseconds.
double time_ms(int runs, const std::function<void()>& f) {
    f();
    std::vector<double> t;
    for (int i = 0; i < runs; ++i) t.push_back(time_once(f));
    return median(t);
}

// Runs f once to warm up, then `runs` times; returns the median wall and process CPU times.
Timing time_ms_cpu(int runs, const std::function<void()>& f) {
    f();
    std::vector<double> w, c;
    for (int i = 0; i < runs; ++i) {
        const Timing t = time_once_cpu(f);
        w.push_back(t.wall_ms);
        c.push_back(t.cpu_ms);
    }
    return {median(w), median(c)};
}

// ---------------------------------------------------------------------------------------------
// Machine

std::string cpu_model() {
    std::ifstream f("/proc/cpuinfo");
    std::string line;
    while (std::getline(f, line))
        if (line.rfind("model name", 0) == 0) {
            size_t c = line.find(':');
            if (c != std::string::npos) return line.substr(c + 2);
        }
    return "unknown";
}

// The 1-minute load average (other processes competing for the cores make timings noisy).
std::string load_average() {
    std::ifstream f("/proc/loadavg");
    std::string first;
    if (!(f >> first)) return "unknown";
    return first;
}

double peak_rss_mib() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0;  // Linux reports KiB
}

// ---------------------------------------------------------------------------------------------
// The scene

// Owns every array the scene description points into (deques: addresses never move).
struct BenchScene {
    std::deque<MeshData> meshes;
    std::deque<std::vector<float>> textures;
    SceneDesc desc;
    std::vector<std::string> parts;  // "name: triangles" for the summary

    TextureDesc texture(std::vector<float> data, int height, int width, int channels) {
        textures.push_back(std::move(data));
        TextureDesc t;
        t.data = textures.back().data();
        t.height = height;
        t.width = width;
        t.channels = channels;
        return t;
    }
    TextureDesc constant(std::initializer_list<float> v) { return texture(v, 1, 1, int(v.size())); }

    int material(TextureDesc diffuse, std::initializer_list<float> specular, float roughness) {
        MaterialDesc m;
        m.diffuse = diffuse;
        m.specular = constant(specular);
        m.roughness = constant({roughness});
        desc.materials.push_back(m);
        return int(desc.materials.size()) - 1;
    }

    MeshDesc& add(const std::string& name, MeshData mesh, int material) {
        meshes.push_back(std::move(mesh));
        parts.push_back(name + " " + grouped(uint64_t(meshes.back().num_triangles())));
        desc.meshes.push_back(meshes.back().desc(material));
        return desc.meshes.back();
    }

    int64_t num_triangles() const {
        int64_t n = 0;
        for (const auto& m : meshes) n += m.num_triangles();
        return n;
    }
};

// A 64x128 lat-long sky: blue at the zenith, pale at the horizon, dark ground below, and a
// bright sun (a Gaussian blob a few texels wide) up and to the right.
TextureDesc make_sky(BenchScene& bs, int height, int width) {
    std::vector<float> v(size_t(height) * width * 3);
    const double pi = 3.14159265358979323846;
    Vec3d sun = normalize(Vec3d(0.6, 0.55, 0.45));
    const double sun_width = 0.06;  // radians
    for (int j = 0; j < height; ++j) {
        double theta = pi * j / (height - 1);  // row j sits at v = j / (H - 1)
        for (int i = 0; i < width; ++i) {
            double phi = 2 * pi * i / width;  // column i sits at u = i / W
            Vec3d d(std::sin(theta) * std::sin(phi), std::cos(theta), -std::sin(theta) * std::cos(phi));
            Vec3d c;
            if (d.y >= 0) {
                double h = std::pow(1.0 - d.y, 3.0);  // 0 at the zenith, 1 at the horizon
                c = Vec3d(0.15, 0.3, 0.8) * (1 - h) + Vec3d(0.85, 0.9, 1.0) * h;
            } else {
                c = Vec3d(0.12, 0.1, 0.08);
            }
            double a = std::acos(std::clamp(dot(d, sun), -1.0, 1.0)) / sun_width;
            c += Vec3d(120.0, 110.0, 90.0) * std::exp(-a * a);
            for (int k = 0; k < 3; ++k) v[(size_t(j) * width + i) * 3 + k] = float(c[k]);
        }
    }
    return bs.texture(std::move(v), height, width, 3);
}

TextureDesc make_checker(BenchScene& bs, int n) {
    std::vector<float> v(size_t(n) * n * 3);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            float g = ((i / 4 + j / 4) % 2) ? 0.65f : 0.35f;
            for (int k = 0; k < 3; ++k) v[(size_t(j) * n + i) * 3 + k] = g * (k == 2 ? 0.9f : 1.f);
        }
    return bs.texture(std::move(v), n, n, 3);
}

void build_bench_scene(BenchScene& bs, const Options& o) {
    SceneDesc& d = bs.desc;
    d.camera.position[0] = 0.f, d.camera.position[1] = 3.2f, d.camera.position[2] = 9.f;
    d.camera.look_at[0] = 0.f, d.camera.look_at[1] = 0.8f, d.camera.look_at[2] = 0.f;
    d.camera.fov = 40.f;
    d.camera.width = d.camera.height = o.size;

    int floor_mat = bs.material(make_checker(bs, 64), {0.f, 0.f, 0.f}, 1.f);
    int teapot_mat = bs.material(bs.constant({0.3f, 0.12f, 0.05f}), {0.5f, 0.5f, 0.5f}, 0.1f);
    int glossy_mat = bs.material(bs.constant({0.05f, 0.05f, 0.08f}), {0.6f, 0.6f, 0.6f}, 0.08f);
    int red_mat = bs.material(bs.constant({0.7f, 0.15f, 0.1f}), {0.f, 0.f, 0.f}, 1.f);
    int green_mat = bs.material(bs.constant({0.15f, 0.6f, 0.2f}), {0.f, 0.f, 0.f}, 1.f);
    int box_mat = bs.material(bs.constant({0.6f, 0.6f, 0.55f}), {0.f, 0.f, 0.f}, 1.f);
    int lamp_mat = bs.material(bs.constant({0.f, 0.f, 0.f}), {0.f, 0.f, 0.f}, 1.f);

    // Floor: 30 x 30 at y = 0, facing up; the checker repeats 6 times across it.
    MeshData floor = make_quad(Vec3f(-15.f, 0.f, -15.f), Vec3f(0.f, 0.f, 30.f), Vec3f(30.f, 0.f, 0.f));
    for (float& uv : floor.uvs) uv *= 6.f;
    bs.add("floor", std::move(floor), floor_mat);

    // Teapot: 0.6 x the original (about 1.9 high), standing at the origin, spout to +x.
    MeshData teapot = make_teapot(o.teapot_subdivisions);
    teapot.transform(Vec3f(0.6f), Vec3f(0.f));
    bs.add("teapot", std::move(teapot), teapot_mat);

    bs.add("glossy sphere", make_sphere(Vec3f(-2.7f, 0.8f, 0.9f), 0.8f, 64, 128), glossy_mat);
    bs.add("sphere", make_sphere(Vec3f(2.7f, 0.6f, 0.9f), 0.6f, 64, 128), red_mat);
    bs.add("sphere", make_sphere(Vec3f(1.0f, 0.45f, 2.4f), 0.45f, 64, 128), green_mat);

    bs.add("box", make_box(Vec3f(-2.0f, 0.f, -2.6f), Vec3f(-1.0f, 0.9f, -1.6f)), box_mat);
    bs.add("box", make_box(Vec3f(1.4f, 0.f, -2.4f), Vec3f(2.6f, 1.3f, -1.2f)), box_mat);
    bs.add("box", make_box(Vec3f(-1.2f, 0.f, 2.0f), Vec3f(-0.4f, 0.4f, 2.8f)), box_mat);
    bs.add("box", make_box(Vec3f(3.6f, 0.f, -1.0f), Vec3f(4.2f, 2.0f, -0.4f)), box_mat);

    // Area light: 1.6 x 1.6 at y = 4.5, facing down.
    MeshData lamp = make_quad(Vec3f(-0.8f, 4.5f, -0.3f), Vec3f(1.6f, 0.f, 0.f), Vec3f(0.f, 0.f, 1.6f));
    MeshDesc& lamp_desc = bs.add("area light", std::move(lamp), lamp_mat);
    lamp_desc.emission = bs.constant({12.f, 11.f, 9.f});

    d.has_envmap = true;
    d.envmap.values = make_sky(bs, 64, 128);
}

// ---------------------------------------------------------------------------------------------
// Embree alone: the same numbers of rays of the same kinds, generated before timing

struct RaySet {
    std::vector<Ray> camera, shadow, bounce;
};

constexpr int kRenderTile = 16;  // the renderer's tile size: camera rays in the same order

RaySet make_rays(const Scene& scene, const RenderOptions& opt, const RenderStats& stats) {
    RaySet rs;
    const int W = scene.out_width, H = scene.out_height;
    const int tiles_x = (W + kRenderTile - 1) / kRenderTile, tiles_y = (H + kRenderTile - 1) / kRenderTile;
    rs.camera.reserve(size_t(W) * H * opt.spp);
    for (int tile = 0; tile < tiles_x * tiles_y; ++tile) {
        int x0 = (tile % tiles_x) * kRenderTile, y0 = (tile / tiles_x) * kRenderTile;
        for (int y = y0; y < std::min(y0 + kRenderTile, H); ++y)
            for (int x = x0; x < std::min(x0 + kRenderTile, W); ++x) {
                int fx = x + scene.crop_x, fy = y + scene.crop_y;
                uint64_t pixel = uint64_t(fy) * uint64_t(scene.camera.width) + uint64_t(fx);
                for (int s = 0; s < opt.spp; ++s) {
                    Rng rng = Rng::for_sample(opt.seed, pixel, uint64_t(s));
                    Vec2f film = sample_film_point(scene, fx, fy, rng);
                    rs.camera.push_back(scene.camera.generate_ray(film.x, film.y));
                }
            }
    }

    // Where the camera rays land (in the same order), as origins of shadow and bounce rays.
    struct Origin {
        SurfacePoint sp;
        Vec3f front;  // ng turned towards the camera
    };
    std::vector<Origin> origins;
    origins.reserve(rs.camera.size());
    for (const Ray& r : rs.camera) {
        Hit h;
        if (!scene.intersect(r, h)) continue;
        SurfacePoint sp = scene.surface_point(h);
        origins.push_back({sp, dot(sp.ng, r.dir) < 0.f ? sp.ng : -sp.ng});
    }
    if (origins.empty()) return rs;

    // Shadow rays: towards points sampled on the emitters (area light or sky, as the renderer
    // samples them: one of each per vertex when there are both, here alternately), on the side
    // of the surface the camera sees, as the renderer only traces shadow rays where the BSDF is
    // non-zero.
    Rng rng(opt.seed + 12345, 7);
    rs.shadow.reserve(stats.shadow_rays);
    for (uint64_t k = 0; k < stats.shadow_rays; ++k) {
        const Origin& o = origins[k % origins.size()];
        LightSample ls, first;
        bool have = false;
        for (int attempt = 0; attempt < 16; ++attempt) {
            const float u0 = rng.next_float(), u1 = rng.next_float(), u2 = rng.next_float();
            const bool env = scene.env_sampled && (!scene.light_distribution.valid() || k % 2 == 1);
            if (!(env ? scene.sample_env(u1, u2, ls) : scene.sample_area_light(o.sp.p, u0, u1, u2, ls))) continue;
            if (!have) first = ls, have = true;
            if (dot(ls.dir, o.front) > 0.f) {
                first = ls;
                break;
            }
        }
        if (!have) {
            first.dir = o.front;
            first.dist = std::numeric_limits<float>::infinity();
        }
        rs.shadow.push_back(shadow_ray(o.sp, first));
    }

    // Bounce rays: cosine-distributed about the visible side of the surface.
    rs.bounce.reserve(stats.bounce_rays);
    for (uint64_t k = 0; k < stats.bounce_rays; ++k) {
        const Origin& o = origins[k % origins.size()];
        Vec3f dir = Frame(o.front).to_world(square_to_cosine_hemisphere(rng.next_float(), rng.next_float()));
        rs.bounce.push_back(spawn_ray(o.sp, normalize(dir)));
    }
    return rs;
}

// Traces `rays` with rtcIntersect1 (or rtcOccluded1) on `threads` threads, in chunks of the size
// of one render tile's camera rays. Returns the number of hits (keeps the work observable).
uint64_t trace_rays(RTCScene rtc, const std::vector<Ray>& rays, bool occlusion, tbb::task_arena& arena, size_t chunk) {
    std::atomic<uint64_t> hits{0};
    const size_t n_chunks = (rays.size() + chunk - 1) / chunk;
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n_chunks, 1), [&](const tbb::blocked_range<size_t>& range) {
            uint64_t local = 0;
            RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            for (size_t c = range.begin(); c < range.end(); ++c) {
                const size_t end = std::min(rays.size(), (c + 1) * chunk);
                for (size_t i = c * chunk; i < end; ++i) {
                    const Ray& ray = rays[i];
                    if (occlusion) {
                        RTCRay r = to_rtc_ray(ray);
                        rtcOccluded1(rtc, &ctx, &r);
                        local += r.tfar < 0.f;
                    } else {
                        RTCRayHit rh = to_rtc_ray_hit(ray);
                        rtcIntersect1(rtc, &ctx, &rh);
                        local += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
                    }
                }
            }
            hits += local;
        });
    });
    return hits;
}

// The camera rays again, in packets of kPacketSize as the renderer traces them
// (intersect_packet). Returns the number of hits.
uint64_t trace_camera_packets(const Scene& scene, Tracing tracing, const std::vector<Ray>& rays, tbb::task_arena& arena,
                              size_t chunk) {
    std::atomic<uint64_t> hits{0};
    const size_t n_chunks = (rays.size() + chunk - 1) / chunk;
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n_chunks, 1), [&](const tbb::blocked_range<size_t>& range) {
            uint64_t local = 0;
            FirstHit first[kPacketSize];
            for (size_t c = range.begin(); c < range.end(); ++c) {
                const size_t end = std::min(rays.size(), (c + 1) * chunk);
                for (size_t i = c * chunk; i < end; i += kPacketSize) {
                    const int n = int(std::min<size_t>(kPacketSize, end - i));
                    intersect_packet(scene, tracing, rays.data() + i, n, first);
                    for (int k = 0; k < n; ++k) local += first[k].found;
                }
            }
            hits += local;
        });
    });
    return hits;
}

// ---------------------------------------------------------------------------------------------

struct ForwardResult {
    int threads_requested;  // 0: all cores
    int threads;            // actual
    int bounces;
    double render_ms;
    RenderStats stats;
    double embree_ms, embree_camera_ms, embree_shadow_ms, embree_bounce_ms;
    double embree_packets_ms;  // the camera rays in packets
    double fraction;  // median over runs of (Embree-only time / renderer time)
    double render_cpu_ms, embree_cpu_ms, fraction_cpu;  // the same in process CPU time
    uint64_t embree_hits;
};

}  // namespace

// Gradient buffers for every differentiable parameter of the scene (the worst case: a user
// optimising everything at once).
struct AllGradients {
    std::deque<std::vector<float>> buffers;
    SceneGradients slots;
    size_t bytes = 0;

    GradSlot slot(int64_t n) {
        if (n == 0) return {};
        buffers.emplace_back(size_t(n), 0.f);
        bytes += size_t(n) * sizeof(float);
        GradSlot s;
        s.grad = buffers.back().data();
        return s;
    }

    explicit AllGradients(const SceneDesc& d) {
        for (const MeshDesc& m : d.meshes) {
            SceneGradients::MeshSlots ms;
            ms.vertices = slot(m.num_vertices * 3);
            ms.uvs = slot(m.uvs ? m.num_uvs * 2 : 0);
            ms.normals = slot(m.normals ? m.num_normals * 3 : 0);
            ms.emission = slot(m.emission.num_values());
            slots.meshes.push_back(ms);
        }
        for (const MaterialDesc& m : d.materials) {
            SceneGradients::MaterialSlots ms;
            ms.diffuse = slot(m.diffuse.num_values());
            ms.specular = slot(m.specular.num_values());
            ms.roughness = slot(m.roughness.num_values());
            slots.materials.push_back(ms);
        }
        if (d.has_envmap) {
            slots.envmap = slot(d.envmap.values.num_values());
            slots.envmap_rotation = slot(9);
        }
        slots.camera = slot(kCameraParams);
        // As the Python API numbers them: the gradient sink's cache places each slot's values
        // by its key (all keys 0 would pile every slot's first values onto the same entries).
        number_slots(slots);
    }
};

// The single-triangle scene of the classic comparison (a triangle in front of a wall, a lamp
// behind the camera), as the Python demo builds it.
struct TriangleScene {
    std::vector<float> tri_v = {-1.7f, 1, 0, 1, 1, 0, -0.5f, -1, 0}, wall_v = {-4, -4, 2, -4, 4, 2, 4, 4, 2, 4, -4, 2},
                       lamp_v = {-2, -2, -7, 2, -2, -7, 2, 2, -7, -2, 2, -7};
    std::vector<int32_t> tri_i = {0, 1, 2}, quad_i = {0, 1, 2, 0, 2, 3};
    std::vector<float> red = {0.8f, 0.2f, 0.2f}, spec = {0.04f, 0.04f, 0.04f}, rough = {0.3f}, grey = {0.5f, 0.5f, 0.5f},
                       zero = {0, 0, 0}, half = {0.5f}, le = {20, 20, 20};
    SceneDesc desc;

    explicit TriangleScene(int size) {
        auto mat = [](std::vector<float>& kd, std::vector<float>& ks, std::vector<float>& r) {
            MaterialDesc m;
            m.diffuse = {kd.data(), 1, 1, 3};
            m.specular = {ks.data(), 1, 1, 3};
            m.roughness = {r.data(), 1, 1, 1};
            return m;
        };
        desc.materials = {mat(red, spec, rough), mat(grey, zero, half), mat(zero, zero, half)};
        auto mesh = [](std::vector<float>& v, std::vector<int32_t>& i, int material) {
            MeshDesc m;
            m.vertices = v.data();
            m.num_vertices = int64_t(v.size() / 3);
            m.indices = i.data();
            m.num_triangles = int64_t(i.size() / 3);
            m.material = material;
            return m;
        };
        desc.meshes = {mesh(tri_v, tri_i, 0), mesh(wall_v, quad_i, 1), mesh(lamp_v, quad_i, 2)};
        desc.meshes[2].emission = {le.data(), 1, 1, 3};
        CameraDesc& c = desc.camera;
        const float pos[3] = {0, 0, -5}, at[3] = {0, 0, 0}, up[3] = {0, 1, 0};
        std::copy(pos, pos + 3, c.position);
        std::copy(at, at + 3, c.look_at);
        std::copy(up, up + 3, c.up);
        c.fov = 45;
        c.width = c.height = size;
    }
};

struct BackwardResult {
    std::string scene;
    int bounces;
    double forward_ms, backward_ms, interior_ms, no_secondary_ms;  // primary edges off; secondary off
    double forward_cpu_ms, backward_cpu_ms;                        // process CPU time
    double materials_cpu_ms;  // the gradient pass with only the materials wanted, every edge term on
};

// Median forward and backward (every parameter wanted, adjoint = 1) times.
BackwardResult time_backward(const std::string& name, const SceneDesc& desc, int spp, int bounces, int threads,
                             int runs, float survival) {
    std::shared_ptr<const Scene> scene = build_scene(desc);
    const size_t n = size_t(image_width(*scene)) * image_height(*scene) * 3;
    std::vector<float> image(n), adjoint(n, 1.f);
    AllGradients grads(desc);
    RenderOptions ro;
    ro.spp = spp;
    ro.max_bounces = bounces;
    ro.num_threads = threads;
    ro.seed = 3;
    ro.secondary_survival = survival;
    BackwardResult r{name, bounces, 0, 0, 0, 0, 0, 0, 0};
    const Timing forward = time_ms_cpu(runs, [&] { render(*scene, ro, image.data()); });
    const Timing backward = time_ms_cpu(runs, [&] { render_gradients(*scene, ro, adjoint.data(), grads.slots); });
    r.forward_ms = forward.wall_ms;
    r.forward_cpu_ms = forward.cpu_ms;
    r.backward_ms = backward.wall_ms;
    r.backward_cpu_ms = backward.cpu_ms;
    ro.secondary_edges = false;
    r.no_secondary_ms = time_ms(runs, [&] { render_gradients(*scene, ro, adjoint.data(), grads.slots); });
    ro.primary_edges = false;
    r.interior_ms = time_ms(runs, [&] { render_gradients(*scene, ro, adjoint.data(), grads.slots); });
    // A material-only step (colours, roughness; no geometry moves, so no edge term has anything
    // to add, though both are on).
    ro.secondary_edges = ro.primary_edges = true;
    SceneGradients materials;
    materials.meshes.resize(grads.slots.meshes.size());
    materials.materials = grads.slots.materials;
    r.materials_cpu_ms = time_ms_cpu(runs, [&] { render_gradients(*scene, ro, adjoint.data(), materials); }).cpu_ms;
    return r;
}

// Variance of the triangle's vertex gradients (image-sum loss) over seeds, for one edge sampling
// strategy, and the mean backward time: their product is the cost of a given accuracy, so the
// ratio of products compares the strategies at equal time. Also for the edge term alone: the
// gradient minus the same seed's interior-only gradient (the interior pass draws the same random
// numbers either way), against the time the edge pass adds.
struct EdgeVariance {
    double variance, ms, edge_variance, edge_ms;
};
EdgeVariance edge_variance(const SceneDesc& desc, EdgeSampling sampling, int threads, int seeds) {
    std::shared_ptr<const Scene> scene = build_scene(desc);
    const size_t n = size_t(image_width(*scene)) * image_height(*scene) * 3;
    std::vector<float> adjoint(n, 1.f);
    RenderOptions ro;
    ro.spp = 4;
    ro.max_bounces = 1;
    ro.num_threads = threads;
    ro.edge_sampling = sampling;
    const size_t nv = size_t(desc.meshes[0].num_vertices) * 3;
    auto gradient = [&](bool edges, uint64_t seed, double& ms) {
        std::vector<float> g(nv, 0.f);
        SceneGradients slots;
        slots.meshes.resize(desc.meshes.size());
        slots.meshes[0].vertices.grad = g.data();
        ro.seed = seed;
        ro.primary_edges = edges;
        auto t0 = std::chrono::steady_clock::now();
        render_gradients(*scene, ro, adjoint.data(), slots);
        ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        return std::vector<double>(g.begin(), g.end());
    };
    std::vector<std::vector<double>> full, edge;
    double full_ms = 0, interior_ms = 0;
    for (int s = 0; s < seeds; ++s) {
        full.push_back(gradient(true, uint64_t(100 + s), full_ms));
        std::vector<double> interior = gradient(false, uint64_t(100 + s), interior_ms);
        edge.push_back(full.back());
        for (size_t k = 0; k < nv; ++k) edge.back()[k] -= interior[k];
    }
    auto variance = [&](const std::vector<std::vector<double>>& xs) {
        double var = 0;
        for (size_t k = 0; k < nv; ++k) {
            double mean = 0, sq = 0;
            for (const auto& x : xs) mean += x[k];
            mean /= double(xs.size());
            for (const auto& x : xs) sq += (x[k] - mean) * (x[k] - mean);
            var += sq / double(xs.size() - 1);
        }
        return var / double(nv);
    };
    return {variance(full), full_ms / seeds, variance(edge), (full_ms - interior_ms) / seeds};
}

// One backward pass at the requested size, alone in this process: its peak RSS against the
// image-sized buffers (image, adjoint) and the gradient buffers it must hold.
int backward_memory(const Options& o, BenchScene& bs) {
    bs.desc.camera.width = bs.desc.camera.height = o.size;
    const double before = peak_rss_mib();
    std::shared_ptr<const Scene> scene = build_scene(bs.desc);
    const double after_build = peak_rss_mib();
    const size_t n = size_t(o.size) * o.size * 3;
    std::vector<float> adjoint(n, 1.f);
    AllGradients grads(bs.desc);
    RenderOptions ro;
    ro.spp = o.spp;
    ro.max_bounces = 1;
    ro.num_threads = o.threads;
    auto t0 = Clock::now();
    render_gradients(*scene, ro, adjoint.data(), grads.slots);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    const double peak = peak_rss_mib();
    const double image_mib = double(n) * sizeof(float) / (1 << 20);
    const double grad_mib = double(grads.bytes) / (1 << 20);
    std::printf("\nBackward pass memory, %dx%d, %d spp, 1 bounce, %d threads (%.0f ms)\n", o.size, o.size, o.spp,
                o.threads, ms);
    std::printf("  peak RSS %.0f MiB: process and scene description %.0f MiB, + built scene (BVH, tables) %.0f MiB,\n"
                "  + adjoint image %.0f MiB + gradient buffers %.1f MiB + the pass itself %.0f MiB\n",
                peak, before, after_build - before, image_mib, grad_mib,
                std::max(0.0, peak - after_build - image_mib - grad_mib));
    return 0;
}

// ---------------------------------------------------------------------------------------------
// Secondary edges: the edge hierarchy against uniform edge sampling, at equal time.
//
// The secondary-edge term of a derivative image is the derivative image minus the same seed's
// image with secondary edges off (the interior and primary terms draw the same random numbers
// either way). The hierarchy renders it with --seeds seeds at --spp, the uniform sampler at the
// spp that takes about as long (so that its rare large samples show up as often as at equal
// time). Each one's MSE against a reference (the hierarchy at 64x the samples) times the time the
// term takes (the two renders' difference, in process CPU time: steadier than wall time on a
// busy machine) is the cost of a given accuracy; the ratio of those products, uniform over
// hierarchy, is the equal-time MSE ratio (also given with the whole derivative image's time).

// (a) a small area light, a large floor, a sphere of about 50k triangles casting the shadow;
// the sphere moves along x. (b) a glossy floor (GGX alpha 0.1) reflecting a box that moves along
// x in front of a bright emissive backdrop, a quarter of its height above the floor; (b') the box
// resting on the floor: where it touches, the derivative grows as 1/distance to the contact, and
// its variance over the pixel's area (whichever edge sampler) dominates the MSE; (c) a sphere of
// about 50k triangles in the box's place, floating.
void make_shadow_case(BenchScene& bs, int size) {
    SceneDesc& d = bs.desc;
    const int floor = bs.material(bs.constant({0.7f, 0.7f, 0.7f}), {0.f, 0.f, 0.f}, 0.5f);
    const int matte = bs.material(bs.constant({0.5f, 0.5f, 0.5f}), {0.f, 0.f, 0.f}, 0.5f);
    bs.add("sphere", make_sphere(Vec3f(0.2f, 1.f, 0.2f), 0.5f, 125, 200), matte);
    bs.add("floor", make_quad(Vec3f(-5, 0, -5), Vec3f(0, 0, 10), Vec3f(10, 0, 0)), floor);
    MeshDesc& light = bs.add("light", make_quad(Vec3f(-2.15f, 3.f, -0.15f), Vec3f(0.3f, 0, 0), Vec3f(0, 0, 0.3f)), matte);
    light.emission = bs.constant({200.f, 200.f, 200.f});
    // Looking straight down at the shadow, the sphere out of view (only the shadow's edge moves).
    const float pos[3] = {1.5f, 2.f, 0.3f}, at[3] = {1.5f, 0, 0.3f}, up[3] = {0, 0, 1};
    std::copy(pos, pos + 3, d.camera.position);
    std::copy(at, at + 3, d.camera.look_at);
    std::copy(up, up + 3, d.camera.up);
    d.camera.fov = 50;
    d.camera.width = d.camera.height = size;
}

void make_glossy_case(BenchScene& bs, int size, float lift, bool sphere) {
    SceneDesc& d = bs.desc;
    const int glossy = bs.material(bs.constant({0.05f, 0.05f, 0.05f}), {0.8f, 0.8f, 0.8f}, 0.1f);
    const int matte = bs.material(bs.constant({0.5f, 0.5f, 0.5f}), {0.f, 0.f, 0.f}, 0.5f);
    if (sphere) bs.add("sphere", make_sphere(Vec3f(0.f, lift + 0.5f, 1.5f), 0.5f, 125, 200), matte);
    else bs.add("box", make_box(Vec3f(-0.5f, lift, 1.f), Vec3f(0.5f, lift + 1.f, 2.f)), matte);
    bs.add("floor", make_quad(Vec3f(-5, 0, -5), Vec3f(0, 0, 10), Vec3f(10, 0, 0)), glossy);
    MeshDesc& wall = bs.add("backdrop", make_quad(Vec3f(-4, 0, 4), Vec3f(0, 3, 0), Vec3f(8, 0, 0)), matte);
    wall.emission = bs.constant({2.f, 2.f, 2.f});
    const float pos[3] = {0, 1.2f, -3.f}, at[3] = {0, 0, 1.5f}, up[3] = {0, 1, 0};
    std::copy(pos, pos + 3, d.camera.position);
    std::copy(at, at + 3, d.camera.look_at);
    std::copy(up, up + 3, d.camera.up);
    d.camera.fov = 45;
    d.camera.width = d.camera.height = size;
}

struct SecondaryRun {
    int spp = 0;
    double mse = 0, ms = 0, total_ms = 0;  // mean over seeds; ms: the secondary term's time
};

int secondary_only(const Options& o) {
    std::printf("edgepath benchmark: secondary edges, edge hierarchy against uniform sampling by length\n");
    std::printf("settings : %dx%d pixels, %d spp, %d seeds per sampler, %d threads, 1 bounce; reference: the "
                "hierarchy at %d spp\n",
                o.size, o.size, o.spp, o.seeds, o.threads, 64 * o.spp);
    Table table({"scene", "compared", "sampler", "spp", "MSE", "secondary cpu ms", "whole cpu ms", "MSE x ms"});
    for (int which = 0; which < 4; ++which) {
        if (o.only_case >= 0 && which != o.only_case) continue;
        BenchScene bs;
        if (which == 0) make_shadow_case(bs, o.size);
        else make_glossy_case(bs, o.size, which == 2 ? 0.f : 0.25f, which == 3);
        const std::string name = which == 0   ? "(a) shadow of a 50k-triangle sphere, small light"
                                 : which == 1 ? "(b) box reflected in a glossy floor (alpha 0.1)"
                                 : which == 2 ? "(b') the same box resting on the floor"
                                              : "(c) a 50k-triangle sphere in its place";
        std::shared_ptr<const Scene> scene = build_scene(bs.desc);
        const size_t n = size_t(o.size) * o.size * 3;
        std::vector<float> dir(size_t(bs.desc.meshes[0].num_vertices) * 3, 0.f);
        for (size_t i = 0; i < dir.size(); i += 3) dir[i] = 1.f;  // the moving mesh along x
        SceneGradients dirs;
        dirs.meshes.resize(bs.desc.meshes.size());
        dirs.meshes[0].vertices.dir = dir.data();
        struct Render {
            std::vector<double> whole, term;  // the derivative image; its secondary term
            double total_ms = 0, ms = 0;      // their process CPU times (ms: the term's)
        };
        // The whole derivative image and, unless `whole_only`, its secondary term: the image
        // minus the same seed's image with secondary edges off.
        auto render = [&](EdgeSampling sampling, int spp, uint64_t seed, bool whole_only) {
            RenderOptions ro;
            ro.spp = spp;
            ro.max_bounces = 1;
            ro.num_threads = o.threads;
            ro.seed = seed;
            ro.edge_sampling = sampling;
            std::vector<float> with(n), without(n);
            Render r;
            r.total_ms = time_once_cpu([&] { derivative_image(*scene, ro, dirs, with.data()); }).cpu_ms;
            r.whole.assign(with.begin(), with.end());
            if (whole_only) return r;
            ro.secondary_edges = false;
            r.ms = r.total_ms - time_once_cpu([&] { derivative_image(*scene, ro, dirs, without.data()); }).cpu_ms;
            r.term.resize(n);
            for (size_t i = 0; i < n; ++i) r.term[i] = double(with[i]) - double(without[i]);
            return r;
        };
        auto mse = [&](const std::vector<double>& a, const std::vector<double>& b) {
            double se = 0;
            for (size_t i = 0; i < n; ++i) se += (a[i] - b[i]) * (a[i] - b[i]);
            return se / double(n);
        };
        const Render ref = render(EdgeSampling::Importance, 64 * o.spp, 999, false);
        double ref_sq = 0;
        for (double v : ref.term) ref_sq += v * v;
        // Equal time: the uniform sampler gets as many samples per pixel as fit in the
        // hierarchy's time (from one render of each; the secondary term's time for the term's
        // MSE, the whole image's for the image's), so that its rare large samples show up in
        // the MSE as often as they would at equal time.
        const Render h_cal = render(EdgeSampling::Importance, o.spp, 500, false),
                     u_cal = render(EdgeSampling::Uniform, o.spp, 500, false);
        auto equal_spp = [&](double h_ms, double u_ms) {
            return std::clamp(int(std::lround(o.spp * std::max(h_ms, 1e-3) / std::max(u_ms, 1e-3))), o.spp, 64 * o.spp);
        };
        // [0] hierarchy, [1] uniform: the secondary term; [2] hierarchy, [3] uniform: the image.
        SecondaryRun runs[4];
        runs[0].spp = runs[2].spp = o.spp;
        runs[1].spp = equal_spp(h_cal.ms, u_cal.ms);
        runs[3].spp = equal_spp(h_cal.total_ms, u_cal.total_ms);
        for (int k = 0; k < o.seeds; ++k) {
            const uint64_t seed = uint64_t(k + 1);
            const Render h = render(EdgeSampling::Importance, o.spp, seed, false),
                         u = render(EdgeSampling::Uniform, runs[1].spp, seed, false),
                         uw = render(EdgeSampling::Uniform, runs[3].spp, seed, true);
            const Render* rs[4] = {&h, &u, &h, &uw};
            for (int s = 0; s < 4; ++s) {
                runs[s].mse += (s < 2 ? mse(rs[s]->term, ref.term) : mse(rs[s]->whole, ref.whole)) / o.seeds;
                runs[s].ms += std::max(rs[s]->ms, 0.0) / o.seeds;
                runs[s].total_ms += rs[s]->total_ms / o.seeds;
            }
        }
        for (int s = 0; s < 4; ++s) {
            const bool term = s < 2;
            table.add({name, term ? "secondary term" : "whole image", s % 2 == 0 ? "hierarchy" : "uniform",
                       std::to_string(runs[s].spp), fmt(runs[s].mse, 6), term ? fmt(runs[s].ms, 1) : "",
                       fmt(runs[s].total_ms, 1), fmt(runs[s].mse * (term ? runs[s].ms : runs[s].total_ms), 4)});
        }
        const double ratio = (runs[1].mse * runs[1].ms) / (runs[0].mse * runs[0].ms),
                     whole = (runs[3].mse * runs[3].total_ms) / (runs[2].mse * runs[2].total_ms);
        std::printf("%s: reference mean square of the secondary term %.6f; equal-time MSE ratio (uniform / "
                    "hierarchy) %.1f for the secondary term (its own time), %.1f for the whole derivative image\n",
                    name.c_str(), ref_sq / double(n), ratio, whole);
    }
    table.print("Secondary edges at equal time (means over seeds): the secondary term of the derivative image "
                "against its reference, timed alone; the whole derivative image against its reference, timed whole");
    return 0;
}

// The backward-pass table: the benchmark scene at each bounce count and the single triangle.
void backward_section(const Options& o, BenchScene& bs,
                      const std::function<void(const std::string&, const std::string&, const std::string&, double,
                                               const std::string&)>& record) {
    // Backward: the gradient pass with every parameter wanted, against the forward pass.
    Table backward({"scene", "threads", "bounces", "forward ms", "backward ms", "backward/forward",
                    "no secondary ms", "secondary share", "interior only ms", "forward cpu ms", "backward cpu ms",
                    "(cpu) backward/forward", "(cpu) materials only/forward"});
    std::vector<BackwardResult> back;
    for (int bounces : o.bounces)
        back.push_back(time_backward("benchmark", bs.desc, o.spp, bounces, o.threads, o.runs, o.secondary_survival));
    const TriangleScene tri(256);
    back.push_back(time_backward("single triangle 256x256", tri.desc, 4, 1, o.threads, o.runs, o.secondary_survival));
    for (const BackwardResult& r : back) {
        const std::string config = r.scene + " threads=" + std::to_string(o.threads) + " bounces=" + std::to_string(r.bounces);
        record("backward", config, "forward_ms", r.forward_ms, "ms");
        record("backward", config, "backward_ms", r.backward_ms, "ms");
        record("backward", config, "backward_over_forward", r.backward_ms / r.forward_ms, "");
        record("backward", config, "forward_cpu_ms", r.forward_cpu_ms, "ms");
        record("backward", config, "backward_cpu_ms", r.backward_cpu_ms, "ms");
        record("backward", config, "backward_interior_only_ms", r.interior_ms, "ms");
        record("backward", config, "backward_no_secondary_ms", r.no_secondary_ms, "ms");
        record("backward", config, "backward_materials_only_cpu_ms", r.materials_cpu_ms, "ms");
        const double share = (r.backward_ms - r.no_secondary_ms) / r.backward_ms;
        record("backward", config, "secondary_share", share, "");
        backward.add({r.scene, std::to_string(o.threads), std::to_string(r.bounces), fmt(r.forward_ms, 1),
                      fmt(r.backward_ms, 1), fmt(r.backward_ms / r.forward_ms, 2), fmt(r.no_secondary_ms, 1),
                      fmt(100.0 * share, 0) + "%", fmt(r.interior_ms, 1), fmt(r.forward_cpu_ms, 1),
                      fmt(r.backward_cpu_ms, 1), fmt(r.backward_cpu_ms / r.forward_cpu_ms, 2),
                      fmt(r.materials_cpu_ms / r.forward_cpu_ms, 2)});
    }
    backward.print("Backward pass (interior term, primary edges (one edge sample per pixel per spp) and secondary "
                   "edges (one hierarchy descent, up to four edges, per scattering vertex); every parameter wanted, adjoint 1; "
                   "the last column: only the materials wanted), " + std::to_string(o.spp) +
                   " spp (single triangle: 4 spp, the scene of the classic comparison: 95 ms forward, 940 ms "
                   "backward)");
    // Issue 18's target: the backward pass at most 3x the forward, every edge term on, in CPU time.
    double worst = 0.0;
    std::string ratios, materials;
    for (const BackwardResult& r : back) {
        if (r.scene != "benchmark") continue;
        const double ratio = r.backward_cpu_ms / r.forward_cpu_ms;
        worst = std::max(worst, ratio);
        const std::string at = "x at " + std::to_string(r.bounces) + (r.bounces == 1 ? " bounce" : " bounces");
        ratios += (ratios.empty() ? "" : ", ") + fmt(ratio, 1) + at;
        materials += (materials.empty() ? "" : ", ") + fmt(r.materials_cpu_ms / r.forward_cpu_ms, 1) + at;
    }
    if (!ratios.empty())
        std::printf("target, backward at most 3x forward with every edge term on (benchmark scene, cpu): %s (%s; "
                    "with only the materials wanted %s)\n\n",
                    worst <= 3.0 ? "met" : "not met", ratios.c_str(), materials.c_str());
}

// The secondary term's roulette by class (RenderOptions::secondary_survival = P) against none, on
// the benchmark scene with every parameter wanted and an adjoint of 1: for each seed, the
// gradient pass's output (every buffer) and its process CPU time, the two settings alternating.
// The sum over all gradient values of their variance over seeds, times the mean CPU time, is the
// cost of a given accuracy; the ratio (roulette over none) below 1 means less error at equal time.
int survival_compare(const Options& o, BenchScene& bs) {
    const float p = o.secondary_survival < 1.f ? o.secondary_survival : 0.1f;
    std::printf("edgepath benchmark: the secondary term's roulette by class (floor %g) against none\n", p);
    std::printf("settings : %dx%d pixels, %d spp, %d seeds, %d threads; every parameter wanted, adjoint 1\n", o.size,
                o.size, o.spp, o.seeds, o.threads);
    std::shared_ptr<const Scene> scene = build_scene(bs.desc);
    const size_t n = size_t(o.size) * o.size * 3;
    std::vector<float> adjoint(n, 1.f);
    Table table({"bounces", "survival", "variance (sum over gradients)", "cpu ms", "variance x ms", "ratio"});
    for (int bounces : o.bounces) {
        double var[2] = {0, 0}, ms[2] = {0, 0};
        std::vector<std::vector<double>> sum(2), sq(2);
        for (int seed = 0; seed < o.seeds; ++seed)
            for (int k = 0; k < 2; ++k) {
                const int which = (seed % 2 == 0) ? k : 1 - k;  // each first in turn
                AllGradients grads(bs.desc);
                RenderOptions ro;
                ro.spp = o.spp;
                ro.max_bounces = bounces;
                ro.num_threads = o.threads;
                ro.seed = uint64_t(seed + 1);
                ro.secondary_survival = which == 0 ? 1.f : p;
                if (seed == 0 && k == 0) render_gradients(*scene, ro, adjoint.data(), grads.slots);  // warm-up
                for (auto& b : grads.buffers) std::fill(b.begin(), b.end(), 0.f);
                ms[which] += time_once_cpu([&] { render_gradients(*scene, ro, adjoint.data(), grads.slots); }).cpu_ms;
                size_t i = 0;
                for (const auto& b : grads.buffers) i += b.size();
                if (sum[which].empty()) sum[which].assign(i, 0.0), sq[which].assign(i, 0.0);
                i = 0;
                for (const auto& b : grads.buffers)
                    for (float v : b) {
                        sum[which][i] += v;
                        sq[which][i] += double(v) * v;
                        ++i;
                    }
            }
        for (int k = 0; k < 2; ++k) {
            for (size_t i = 0; i < sum[k].size(); ++i) {
                const double m = sum[k][i] / o.seeds;
                var[k] += (sq[k][i] - o.seeds * m * m) / (o.seeds - 1);
            }
            ms[k] /= o.seeds;
        }
        for (int k = 0; k < 2; ++k)
            table.add({std::to_string(bounces), k == 0 ? "1" : fmt(p, 2), fmt(var[k], 6), fmt(ms[k], 1),
                       fmt(var[k] * ms[k], 4), k == 0 ? "" : fmt((var[1] * ms[1]) / (var[0] * ms[0]), 3)});
    }
    table.print("The roulette by class at equal time: variance over seeds of every gradient value (summed), "
                "times the gradient pass's mean process CPU time; ratio below 1: less error at equal time");
    return 0;
}

// FNV-1a over the bytes of the values, and their sum of magnitudes (to see what changed).
struct Digest {
    uint64_t hash = 1469598103934665603ull;
    double magnitude = 0.0;
    size_t count = 0;
    void add(const float* v, size_t n) {
        const unsigned char* b = reinterpret_cast<const unsigned char*>(v);
        for (size_t i = 0; i < n * sizeof(float); ++i) hash = (hash ^ b[i]) * 1099511628211ull;
        for (size_t i = 0; i < n; ++i) magnitude += std::abs(double(v[i]));
        count += n;
    }
    // The hash first, the pass's process CPU time last (apart, so that two runs' digests can be
    // compared with the times cut off).
    void print(const std::string& what, double cpu_ms) const {
        std::printf("%-44s %016llx  sum|g| %.9g over %zu values  | cpu ms %.1f\n", what.c_str(),
                    (unsigned long long)hash, magnitude, count, cpu_ms);
    }
};

// The passes --digest hashes, each in a function of its own, so that a profiler can collect them
// alone (valgrind --tool=callgrind --toggle-collect='*measured_gradients*'): the scene's edges
// and hierarchy are built by a pass before.
__attribute__((noinline)) void measured_gradients(const Scene& scene, const RenderOptions& ro, const float* adjoint,
                                                  const SceneGradients& slots) {
    render_gradients(scene, ro, adjoint, slots);
}
__attribute__((noinline)) void measured_derivative_image(const Scene& scene, const RenderOptions& ro,
                                                         const SceneGradients& dirs, float* out) {
    derivative_image(scene, ro, dirs, out);
}

// One reverse-mode pass (every parameter wanted, adjoint 1, after a warm-up pass) and one
// derivative image (every parameter's direction a fixed pattern) per configuration: their digests.
int digest(const Options& o, BenchScene& bs) {
    std::printf("edgepath benchmark: digests of gradient passes, %dx%d, %d spp, %d threads, survival %g\n", o.size,
                o.size, o.spp, o.threads, o.secondary_survival);
    auto one = [&](const std::string& name, const SceneDesc& desc, int spp, int bounces) {
        std::shared_ptr<const Scene> scene = build_scene(desc);
        const size_t n = size_t(image_width(*scene)) * image_height(*scene) * 3;
        std::vector<float> adjoint(n, 1.f), image(n);
        RenderOptions ro;
        ro.spp = spp;
        ro.max_bounces = bounces;
        ro.num_threads = o.threads;
        ro.seed = 3;
        ro.secondary_survival = o.secondary_survival;
        AllGradients grads(desc);
        render_gradients(*scene, ro, adjoint.data(), grads.slots);  // builds the edges and hierarchy
        for (auto& b : grads.buffers) std::fill(b.begin(), b.end(), 0.f);
        const double cpu_g = time_once_cpu([&] { measured_gradients(*scene, ro, adjoint.data(), grads.slots); }).cpu_ms;
        Digest g;
        for (const auto& b : grads.buffers) g.add(b.data(), b.size());
        g.print(name + " bounces=" + std::to_string(bounces) + " gradients", cpu_g);
        // The same buffers as directions: every parameter moves by 1 (a deterministic pattern).
        AllGradients dirs(desc);
        for (auto& b : dirs.buffers)
            for (size_t i = 0; i < b.size(); ++i) b[i] = float(int(i % 7) - 3) * 0.25f;
        SceneGradients d = dirs.slots;
        auto to_dir = [](GradSlot& s) {
            s.dir = s.grad;
            s.grad = nullptr;
        };
        for (auto& m : d.meshes)
            for (GradSlot* s : {&m.vertices, &m.uvs, &m.normals, &m.emission}) to_dir(*s);
        for (auto& m : d.materials)
            for (GradSlot* s : {&m.diffuse, &m.specular, &m.roughness}) to_dir(*s);
        to_dir(d.envmap);
        to_dir(d.envmap_rotation);
        to_dir(d.camera);
        const double cpu_d = time_once_cpu([&] { measured_derivative_image(*scene, ro, d, image.data()); }).cpu_ms;
        Digest di;
        di.add(image.data(), n);
        di.print(name + " bounces=" + std::to_string(bounces) + " derivative image", cpu_d);
    };
    for (int bounces : o.bounces) one("benchmark", bs.desc, o.spp, bounces);
    const TriangleScene tri(o.size);
    one("single triangle", tri.desc, o.spp, 1);
    return 0;
}

// Edge extraction and the edge hierarchy for about a million edges (a sphere of 1.15M triangles),
// built, then an optimisation step's share of them. `base`: a scene description whose meshes
// are replaced by the sphere.
void edges_section(const SceneDesc& base,
                   const std::function<void(const std::string&, const std::string&, const std::string&, double,
                                            const std::string&)>& record) {
    MeshData big = make_sphere(Vec3f(0, 0, 0), 1.f, 760, 760);
    SceneDesc d = base;
    d.meshes = {big.desc(0)};
    std::shared_ptr<const Scene> scene = build_scene(d);
    auto t0 = std::chrono::steady_clock::now();
    const size_t edges = scene->edges().size();
    const double extract_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    std::vector<int32_t> ids(edges);
    for (size_t i = 0; i < edges; ++i) ids[i] = int32_t(i);
    EdgeHierarchy h;
    h.build(*scene, ids);
    std::printf("\nEdges of a %s-triangle mesh: %s edges extracted (welded, classified) in %.0f ms; edge "
                "hierarchy built in %.0f ms (parallel)\n",
                grouped(uint64_t(big.num_triangles())).c_str(), grouped(uint64_t(edges)).c_str(), extract_ms,
                h.build_ms());
    record("edges", "sphere", "edges", double(edges), "");
    record("edges", "sphere", "extract_ms", extract_ms, "ms");
    record("edges", "sphere", "hierarchy_build_ms", h.build_ms(), "ms");

    // An optimisation step's share of that on the kept scene, the vertices all moved (by
    // the order of rounding: scaled by 1 +- 1e-4 in turn): the scene's update, its edge
    // list and its edge hierarchy (refit), medians of five steps after two (the first
    // move builds the refittable form).
    std::shared_ptr<Scene> kept = build_scene(d);
    std::vector<float> moved(big.vertices);
    std::vector<double> update_ms, list_ms, refit_ms;
    for (int step = 0; step < 7; ++step) {
        const float scale = 1.f + (step % 2 ? -1e-4f : 1e-4f);
        for (float& x : moved) x *= scale;
        SceneDesc md = d;
        md.meshes[0].vertices = moved.data();
        const auto a = std::chrono::steady_clock::now();
        update_scene(*kept, md);
        const auto b = std::chrono::steady_clock::now();
        const size_t n = kept->edges().size();
        const auto c = std::chrono::steady_clock::now();
        std::vector<int32_t> all(n);
        for (size_t i = 0; i < n; ++i) all[i] = int32_t(i);
        kept->edge_hierarchy(all, 0);
        const auto e = std::chrono::steady_clock::now();
        if (step < 2) continue;
        auto ms = [](auto x, auto y) { return std::chrono::duration<double, std::milli>(y - x).count(); };
        update_ms.push_back(ms(a, b));
        list_ms.push_back(ms(b, c));
        refit_ms.push_back(ms(c, e));
    }
    const SceneBuildCounts counts = scene_hierarchy_counts(*kept);
    std::printf("A vertex step on it (kept scene, every vertex moved; medians of 5 steps): scene update %.0f ms, "
                "edge list %.0f ms, edge hierarchy %.0f ms (hierarchy builds %llu, refits %llu)\n",
                median(update_ms), median(list_ms), median(refit_ms), (unsigned long long)counts.builds,
                (unsigned long long)counts.refits);
    record("edges", "sphere vertex step", "scene_update_ms", median(update_ms), "ms");
    record("edges", "sphere vertex step", "edge_list_ms", median(list_ms), "ms");
    record("edges", "sphere vertex step", "hierarchy_refit_ms", median(refit_ms), "ms");

    // A whole optimisation step on it, under the base scene's lamps: the vertices moved as
    // above, the scene updated, an image rendered and the gradient pass w.r.t. the vertices, at
    // 16x16 and 1 spp, to show what a step costs whatever its image (medians of five steps after
    // two). A scene of its own: its hierarchy holds the wanted mesh's edges in a subtree apart.
    SceneDesc ld = d;
    for (const MeshDesc& m : base.meshes)
        if (m.emission.num_values() > 0) ld.meshes.push_back(m);
    ld.camera.width = ld.camera.height = 16;
    ld.camera.crop_width = ld.camera.crop_height = 0;
    std::shared_ptr<Scene> stepped = build_scene(ld);
    std::vector<float> step_v(big.vertices), image(16 * 16 * 3), adjoint(16 * 16 * 3, 1.f), grad(step_v.size());
    SceneGradients slots;
    slots.meshes.resize(ld.meshes.size());
    slots.meshes[0].vertices.grad = grad.data();
    number_slots(slots);
    RenderOptions ro;
    ro.spp = 1;
    ro.max_bounces = 1;
    ro.seed = 3;
    std::vector<double> move_ms, render_ms, gradient_ms;
    for (int step = 0; step < 7; ++step) {
        const float scale = 1.f + (step % 2 ? -1e-4f : 1e-4f);
        for (float& x : step_v) x *= scale;
        SceneDesc md = ld;
        md.meshes[0].vertices = step_v.data();
        const auto a = std::chrono::steady_clock::now();
        update_scene(*stepped, md);
        const auto b = std::chrono::steady_clock::now();
        render(*stepped, ro, image.data());
        const auto c = std::chrono::steady_clock::now();
        render_gradients(*stepped, ro, adjoint.data(), slots);
        const auto e = std::chrono::steady_clock::now();
        if (step < 2) continue;
        auto ms = [](auto x, auto y) { return std::chrono::duration<double, std::milli>(y - x).count(); };
        move_ms.push_back(ms(a, b));
        render_ms.push_back(ms(b, c));
        gradient_ms.push_back(ms(c, e));
    }
    std::printf("A whole vertex step on it under a lamp, 16x16, 1 spp (medians of 5 steps): scene update %.0f ms, "
                "render %.0f ms, gradient pass w.r.t. the vertices %.0f ms\n",
                median(move_ms), median(render_ms), median(gradient_ms));
    record("edges", "sphere vertex step 16x16", "scene_update_ms", median(move_ms), "ms");
    record("edges", "sphere vertex step 16x16", "render_ms", median(render_ms), "ms");
    record("edges", "sphere vertex step 16x16", "gradient_ms", median(gradient_ms), "ms");

    // A camera step on it (a pose optimisation over a static scan): eight views around the
    // sphere, 16x16 at 1 spp, the gradient pass w.r.t. the camera of each (what a view costs
    // whatever its image; medians of five steps after two).
    std::vector<float> cam_grad(kCameraParams);
    SceneGradients cam_slots;
    cam_slots.meshes.resize(ld.meshes.size());
    cam_slots.camera.grad = cam_grad.data();
    number_slots(cam_slots);
    std::vector<double> view_ms;
    for (int step = 0; step < 7; ++step) {
        const auto a = std::chrono::steady_clock::now();
        for (int v = 0; v < 8; ++v) {
            CameraDesc c = ld.camera;
            const float angle = 2.f * kPi * float(v) / 8.f;
            c.position[0] = 3.5f * std::sin(angle), c.position[1] = 1.5f, c.position[2] = 3.5f * std::cos(angle);
            c.look_at[0] = c.look_at[1] = c.look_at[2] = 0.f;
            set_scene_camera(*stepped, c);
            render_gradients(*stepped, ro, adjoint.data(), cam_slots);
        }
        const auto e = std::chrono::steady_clock::now();
        if (step >= 2) view_ms.push_back(std::chrono::duration<double, std::milli>(e - a).count() / 8.0);
    }
    std::printf("A camera step on it, 8 views 16x16, 1 spp (medians of 5 steps): gradient pass w.r.t. the camera "
                "%.0f ms per view\n", median(view_ms));
    record("edges", "sphere camera step 16x16", "gradient_ms_per_view", median(view_ms), "ms");
}

int main(int argc, char** argv) {
    const Options o = parse_options(argc, argv);
    if (o.digest) {
        BenchScene bs;
        build_bench_scene(bs, o);
        return digest(o, bs);
    }
    if (o.backward_memory) {
        BenchScene bs;
        build_bench_scene(bs, o);
        return backward_memory(o, bs);
    }
    if (o.secondary_only) return secondary_only(o);
    if (o.edges_only) {
        const TriangleScene tri(8);
        edges_section(tri.desc, [](const std::string&, const std::string&, const std::string&, double,
                                   const std::string&) {});
        return 0;
    }
    if (o.survival_compare) {
        BenchScene bs;
        build_bench_scene(bs, o);
        return survival_compare(o, bs);
    }
    if (o.backward_only) {
        BenchScene bs;
        build_bench_scene(bs, o);
        backward_section(o, bs, [](const std::string&, const std::string&, const std::string&, double,
                                   const std::string&) {});
        return 0;
    }
    std::vector<Record> records;
    auto record = [&](const std::string& section, const std::string& config, const std::string& metric, double v,
                      const std::string& unit) { records.push_back({section, config, metric, v, unit}); };

    auto write_csv = [&] {
        if (o.csv_path.empty()) return;
        std::ofstream f(o.csv_path);
        f << "section,config,metric,value,unit\n";
        for (const Record& r : records) f << r.section << ',' << r.config << ',' << r.metric << ',' << r.value << ',' << r.unit << '\n';
        if (!f) throw std::runtime_error(o.csv_path + ": could not write");
    };

    try {
        const int all_cores = tbb::info::default_concurrency();
        std::printf("edgepath forward benchmark\n");
        std::printf("machine  : %s; %u hardware threads, oneTBB default concurrency %d; Embree %s; load %s\n",
                    cpu_model().c_str(), std::thread::hardware_concurrency(), all_cores, RTC_VERSION_STRING,
                    load_average().c_str());
        record("machine", "", "hardware_threads", std::thread::hardware_concurrency(), "");
        record("machine", "", "tbb_default_concurrency", all_cores, "");

        BenchScene bs;
        auto t_setup = Clock::now();
        build_bench_scene(bs, o);
        double setup_ms = std::chrono::duration<double, std::milli>(Clock::now() - t_setup).count();
        std::string parts;
        for (size_t i = 0; i < bs.parts.size(); ++i) parts += (i ? ", " : "") + bs.parts[i];
        std::printf("scene    : %s triangles in %zu meshes (%s); sky %dx%d\n", grouped(uint64_t(bs.num_triangles())).c_str(),
                    bs.desc.meshes.size(), parts.c_str(), bs.desc.envmap.values.height, bs.desc.envmap.values.width);
        std::printf("settings : %dx%d pixels, %d spp, median of %d runs after one warm-up\n", o.size, o.size, o.spp,
                    o.runs);
        record("scene", "", "triangles", double(bs.num_triangles()), "");

        // build_scene: validation, BVH, light distributions (one cold build with --render-only).
        std::shared_ptr<const Scene> scene;
        std::vector<double> build_times;
        const int builds = o.render_only ? 1 : o.runs + 1;
        for (int i = 0; i < builds; ++i) {
            scene.reset();
            auto t0 = Clock::now();
            scene = build_scene(bs.desc);
            if (i > 0 || builds == 1)
                build_times.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
        }
        double build_ms = median(build_times);
        std::printf("build    : procedural meshes %.1f ms (once); build_scene %.1f ms (%s, all cores)\n", setup_ms,
                    build_ms, builds == 1 ? "one cold build" : "median");
        record("build", "", "procedural_meshes_ms", setup_ms, "ms");
        record("build", "", "build_scene_ms", build_ms, "ms");

        std::vector<int> thread_configs = {o.threads};
        if (o.all_cores) thread_configs.push_back(0);

        const int W = image_width(*scene), H = image_height(*scene);
        std::vector<float> image(size_t(W) * H * 3);
        std::vector<ForwardResult> results;
        for (int bounces : o.bounces) {
            RenderOptions ro;
            ro.spp = o.spp;
            ro.max_bounces = bounces;
            ro.seed = 1;
            // The rays Embree alone traces: counts from a render, generated once per bounce count.
            ro.num_threads = o.threads;
            RenderStats counts = render(*scene, ro, image.data());
            RaySet rays = o.render_only ? RaySet() : make_rays(*scene, ro, counts);
            for (int threads : thread_configs) {
                ForwardResult r{};
                r.threads_requested = threads;
                r.threads = threads > 0 ? threads : all_cores;
                r.bounces = bounces;
                ro.num_threads = threads;
                if (o.render_only) {
                    r.render_ms = time_ms(o.runs, [&] { r.stats = render(*scene, ro, image.data()); });
                    results.push_back(r);
                    continue;
                }
                // Renderer and Embree alone take turns within each run, so that both see the same
                // machine load; the fraction is the median of the per-run fractions.
                tbb::task_arena arena(r.threads);
                const size_t chunk = size_t(kRenderTile) * kRenderTile * size_t(o.spp);
                const Tracing tracing = tracing_of(ro);  // the BVH the render traces
                RTCScene rtc = scene->bvh(tracing);
                std::vector<double> t_render, t_camera, t_packets, t_shadow, t_bounce, fractions, cpu_render, cpu_embree,
                    cpu_fractions;
                for (int run = 0; run <= o.runs; ++run) {  // run 0 warms up
                    Timing tr = time_once_cpu([&] { r.stats = render(*scene, ro, image.data()); });
                    Timing tc = time_once_cpu([&] { r.embree_hits = trace_rays(rtc, rays.camera, false, arena, chunk); });
                    Timing tp = time_once_cpu([&] { trace_camera_packets(*scene, tracing, rays.camera, arena, chunk); });
                    Timing ts = time_once_cpu([&] { r.embree_hits += trace_rays(rtc, rays.shadow, true, arena, chunk); });
                    Timing tb = time_once_cpu([&] { r.embree_hits += trace_rays(rtc, rays.bounce, false, arena, chunk); });
                    if (run == 0) continue;
                    t_render.push_back(tr.wall_ms);
                    t_camera.push_back(tc.wall_ms);
                    t_packets.push_back(tp.wall_ms);
                    t_shadow.push_back(ts.wall_ms);
                    t_bounce.push_back(tb.wall_ms);
                    fractions.push_back((tc.wall_ms + ts.wall_ms + tb.wall_ms) / tr.wall_ms);
                    const double ce = tc.cpu_ms + ts.cpu_ms + tb.cpu_ms;
                    cpu_render.push_back(tr.cpu_ms);
                    cpu_embree.push_back(ce);
                    cpu_fractions.push_back(ce / tr.cpu_ms);
                }
                r.render_ms = median(t_render);
                r.embree_camera_ms = median(t_camera);
                r.embree_packets_ms = median(t_packets);
                r.embree_shadow_ms = median(t_shadow);
                r.embree_bounce_ms = median(t_bounce);
                r.embree_ms = r.embree_camera_ms + r.embree_shadow_ms + r.embree_bounce_ms;
                r.fraction = median(fractions);
                r.render_cpu_ms = median(cpu_render);
                r.embree_cpu_ms = median(cpu_embree);
                r.fraction_cpu = median(cpu_fractions);
                if (rays.camera.size() != r.stats.camera_rays || rays.shadow.size() != r.stats.shadow_rays ||
                    rays.bounce.size() != r.stats.bounce_rays)
                    std::fprintf(stderr, "warning: Embree-only ray counts differ from the renderer's\n");
                results.push_back(r);
            }
        }

        // Image sanity: the mean must be finite and positive.
        double mean = 0.0;
        for (float v : image) mean += v;
        mean /= double(image.size());
        if (!o.image_path.empty()) write_image(o.image_path, image.data(), H, W, 3);

        Table forward({"threads", "bounces", "render ms", "camera rays", "shadow rays", "bounce rays", "Mrays/s",
                       "embree ms", "embree Mrays/s", "embree/render", "(cpu time)"});
        Table split({"threads", "bounces", "camera ms", "camera ms, packets", "shadow ms", "bounce ms", "embree ms", "render ms",
                     "non-embree ms", "ns/ray outside embree"});
        for (const ForwardResult& r : results) {
            const uint64_t rays = r.stats.camera_rays + r.stats.shadow_rays + r.stats.bounce_rays;
            const std::string threads = r.threads_requested > 0 ? std::to_string(r.threads)
                                                                : "all (" + std::to_string(r.threads) + ")";
            const std::string config = "threads=" + std::to_string(r.threads) + (r.threads_requested ? "" : "(all)") +
                                       " bounces=" + std::to_string(r.bounces);
            const double fraction = r.fraction;
            const double outside = r.render_ms - r.embree_ms;
            record("forward", config, "render_ms", r.render_ms, "ms");
            record("forward", config, "camera_rays", double(r.stats.camera_rays), "rays");
            record("forward", config, "shadow_rays", double(r.stats.shadow_rays), "rays");
            record("forward", config, "bounce_rays", double(r.stats.bounce_rays), "rays");
            record("forward", config, "rays_per_second", rays / r.render_ms * 1e3, "rays/s");
            if (o.render_only) {
                forward.add({threads, std::to_string(r.bounces), fmt(r.render_ms, 1), grouped(r.stats.camera_rays),
                             grouped(r.stats.shadow_rays), grouped(r.stats.bounce_rays),
                             fmt(rays / r.render_ms * 1e-3, 2), "-", "-", "-", "-"});
                continue;
            }
            forward.add({threads, std::to_string(r.bounces), fmt(r.render_ms, 1), grouped(r.stats.camera_rays),
                         grouped(r.stats.shadow_rays), grouped(r.stats.bounce_rays), fmt(rays / r.render_ms * 1e-3, 2),
                         fmt(r.embree_ms, 1), fmt(rays / r.embree_ms * 1e-3, 2), fmt(fraction, 2),
                         fmt(r.fraction_cpu, 2)});
            split.add({threads, std::to_string(r.bounces), fmt(r.embree_camera_ms, 1), fmt(r.embree_packets_ms, 1),
                       fmt(r.embree_shadow_ms, 1),
                       fmt(r.embree_bounce_ms, 1), fmt(r.embree_ms, 1), fmt(r.render_ms, 1), fmt(outside, 1),
                       fmt(outside * 1e6 / double(rays) * r.threads, 0)});
            record("embree_only", config, "camera_ms", r.embree_camera_ms, "ms");
            record("embree_only", config, "camera_packets_ms", r.embree_packets_ms, "ms");
            record("embree_only", config, "shadow_ms", r.embree_shadow_ms, "ms");
            record("embree_only", config, "bounce_ms", r.embree_bounce_ms, "ms");
            record("embree_only", config, "total_ms", r.embree_ms, "ms");
            record("embree_only", config, "rays_per_second", rays / r.embree_ms * 1e3, "rays/s");
            record("embree_only", config, "fraction_of_render", fraction, "");
            record("forward", config, "render_cpu_ms", r.render_cpu_ms, "ms");
            record("embree_only", config, "total_cpu_ms", r.embree_cpu_ms, "ms");
            record("embree_only", config, "fraction_of_render_cpu", r.fraction_cpu, "");
        }
        forward.print("Forward pass, " + std::to_string(o.spp) + " spp, " + std::to_string(W) + "x" +
                      std::to_string(H) + " (embree/render: Embree-only time over renderer time, wall and CPU; "
                      "target >= 0.5)");
        if (!o.render_only)
            split.print("Embree-only time by ray kind (camera rays one by one, and in packets of " +
                        std::to_string(kPacketSize) + " as the renderer traces them; the total counts them one by one), "
                        "and the renderer's time outside Embree (per ray, per thread)");
        if (o.forward_only) {
            write_csv();
            return 0;
        }

        TriangleScene tri(256);
        backward_section(o, bs, record);

        // Edge sampling against the baseline: the triangle's vertex gradients over 16 seeds.
        const EdgeVariance imp = edge_variance(tri.desc, EdgeSampling::Importance, o.threads, 16),
                           uni = edge_variance(tri.desc, EdgeSampling::Uniform, o.threads, 16);
        const double ratio = (uni.variance * uni.ms) / (imp.variance * imp.ms),
                     edge_ratio = (uni.edge_variance * uni.edge_ms) / (imp.edge_variance * imp.edge_ms);
        Table variance({"edge sampling", "backward ms", "gradient variance", "variance x time", "edge pass ms",
                        "edge term variance", "variance x time"});
        for (const auto& [label, v] : {std::pair<const char*, const EdgeVariance&>{"silhouettes, film length, stratified", imp},
                                       std::pair<const char*, const EdgeVariance&>{"uniform over all edges (baseline)", uni}})
            variance.add({label, fmt(v.ms, 1), fmt(v.variance, 2), fmt(v.variance * v.ms, 0), fmt(v.edge_ms, 1),
                          fmt(v.edge_variance, 3), fmt(v.edge_variance * v.edge_ms, 1)});
        variance.print("Single triangle 256x256, 4 spp, 1 bounce: variance of the triangle's vertex gradients over 16 "
                       "seeds (whole gradient, and the edge term alone); at equal time the baseline's variance is " +
                       fmt(ratio, 1) + "x ours for the whole gradient, " + fmt(edge_ratio, 0) + "x for the edge term");
        record("edge_variance", "single triangle importance", "variance", imp.variance, "");
        record("edge_variance", "single triangle uniform", "variance", uni.variance, "");
        record("edge_variance", "single triangle", "equal_time_ratio", ratio, "");
        record("edge_variance", "single triangle", "edge_term_equal_time_ratio", edge_ratio, "");

        edges_section(tri.desc, record);

        record("memory", "", "peak_rss_mib", peak_rss_mib(), "MiB");
        std::printf("\nlast image mean %.4f; peak RSS %.0f MiB\n", mean, peak_rss_mib());
        if (!(std::isfinite(mean) && mean > 0.0)) {
            std::fprintf(stderr, "error: the rendered image is black or not finite\n");
            return 1;
        }

        write_csv();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "error: %s\n", e.what());
        return 1;
    }
    return 0;
}
