"""edgepath and Mitsuba 3 side by side, on the same scene files.

Each scene is written as a Mitsuba XML file with PLY meshes (welded: every vertex shared by the
triangles around it, so that both renderers see the same topology), loaded by Mitsuba
(``mi.load_file``) and by edgepath (``ep.load_mitsuba``), and rendered by both at equal samples
per pixel, the two alternating run by run so that both see the same machine load. Times are
medians of wall time and of process CPU time (the steadier on a busy machine); the ratio is
Mitsuba's time over edgepath's (above 1: edgepath is faster). Each call is timed as a user
makes it: edgepath's includes building the scene (BVH, light tables), Mitsuba's its kernel
tracing (its compiled kernels are cached after the first, untimed, call).

    python bench/mitsuba_compare.py [--runs N] [--size N] [--spp N] [--threads N] [--no-forward | --no-gradient]

Needs the ``mitsuba`` package (``pip install -e '.[bench]'``) and, for its ``llvm_ad_rgb``
variant, a libLLVM of version 16 or newer (Debian: ``apt-get install libllvm19``; found by
itself in the usual folders, or named by DRJIT_LIBLLVM_PATH). Without them it says so in one
line and exits 0.

Scenes: a Cornell box (welded walls, boxes and a sphere, 32k triangles, one area light); a
100k-triangle bumpy sphere standing in for a scan, on a floor under an area light and a
constant sky. Forward: time at equal spp and at equal noise (each renderer's per-pixel variance
from two images of other seeds, times its time). Gradients: a welded cube casting a shadow from
a small area light, the same cube over a glossy floor (a GGX roughplastic: the light's
highlight cut by the cube's edge, the cube's reflection, the shadow), and a faceted sphere of
50k triangles in view with its shadow; the derivative image of the occluder's translation
along x (Mitsuba: ``prb_projective``, forward mode; edgepath:
``derivative_image``) at about equal CPU time, against edgepath's image at many more samples
(the two renderers' image sums are printed beside it: they agree within noise).
"""

import argparse
import glob
import math
import os
import statistics
import sys
import tempfile
import time

try:
    import numpy as np
except ImportError:  # not the project's environment: main() says so
    np = None

LLVM_GLOBS = ["/usr/lib/x86_64-linux-gnu/libLLVM-1[6-9]*.so*", "/usr/lib/x86_64-linux-gnu/libLLVM-[2-9][0-9]*.so*",
              "/usr/lib/llvm-1[6-9]/lib/libLLVM*.so*", "/usr/lib/llvm-[2-9][0-9]/lib/libLLVM*.so*",
              "/usr/lib/aarch64-linux-gnu/libLLVM-1[6-9]*.so*"]


def find_libllvm():
    """A libLLVM that Dr.Jit's LLVM backend accepts (16 or newer), or None."""
    for pattern in LLVM_GLOBS:
        found = sorted(glob.glob(pattern))
        if found:
            return found[-1]
    return None


def import_mitsuba():
    """Mitsuba with its llvm_ad_rgb variant, or (None, why)."""
    try:
        import mitsuba as mi
    except ImportError:
        return None, "the mitsuba package is not installed (pip install -e '.[bench]')"
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = find_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
    try:
        mi.set_variant("llvm_ad_rgb")
    except Exception as e:  # no usable libLLVM: Dr.Jit raises its own error types
        return None, f"Mitsuba's llvm_ad_rgb variant is unavailable ({str(e).splitlines()[0]}); it needs libLLVM 16 or newer (Debian: libllvm19), or DRJIT_LIBLLVM_PATH"
    return mi, ""


# ---------------------------------------------------------------------------------------------
# Welded meshes

def grid(corner, u, v, n):
    """A parallelogram corner + s u + t v, s, t in [0, 1], as an n x n grid of quads; face
    normal along u x v."""
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    p = np.asarray(corner) + s[..., None] * np.asarray(u) + t[..., None] * np.asarray(v)
    i = np.arange((n + 1) * (n + 1)).reshape(n + 1, n + 1)
    a, b, c, d = i[:-1, :-1], i[1:, :-1], i[1:, 1:], i[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return p.reshape(-1, 3), faces


def box(lo, hi):
    """An axis-aligned box, 8 shared vertices, 12 triangles, faces outward."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if (k >> j) & 1 else lo)[j] for j in range(3)] for k in range(8)])
    f = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    return v, f


def sphere(center, radius, rings, segments, bumps=0.0):
    """A UV sphere with shared poles and seam, faces outward; `bumps` displaces it radially by a
    few low-frequency waves (a stand-in for a scanned object)."""
    theta = np.linspace(0, math.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * math.pi, segments, endpoint=False)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    d = np.concatenate([[[0, 1, 0]], d, [[0, -1, 0]]])
    r = radius * (1 + bumps * np.sin(5 * d[:, 0]) * np.sin(4 * d[:, 1]) * np.sin(6 * d[:, 2]))
    v = np.asarray(center) + d * r[:, None]
    last = len(v) - 1
    ring = lambda k: 1 + k * segments + np.arange(segments)
    faces = [np.stack([np.zeros(segments, int), ring(0)[(np.arange(segments) + 1) % segments], ring(0)], -1)]
    for k in range(rings - 2):
        a, b = ring(k), ring(k + 1)
        an, bn = np.roll(a, -1), np.roll(b, -1)
        faces += [np.stack([a, an, bn], -1), np.stack([a, bn, b], -1)]
    a = ring(rings - 2)
    faces.append(np.stack([a, np.roll(a, -1), np.full(segments, last)], -1))
    return v, np.concatenate(faces)


def write_ply(path, vertices, faces):
    vertices = np.asarray(vertices, "<f4")
    faces = np.asarray(faces)
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
        rows["n"] = 3
        rows["i"] = faces
        f.write(vertices.tobytes())
        f.write(rows.tobytes())
    return len(faces)


# ---------------------------------------------------------------------------------------------
# Scene files

def scene_xml(shapes, camera, size, spp, max_depth, integrator="path", sky=None):
    """shapes: (ply file, bsdf xml, emitter radiance or None); camera: (origin, target, fov[, up])."""
    origin, target, fov, up = camera if len(camera) == 4 else camera + ("0, 1, 0",)
    parts = [f'<scene version="3.0.0">',
             f'<integrator type="{integrator}"><integer name="max_depth" value="{max_depth}"/></integrator>',
             f'<sensor type="perspective"><float name="fov" value="{fov}"/>',
             f'<transform name="to_world"><lookat origin="{origin}" target="{target}" up="{up}"/></transform>',
             f'<sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>',
             f'<film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>',
             '<rfilter type="box"/></film></sensor>']
    for k, (ply, bsdf, radiance) in enumerate(shapes):
        emitter = f'<emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter>' if radiance else ""
        parts.append(f'<shape type="ply" id="shape{k}"><string name="filename" value="{ply}"/>'
                     f'<boolean name="face_normals" value="true"/>{bsdf}{emitter}</shape>')
    if sky:
        parts.append(f'<emitter type="constant"><rgb name="radiance" value="{sky}"/></emitter>')
    parts.append("</scene>")
    return "\n".join(parts)


def diffuse(rgb):
    return f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb}"/></bsdf>'


def make_cornell(folder, size, spp, max_depth):
    L = 2.0
    white, red, green = diffuse("0.73, 0.73, 0.73"), diffuse("0.63, 0.065, 0.05"), diffuse("0.14, 0.45, 0.091")
    n = 40  # 2 n^2 triangles per wall
    walls = [("floor", grid([-1, 0, -1], [0, 0, L], [L, 0, 0], n), white),
             ("ceiling", grid([-1, L, -1], [L, 0, 0], [0, 0, L], n), white),
             ("back", grid([-1, 0, -1], [L, 0, 0], [0, L, 0], n), white),
             ("left", grid([-1, 0, -1], [0, L, 0], [0, 0, L], n), red),
             ("right", grid([1, 0, -1], [0, 0, L], [0, L, 0], n), green),
             ("tall box", box([-0.6, 0, -0.6], [-0.05, 1.2, -0.05]), white),
             ("sphere", sphere([0.45, 0.35, 0.3], 0.35, 64, 128), white),
             ("light", grid([-0.25, L - 0.01, -0.25], [0.5, 0, 0], [0, 0, 0.5], 1), diffuse("0, 0, 0"))]
    shapes, triangles = [], 0
    for k, (name, (v, f), bsdf) in enumerate(walls):
        path = os.path.join(folder, f"cornell{k}.ply")
        triangles += write_ply(path, v, f)
        shapes.append((path, bsdf, "17, 12, 4" if name == "light" else None))
    xml = scene_xml(shapes, ("0, 1, 3.9", "0, 1, 0", 39.3), size, spp, max_depth)
    return xml, triangles


def make_scan(folder, size, spp, max_depth):
    v, f = sphere([0, 0.75, 0], 0.7, 224, 224, bumps=0.12)
    shapes, triangles = [], 0
    path = os.path.join(folder, "scan.ply")
    triangles += write_ply(path, v, f)
    shapes.append((path, diffuse("0.6, 0.5, 0.4"), None))
    path = os.path.join(folder, "scan_floor.ply")
    triangles += write_ply(path, *grid([-4, 0, -4], [0, 0, 8], [8, 0, 0], 1))
    shapes.append((path, diffuse("0.5, 0.5, 0.5"), None))
    path = os.path.join(folder, "scan_light.ply")
    triangles += write_ply(path, *grid([-0.5, 3, -0.5], [1, 0, 0], [0, 0, 1], 1))
    shapes.append((path, diffuse("0, 0, 0"), "20, 20, 20"))
    xml = scene_xml(shapes, ("0, 1.6, 3.2", "0, 0.7, 0", 40), size, spp, max_depth, sky="0.2, 0.25, 0.3")
    return xml, triangles


def make_shadow(folder, size, spp, max_depth, floor_bsdf=None, occluder=None):
    """A welded cube (or `occluder`) floating over a floor, a small area light above: seen from
    above, the cube out of view, only its shadow in the image (and, on a glossy floor, its
    reflection)."""
    shapes = []
    for name, (v, f), bsdf, radiance in [
            ("cube", occluder or box([-0.4, 0.8, -0.4], [0.4, 1.6, 0.4]), diffuse("0.5, 0.5, 0.5"), None),
            ("floor", grid([-5, 0, -5], [0, 0, 10], [10, 0, 0], 1), floor_bsdf or diffuse("0.7, 0.7, 0.7"), None),
            ("light", grid([-0.15, 3.5, -0.15], [0.3, 0, 0], [0, 0, 0.3], 1), diffuse("0, 0, 0"), "300, 300, 300")]:
        path = os.path.join(folder, f"shadow_{name}.ply")
        write_ply(path, v, f)
        shapes.append((path, bsdf, radiance))
    xml = scene_xml(shapes, ("1.7, 3, 0", "1.7, 0, 0", 50, "0, 0, 1"), size, spp, max_depth, integrator="prb_projective")
    return xml


GLOSSY_FLOOR = ('<bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
                '<float name="alpha" value="0.08"/>'
                '<rgb name="diffuse_reflectance" value="0.3, 0.3, 0.3"/></bsdf>')


def make_glossy(folder, size, spp, max_depth):
    """The shadow scene on a glossy floor (Mitsuba's roughplastic, GGX alpha 0.08): the camera
    sees the light's highlight in the floor with the cube's top edge cutting into it, the
    cube's lit top face reflected beside it, and the shadow."""
    return make_shadow(folder, size, spp, max_depth, floor_bsdf=GLOSSY_FLOOR)


def make_faceted_shadow(folder, size, spp, max_depth):
    """A detailed occluder: a welded, flat-shaded sphere of 50k triangles in view, over the
    floor, and its shadow. From a floor point most of its edges lie inside the light's cone but
    cast no shadow there (the light strategy's edges are those near the light's triangles)."""
    return make_shadow(folder, size, spp, max_depth, occluder=sphere([1.5, 1.0, 0], 0.45, 125, 200))


# ---------------------------------------------------------------------------------------------
# Timing

def timed(fn):
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def interleaved(runs, fns):
    """Runs each fn once untimed, then `runs` rounds of all of them in turn; returns the median
    (wall, cpu) seconds of each, and each one's last two results (of its last two calls)."""
    last = [[None, fn()] for fn in fns]
    wall = [[] for _ in fns]
    cpu = [[] for _ in fns]
    for _ in range(runs):
        for k, fn in enumerate(fns):
            out, w, c = timed(fn)
            last[k] = [last[k][1], out]
            wall[k].append(w)
            cpu[k].append(c)
    return [(statistics.median(w), statistics.median(c)) for w, c in zip(wall, cpu)], last


def noise_variance(a, b):
    """The per-pixel variance of a renderer's image at its spp, from two images of other seeds:
    E[(a - b)^2] = 2 var, averaged over the pixels and colours."""
    return float(np.mean((a - b) ** 2) / 2)


def table(title, header, rows):
    widths = [max(len(str(r[c])) for r in [header] + rows) for c in range(len(header))]
    print(f"\n{title}")
    line = lambda r: "  ".join(str(x).rjust(w) for x, w in zip(r, widths))
    print(line(header))
    print("-" * len(line(header)))
    for r in rows:
        print(line(r))


# ---------------------------------------------------------------------------------------------

def rays_per_sample(scene, size, spp, bounces, threads=None):
    """edgepath's rays per camera sample on `scene` (camera, shadow, bounce), from the core's
    counters. Mitsuba's path tracer traces one shadow ray per scattering vertex (one emitter
    sample); edgepath traces one towards the area lights and one towards the environment where
    a scene has both (docs/gradients.md), so at equal spp it may trace more rays (a uniform sky,
    as both scenes here have, gets none: the BSDF's samples find it, docs/conventions.md)."""
    from edgepath.render import flatten_scene, render_flat, render_options
    options = render_options(spp=spp, max_bounces=bounces, num_threads=threads)
    options.replayable = False  # as ep.render's images without a gradient, which the table times
    _, stats = render_flat(flatten_scene(scene), options)
    samples = size * size * spp
    return tuple(stats[k] / samples for k in ("camera_rays", "shadow_rays", "bounce_rays"))


def forward(mi, dr, ep, args, folder):
    rows = []
    for name, make in [("Cornell box", make_cornell), ("100k-triangle scan", make_scan)]:
        xml, triangles = make(folder, args.size, args.spp, args.bounces + 1)
        path = os.path.join(folder, name.split()[0] + ".xml")
        with open(path, "w") as f:
            f.write(xml)
        ms = mi.load_file(path)
        loaded = ep.load_mitsuba(path)

        def run_mitsuba(seed=[0]):
            seed[0] += 1
            img = mi.render(ms, spp=args.spp, seed=seed[0])
            dr.eval(img)
            dr.sync_thread()
            return img

        def run_edgepath(seed=[0]):
            seed[0] += 1
            return ep.render(loaded.scene, spp=args.spp, max_bounces=args.bounces, seed=seed[0],
                             num_threads=args.threads)

        (m, e), (m_imgs, e_imgs) = interleaved(args.runs, [run_mitsuba, run_edgepath])
        m_imgs = [np.asarray(img, dtype=np.float64)[..., :3] for img in m_imgs]
        e_imgs = [img.double().numpy() for img in e_imgs]
        m_img, e_img = m_imgs[1], e_imgs[1]
        diff = abs(m_img.mean() - e_img.mean()) / max(m_img.mean(), 1e-12)
        # Equal noise: the time each needs for the same variance is its time x its variance
        # (variance falls as 1 / spp); the ratio is Mitsuba's over edgepath's.
        m_var, e_var = noise_variance(*m_imgs), noise_variance(*e_imgs)
        rays = rays_per_sample(loaded.scene, args.size, 1, args.bounces, args.threads)
        rows.append([f"{name} ({triangles:,} tri)", f"{e[0]:.3f}", f"{m[0]:.3f}", f"{m[0] / e[0]:.2f}",
                     f"{e[1]:.3f}", f"{m[1]:.3f}", f"{m[1] / e[1]:.2f}", f"{100 * diff:.1f}%",
                     f"{e_var / m_var:.2f}", f"{(m_var * m[1]) / (e_var * e[1]):.2f}",
                     " / ".join(f"{r:.2f}" for r in rays)])
    table(f"Forward, {args.size}x{args.size}, {args.spp} spp, max_bounces {args.bounces} (Mitsuba max_depth "
          f"{args.bounces + 1}), {args.threads} threads, median of {args.runs} interleaved runs; variance per "
          f"pixel from two images of other seeds, equal-noise ratio = Mitsuba's cpu x variance over edgepath's",
          ["scene", "edgepath s", "Mitsuba s", "ratio", "edgepath cpu s", "Mitsuba cpu s", "cpu ratio",
           "image means differ", "variance ratio (edgepath / Mitsuba)", "equal-noise cpu ratio",
           "edgepath rays/sample (camera / shadow / bounce)"], rows)
    # Issue 18's target: the forward pass at least as fast as Mitsuba's at equal spp, in CPU time.
    ratios = [float(r[6]) for r in rows]
    verdict = "met" if min(ratios) >= 1 else f"not met (edgepath at {min(ratios):.2f}x Mitsuba's speed at worst)"
    print(f"target, forward at least as fast as Mitsuba at equal spp (cpu ratio >= 1 on both scenes): {verdict}")


def gradient_at_equal_time(mi, dr, ep, args, folder, title, make, bounces):
    """Derivative image of the cube's x translation, at about equal CPU time, against one
    reference: edgepath's at many samples (cheap; that the two renderers agree on it is checked
    by the images' sums, printed with the table). Returns Mitsuba's MSE over edgepath's."""
    import torch
    size = args.grad_size
    path = os.path.join(folder, "gradient.xml")
    with open(path, "w") as f:
        f.write(make(folder, size, 4, bounces + 1))
    ms = mi.load_file(path)
    params = mi.traverse(ms)
    key = "shape0.vertex_positions"
    base = mi.Float(params[key])
    loaded = ep.load_mitsuba(path)
    cube = loaded.shapes["shape0"]
    direction = torch.zeros_like(cube.vertices)
    direction[:, 0] = 1

    def mitsuba_derivative(spp, seed):
        t = mi.Float(0.0)
        dr.enable_grad(t)
        dr.set_grad(t, 1.0)
        moved = dr.unravel(mi.Point3f, base)
        moved.x += t
        params[key] = dr.ravel(moved)
        params.update()
        img = mi.render(ms, params, spp=spp, seed=seed)
        dr.forward_to(img)
        g = dr.grad(img)
        dr.eval(g)
        dr.sync_thread()
        return np.asarray(g, dtype=np.float64)[..., :3]

    def edgepath_derivative(spp, seed):
        return ep.derivative_image(loaded.scene, cube.vertices, direction, spp=spp, max_bounces=bounces,
                                   seed=seed, num_threads=args.threads).double().numpy()

    ref = edgepath_derivative(args.grad_ref_spp, 1000)
    # Mitsuba's time at its spp; edgepath's time as a + b spp from two sample counts, solved
    # for the spp that takes as long.
    (m_t, e_lo, e_hi), _ = interleaved(args.runs, [lambda: mitsuba_derivative(args.grad_spp, 1),
                                                    lambda: edgepath_derivative(args.grad_spp, 1),
                                                    lambda: edgepath_derivative(8 * args.grad_spp, 1)])
    per_spp = max((e_hi[1] - e_lo[1]) / (7 * args.grad_spp), 1e-9)
    e_spp = int(min(max(1, round(args.grad_spp + (m_t[1] - e_lo[1]) / per_spp)), args.grad_ref_spp // 4))
    scale = np.abs(ref).mean()
    rows = []
    for name, fn, spp in [("Mitsuba prb_projective", mitsuba_derivative, args.grad_spp),
                          ("edgepath", edgepath_derivative, e_spp)]:
        errs, times, total = [], [], 0.0
        for s in range(args.seeds):
            img, w, c = timed(lambda: fn(spp, s + 1))
            errs.append(np.sqrt(np.mean((img - ref) ** 2)) / scale)
            times.append(c)
            total += img.sum() / args.seeds
        rows.append([name, spp, f"{statistics.median(times):.3f}", f"{statistics.mean(errs):.3f}", f"{total:.2f}"])
    rows.append(["reference (edgepath)", args.grad_ref_spp, "", "", f"{ref.sum():.2f}"])
    table(f"{title}, d image / d x, {size}x{size}, {bounces} bounce{'s' if bounces > 1 else ''}, at about equal "
          f"CPU time: RMSE relative to the mean |derivative| of the reference, mean of {args.seeds} seeds",
          ["renderer", "spp", "cpu s", "relative RMSE", "image sum"], rows)
    ratio = float(rows[0][3]) ** 2 / max(float(rows[1][3]) ** 2, 1e-30)
    print(f"equal-time MSE ratio (Mitsuba / edgepath): {ratio:.1f}")
    return ratio


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--bounces", type=int, default=3, help="edgepath max_bounces (Mitsuba max_depth - 1)")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--grad-size", type=int, default=64)
    parser.add_argument("--grad-spp", type=int, default=16, help="Mitsuba's spp for the derivative image")
    parser.add_argument("--grad-ref-spp", type=int, default=4096, help="spp of edgepath's reference")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--no-gradient", action="store_true", help="skip the derivative images")
    parser.add_argument("--no-forward", action="store_true", help="skip the forward renders (derivative images only)")
    args = parser.parse_args(argv)

    if np is None:
        print(f"Mitsuba comparison skipped: numpy is not installed in {sys.executable} (run it in the project's environment)")
        return 0
    mi, why = import_mitsuba()
    if mi is None:
        print(f"Mitsuba comparison skipped: {why}")
        return 0
    import drjit as dr
    import edgepath as ep
    dr.set_thread_count(args.threads)
    print(f"edgepath against Mitsuba {mi.__version__} (llvm_ad_rgb, libLLVM "
          f"{os.environ.get('DRJIT_LIBLLVM_PATH', 'found by Dr.Jit')}), {args.threads} threads, "
          f"load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as folder:
        if not args.no_forward:
            forward(mi, dr, ep, args, folder)
        if not args.no_gradient:
            gradient_at_equal_time(mi, dr, ep, args, folder, "Shadow of a welded cube", make_shadow, 1)
            gradient_at_equal_time(mi, dr, ep, args, folder, "The cube over a glossy floor (its shadow, its "
                                   "reflection, the light's highlight cut by it)", make_glossy, 2)
            gradient_at_equal_time(mi, dr, ep, args, folder, "A faceted sphere of 50k triangles and its shadow",
                                   make_faceted_shadow, 1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
