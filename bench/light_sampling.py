"""Light sampling at equal time: area sampling against solid-angle sampling of the same
light, by the relative noise per pixel each reaches in the same render time.

Two scenes, a diffuse floor lit directly (one bounce) and seen from below the light by an
orthographic camera: a large square lamp close over it ("area" against
"spherical_triangle"), and a sphere light over it (``lights.sphere_light``, 80 faces: "area"
against "solid_angle", its bounding sphere's cone, and "spherical_triangle", which picks its
faces by power). Each method renders the scene `--runs` times with other seeds, the methods
taking turns; the relative noise is the per-pixel standard deviation over the runs over the
image's mean (its RMS over the pixels), at `--spp` samples; at equal time it is that noise
times sqrt(time / area sampling's time) (noise falls as one over the square root of the
samples). The ratio to area sampling's is the figure: below 1, the method wins.

A third scene samples an environment map (``museum.exr`` of the shared conformance data, where
present) over a glossy sphere on a floor, two bounces: by its whole radiance, as a gradient pass
and the images it may retrace do, against by its light above its mean, as an image no gradient
follows does (docs/conventions.md, "How lights are sampled"); the ratio is to the former's.

    python bench/light_sampling.py [--size 64] [--spp 16] [--runs 8]
"""

import argparse
import pathlib
import time

import torch

import edgepath as ep


def floor_and_camera(size, camera_height, width):
    fv, fi = ep.shapes.quad([[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]])
    floor = ep.Mesh(vertices=fv, indices=fi, material=ep.Material(diffuse=0.5, specular=0.0))
    camera = ep.Camera(position=torch.tensor([0.0, camera_height, 0.0]), look_at=torch.zeros(3),
                       up=torch.tensor([0.0, 0, -1]), camera_type="orthographic",
                       ortho_scale=width, resolution=(size, size))
    return floor, camera


def quad_scene(method, size):
    floor, camera = floor_and_camera(size, 0.5, 3.0)
    lv, li = ep.shapes.quad([[-0.6, 1.0, -0.6], [0.6, 1.0, -0.6], [0.6, 1.0, 0.6], [-0.6, 1.0, 0.6]])
    lamp = ep.Mesh(vertices=lv, indices=li, material=ep.Material(diffuse=0.0, specular=0.0),
                   emission=torch.full((3,), 2.0), light_sampling=method)
    return ep.Scene(camera=camera, meshes=[floor, lamp])


def sphere_scene(method, size):
    floor, camera = floor_and_camera(size, 0.5, 3.0)
    light = ep.lights.sphere_light((0.0, 1.0, 0.0), 2.0, radius=0.25)
    light.light_sampling = method
    return ep.Scene(camera=camera, meshes=[floor, light])


MUSEUM = pathlib.Path(__file__).resolve().parents[2] / "shared" / "conformance" / "mitsuba3" / "textures" / "museum.exr"


def environment_scene(method, size):
    v, i, _, n = ep.shapes.sphere(radius=1.0, rings=48, segments=96)
    fv, fi = ep.shapes.quad([[-4, -1, -4], [-4, -1, 4], [4, -1, 4], [4, -1, -4]])
    meshes = [ep.Mesh(v, i, normals=n, material=ep.Material(diffuse=torch.tensor([0.6, 0.5, 0.4]), specular=0.2,
                                                              roughness=0.25)),
              ep.Mesh(fv, fi, material=ep.Material(diffuse=0.5))]
    camera = ep.Camera(position=torch.tensor([0.0, 1.5, 4.5]), look_at=torch.tensor([0.0, -0.2, 0.0]), fov=45.0,
                       resolution=(size, size))
    return ep.Scene(camera, meshes, ep.EnvironmentMap(ep.imread(MUSEUM)))


def environment_render(scene, method, spp, seed):
    """The environment by its whole radiance (a replayable image's sampling) or by its light
    above its mean (an image alone's: what ep.render gives without a gradient)."""
    from edgepath.render import flatten_scene, render_flat, render_options
    options = render_options(spp=spp, max_bounces=2, seed=seed)
    options.replayable = method == "whole radiance"
    return render_flat(flatten_scene(scene), options)[0]


def plain_render(scene, method, spp, seed):
    return ep.render(scene, spp=spp, seed=seed)


def measure(make, methods, size, spp, runs, render=plain_render):
    scenes = {m: make(m, size) for m in methods}
    for m in methods:  # warm up (first-call costs)
        render(scenes[m], m, 1, 0)
    images = {m: [] for m in methods}
    times = {m: [] for m in methods}
    for r in range(runs):
        order = methods[r % len(methods):] + methods[:r % len(methods)]
        for m in order:
            start = time.perf_counter()
            images[m].append(render(scenes[m], m, spp, r + 1))
            times[m].append(time.perf_counter() - start)
    out = {}
    for m in methods:
        stack = torch.stack(images[m]).double()
        noise = float(stack.var(dim=0).mean().sqrt() / stack.mean())
        t = sorted(times[m])[len(times[m]) // 2]
        out[m] = (t, noise)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--runs", type=int, default=8)
    a = ap.parse_args()
    print(f"light sampling at equal time ({a.size}x{a.size}, {a.spp} spp, {a.runs} runs each; "
          "relative noise per pixel)")
    print(f"  {'scene':<22} {'method':<20} {'time':>9} {'noise':>8} {'equal-time noise':>17} "
          f"{'ratio':>6}")
    cases = [("square lamp over floor", quad_scene, ["area", "spherical_triangle"], plain_render),
             ("sphere light over floor", sphere_scene, ["area", "solid_angle", "spherical_triangle"], plain_render)]
    if MUSEUM.is_file():
        cases.append(("museum.exr over sphere", environment_scene, ["whole radiance", "above its mean"],
                      environment_render))
    else:
        print(f"  (the environment map's case skipped: {MUSEUM.name} not found beside the repository)")
    for name, make, methods, render in cases:
        res = measure(make, methods, a.size, a.spp, a.runs, render)
        t_ref, n_ref = res[methods[0]]
        for m in methods:
            t, n = res[m]
            equal = n * (t / t_ref) ** 0.5
            print(f"  {name:<22} {m:<20} {t * 1e3:7.1f}ms {n:8.4f} {equal:17.4f} {equal / n_ref:6.2f}")


if __name__ == "__main__":
    main()
