"""Command line: ``edgepath render SCENE -o out.exr``, ``edgepath derivative SCENE --param NAME
--direction ...``, ``edgepath info SCENE``, ``edgepath demo``. SCENE is a Mitsuba 3 XML file
(the subset ``load_mitsuba`` reads) or an OBJ file. See docs/cli.md."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import List, Optional

import torch

from .io import imwrite, load_obj
from .mitsuba import UNBOUNDED_MAX_BOUNCES, MitsubaScene, load_mitsuba
from .render import CHANNELS, ID_CHANNELS, SAMPLING, derivative_image, render, render_channels
from .scene import Camera, EnvironmentMap, Material, Scene


def _framing_camera(meshes, resolution, fov: float) -> Camera:
    """A camera on the +z side of the meshes' bounding box, looking at its centre."""
    points = torch.cat([m.vertices.detach().reshape(-1, 3).to(torch.float32) for m in meshes])
    lo, hi = points.min(dim=0).values, points.max(dim=0).values
    centre, radius = (lo + hi) / 2, max(float((hi - lo).norm()) / 2, 1e-3)
    distance = 1.1 * radius / math.sin(math.radians(fov) / 2)
    position = centre + torch.tensor([0.0, 0.0, distance])
    return Camera(position=position, look_at=centre, up=torch.tensor([0.0, 1.0, 0.0]),
                  fov=fov, resolution=tuple(resolution))


def _render_and_write(scene: Scene, args, outputs: List[str]) -> None:
    start = time.perf_counter()
    image = render(scene, spp=args.spp, max_bounces=args.max_bounces, seed=args.seed,
                   num_threads=args.threads, sampling=args.sampling)
    seconds = time.perf_counter() - start
    for path in outputs:
        directory = os.path.dirname(path)
        if directory:
            os.makedirs(directory, exist_ok=True)
        imwrite(image, path)
    height, width = image.shape[:2]
    print(f"rendered {width}x{height} at {args.spp} spp in {seconds:.2f} s: {', '.join(outputs)}")


def _obj_scene(args) -> MitsubaScene:
    """An OBJ file seen from the +z side of its bounding box, as a MitsubaScene (shape ids
    mesh_0, mesh_1, ...). Without emitters it is lit by a constant white environment."""
    meshes = load_obj(args.scene)
    if not meshes:
        raise ValueError(f"{args.scene}: no faces")
    camera = _framing_camera(meshes, args.resolution or (256, 256),
                             45.0 if args.fov is None else args.fov)
    envmap = None
    if args.env >= 0 and (args.env > 0 or all(m.emission is None for m in meshes)):
        # A constant white environment (1x1 map) lights scenes without emitters.
        envmap = EnvironmentMap(values=torch.full((1, 1, 3), 1.0), scale=args.env or 1.0)
    for m in meshes:  # materials of their own, so that their tensors can be named
        if m.material is None:
            m.material = Material(diffuse=torch.full((3,), 0.0 if m.emission is not None else 0.5))
    ids = [f"mesh_{i}" for i in range(len(meshes))]
    return MitsubaScene(scene=Scene(camera=camera, meshes=meshes, envmap=envmap), max_bounces=None,
                        spp=16, shapes=dict(zip(ids, meshes)), shape_ids=ids, path=args.scene)


def _load_scene(args) -> MitsubaScene:
    """The scene of ``args.scene`` (XML or OBJ) with the command line's overrides applied."""
    if args.scene.lower().endswith(".obj"):
        if args.define:
            raise ValueError("-D: parameters apply to XML scene files only")
        loaded = _obj_scene(args)
    else:
        if args.fov is not None or args.env != 0.0:
            raise ValueError("--fov and --env apply to OBJ files only (an XML file has its sensor "
                             "and emitters)")
        loaded = load_mitsuba(args.scene, **dict(args.define or []))
        if args.resolution:
            camera = loaded.scene.camera
            camera.resolution = tuple(args.resolution)
            camera.crop_window = None
    if args.spp is not None:
        loaded.spp = args.spp
    if args.max_bounces is not None:
        loaded.max_bounces = args.max_bounces
    elif loaded.max_bounces is None:
        loaded.max_bounces = DEFAULT_MAX_BOUNCES
    if args.seed is not None:
        loaded.seed = args.seed
    return loaded


DEFAULT_MAX_BOUNCES = UNBOUNDED_MAX_BOUNCES


# True while stderr may end in a line that is not finished: the progress line on a terminal
# (it is rewritten in place), or one cut short by Ctrl-C between its text and its newline.
_line_open = False


def _progress(done: int, total: int, start: float, final: bool = False) -> None:
    global _line_open
    elapsed = time.perf_counter() - start
    left = elapsed * (total - done) / done if done else 0.0
    end = "\n" if final or not sys.stderr.isatty() else ""
    _line_open = True
    print(f"\r{done}/{total} spp, {elapsed:.1f} s elapsed, ~{left:.1f} s left ",
          end=end, file=sys.stderr, flush=True)
    _line_open = not end


def render_in_chunks(loaded: MitsubaScene, chunk_spp: int, num_threads=None, sampling="mis",
                     quiet: bool = False) -> torch.Tensor:
    """The mean of renders of at most ``chunk_spp`` samples per pixel each (chunk k with seed
    seed + k), with progress on stderr. One chunk (spp <= chunk_spp) is exactly
    ``ep.render(scene, spp, max_bounces, seed)``."""
    if chunk_spp < 1:
        raise ValueError(f"--chunk-spp: must be >= 1, got {chunk_spp}")
    total, done, k = loaded.spp, 0, 0
    start = time.perf_counter()
    image = None
    while done < total:
        n = min(chunk_spp, total - done)
        part = render(loaded.scene, spp=n, max_bounces=loaded.max_bounces, seed=loaded.seed + k,
                      num_threads=num_threads, sampling=sampling, hide_emitters=loaded.hide_emitters)
        image = part * n if image is None else image + part * n
        done, k = done + n, k + 1
        if not quiet and total > chunk_spp:
            _progress(done, total, start, final=done == total)
    return image / total


def _channels(text: str) -> List[str]:
    """--channels: comma-separated output channel names (at least one)."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in CHANNELS or n == "radiance"]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown channel(s) {unknown or [text]}; choose from "
            f"{', '.join(n for n in CHANNELS if n != 'radiance')}")
    return names


def channel_path(output: str, name: str) -> str:
    """Where ``edgepath render --channels`` writes channel ``name`` for the image ``output``:
    beside it, ``<stem>.<name>.exr`` (EXR keeps depth, positions and ids exact)."""
    return f"{os.path.splitext(output)[0]}.{name}.exr"


def _cmd_render(args) -> None:
    channels = args.channels or []
    loaded = _load_scene(args)
    start = time.perf_counter()
    image = render_in_chunks(loaded, args.chunk_spp, args.threads, args.sampling)
    extra = {}
    if channels:
        # One pass at the file's spp: ids come from the pixel centres, so chunks would not help.
        extra = render_channels(loaded.scene, channels, spp=loaded.spp, max_bounces=loaded.max_bounces,
                                seed=loaded.seed, num_threads=args.threads, sampling=args.sampling,
                                hide_emitters=loaded.hide_emitters)
    seconds = time.perf_counter() - start
    outputs = args.output or ["out.png"]
    written = []
    for path in outputs:
        _make_parent(path)
        imwrite(image, path)
        written.append(path)
        for name, values in extra.items():
            values = values.to(torch.float32) if name in ID_CHANNELS else values
            imwrite(values, channel_path(path, name))
            written.append(channel_path(path, name))
    outputs = written
    height, width = image.shape[:2]
    print(f"rendered {width}x{height} at {loaded.spp} spp, max_bounces {loaded.max_bounces}, "
          f"in {seconds:.2f} s: {', '.join(outputs)}")


def _make_parent(path: str) -> None:
    directory = os.path.dirname(path)
    if directory:
        os.makedirs(directory, exist_ok=True)


def diverging_colours(values: torch.Tensor, scale: float) -> torch.Tensor:
    """(H, W) signed values to (H, W, 3) linear RGB: blue (-scale) through white (0) to red
    (+scale), clamped beyond; the colours are chosen in sRGB and linearised for imwrite."""
    t = (values / scale).clamp(-1, 1) if scale > 0 else torch.zeros_like(values)
    pos, neg = t.clamp_min(0), (-t).clamp_min(0)
    srgb = torch.stack([1 - neg, 1 - pos - neg, 1 - pos], -1).clamp(0, 1)
    return torch.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def robust_scale(values: torch.Tensor, percentile: float) -> float:
    """The ``percentile`` of |values| over the non-zero entries (0 if all are zero)."""
    a = values.abs().flatten()
    a = a[a > 0]
    if a.numel() == 0:
        return 0.0
    return float(torch.quantile(a.double(), percentile / 100.0)) if a.numel() <= 16_000_000 \
        else float(a.double().kthvalue(max(1, int(a.numel() * percentile / 100.0))).values)


def _cmd_derivative(args) -> None:
    loaded = _load_scene(args)
    if not args.output.lower().endswith(".exr"):
        raise ValueError(f"-o: the derivative image is written as EXR, got {args.output!r}")
    param, direction = loaded.direction(args.param, args.direction)
    start = time.perf_counter()
    image = derivative_image(loaded.scene, param, direction, spp=loaded.spp,
                             max_bounces=loaded.max_bounces, seed=loaded.seed,
                             num_threads=args.threads, sampling=args.sampling)
    seconds = time.perf_counter() - start
    _make_parent(args.output)
    imwrite(image, args.output)
    signed = image.mean(dim=2)
    scale = robust_scale(signed, args.percentile)
    png = os.path.splitext(args.output)[0] + ".png"
    imwrite(diverging_colours(signed, scale), png)
    height, width = image.shape[:2]
    print(f"derivative of {width}x{height} image along {args.param} at {loaded.spp} spp in "
          f"{seconds:.2f} s: {args.output}, {png} (colour scale +-{scale:.4g}: the "
          f"{args.percentile:g}th percentile of |mean over RGB|)")


def _fmt(values) -> str:
    return "(" + ", ".join(f"{float(x):.4g}" for x in values) + ")"


def _cmd_info(args) -> None:
    loaded = _load_scene(args)
    scene = loaded.scene
    triangles = sum(int(m.indices.shape[0]) for m in scene.meshes)
    vertices = sum(int(m.vertices.shape[0]) for m in scene.meshes)
    area_lights = sum(m.emission is not None for m in scene.meshes)
    points = torch.cat([m.vertices.detach().reshape(-1, 3).double() for m in scene.meshes])
    lo, hi = points.min(dim=0).values, points.max(dim=0).values
    c = scene.camera
    position, look_at, up = (t.detach() for t in c.frame())
    print(f"scene: {loaded.path}")
    print(f"meshes: {len(scene.meshes)}, triangles: {triangles}, vertices: {vertices}")
    env = "none" if scene.envmap is None else \
        f"{tuple(scene.envmap.values.shape[:2])} map" if scene.envmap.values.shape[:2] != (1, 1) \
        else "constant"
    print(f"lights: {area_lights} area, environment: {env}")
    print(f"bounds: min {_fmt(lo)}, max {_fmt(hi)}")
    view = f"ortho_scale {float(c.ortho_scale):.4g}" if c.camera_type == "orthographic" else \
        f"fov {float(c.fov):.4g} deg"
    if c.camera_type == "panorama":
        view = "360 x 180 deg"
    if c.camera_type == "thinlens":
        view += (f", aperture_radius {float(c.aperture_radius):.4g}, "
                 f"focus_distance {float(c.focus_distance):.4g}")
    height, width = c.resolution
    crop = f", crop {tuple(c.crop_window)}" if c.crop_window is not None else ""
    print(f"camera: {c.camera_type}, position {_fmt(position)}, look_at {_fmt(look_at)}, "
          f"up {_fmt(up)}, {view}, {width}x{height}{crop}, {c.pixel_filter} filter")
    print(f"render: spp {loaded.spp}, max_bounces {loaded.max_bounces}, seed {loaded.seed}")
    print("shapes: " + ", ".join(
        f"{sid} ({int(m.indices.shape[0])} triangles{', emitter' if m.emission is not None else ''})"
        for sid, m in zip(loaded.shape_ids, scene.meshes)))
    print("parameters (NAME, shape, what --direction takes):")
    for name, t in loaded.parameters().items():
        print(f"  {name}  {tuple(t.shape)}  {_direction_help(name, t)}")
        if name == "sensor.to_world":  # a direction of it, not a parameter of its own
            print("  sensor.position  (--direction only)  3 numbers: a translation of the camera")


def _direction_help(name: str, t: torch.Tensor) -> str:
    if name.endswith(".vertex_positions") or name == "sensor.position":
        return "3 numbers: a translation"
    if name == "sensor.to_world":
        return "16 numbers: a 4x4 matrix, row-major"
    if t.dim() > 0 and t.shape[-1] == 3:
        return "1 or 3 numbers: added to every " + ("texel" if t.dim() == 3 else "channel")
    return "1 number"


# The largest image the command line renders: a (H, W, 3) float32 image of this many pixels
# (16384 x 16384) takes 3 GiB.
MAX_PIXELS = 2**28


def _integer(minimum: int, maximum: int = 2**31 - 1):
    """An argparse type: an integer in [minimum, maximum]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not minimum <= value <= maximum:
            raise argparse.ArgumentTypeError(f"must be in [{minimum}, {maximum}], got {value}")
        return value
    return parse


def _finite(low: float = -math.inf, high: float = math.inf, open_low: bool = False,
            open_high: bool = False):
    """An argparse type: a finite number in the interval from low to high (open where asked)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
        if value < low or value > high or (open_low and value == low) or \
                (open_high and value == high):
            interval = ("(" if open_low else "[") + f"{low:g}, {high:g}" + (")" if open_high else "]")
            raise argparse.ArgumentTypeError(f"must be in {interval}, got {text}")
        return value
    return parse


class _Resolution(argparse.Action):
    """--resolution HEIGHT WIDTH: at most MAX_PIXELS pixels in all."""

    def __call__(self, parser, namespace, values, option_string=None):
        if values[0] * values[1] > MAX_PIXELS:
            raise argparse.ArgumentError(self, f"{values[0]}x{values[1]} is more than the "
                                               f"{MAX_PIXELS} pixels the command line renders")
        setattr(namespace, self.dest, values)


def _define(text: str):
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    name, value = text.split("=", 1)
    return name.strip(), value


def _add_scene_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="a Mitsuba 3 XML scene file, or an OBJ file")
    parser.add_argument("-D", dest="define", action="append", type=_define, metavar="NAME=VALUE",
                        help="set the XML file's parameter $NAME (overrides its <default>); repeat")
    parser.add_argument("--spp", type=_integer(1), default=None,
                        help="samples per pixel (default: the file's sampler, 16 for OBJ)")
    parser.add_argument("--max-bounces", type=_integer(0), default=None,
                        help="scattering events per path: 0 = emitters only, 1 = direct light, ... "
                             "(default: the file's max_depth - 1, or "
                             f"{DEFAULT_MAX_BOUNCES} where it has none)")
    parser.add_argument("--seed", type=_integer(0, 2**64 - 1), default=None,
                        help="random seed (default: the file's sampler seed, or 0)")
    parser.add_argument("--threads", type=_integer(1, 4096), default=None,
                        help="worker threads (default: all cores)")
    parser.add_argument("--sampling", choices=list(SAMPLING), default="mis",
                        help="direct-light sampling strategy (default mis)")
    parser.add_argument("--resolution", type=_integer(1, 65536), nargs=2, action=_Resolution, metavar=("HEIGHT", "WIDTH"), default=None,
                        help="image size (default: the file's film, 256 256 for OBJ)")
    parser.add_argument("--fov", type=_finite(0, 180, open_low=True, open_high=True), default=None,
                        help="OBJ only: horizontal field of view, degrees (default 45)")
    parser.add_argument("--env", type=_finite(), default=0.0,
                        help="OBJ only: constant environment radiance: 0 = only if the file has no "
                             "emitters (radiance 1), < 0 = never (default 0)")


def _cmd_demo(args) -> None:
    from .demo import run_demo
    run_demo(iterations=args.iterations, size=args.size, spp=args.spp, output_dir=args.output_dir,
             seed=args.seed, num_threads=args.threads, progress=not args.quiet,
             secondary_edges=not args.no_secondary_edges)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="edgepath",
                                     description="edgepath: a differentiable path tracer.")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    r = commands.add_parser("render", help="render a scene file (Mitsuba XML or OBJ)",
                            description="Render a Mitsuba 3 XML scene (see docs/scene-files.md) or "
                                        "an OBJ file (with its MTL materials, seen from the +z side "
                                        "of its bounding box; without emitters in the file it is "
                                        "lit by a constant white environment). Renders in chunks "
                                        "of --chunk-spp samples, with progress on stderr.")
    _add_scene_options(r)
    r.add_argument("-o", "--output", action="append", metavar="FILE",
                   help="output image, .png or .exr; repeat for several (default out.png)")
    r.add_argument("--chunk-spp", type=_integer(1), default=16,
                   help="samples per pixel per chunk (default 16; chunk k uses seed + k)")
    r.add_argument("--channels", metavar="NAMES", type=_channels, default=None,
                   help="also write these output channels, comma-separated (alpha, depth, "
                        "position, geometry_normal, shading_normal, uv, albedo, barycentrics, "
                        "vertex_color, roughness, specular, mesh_id, triangle_id, material_id), "
                        "each as OUTPUT_STEM.NAME.exr; ids as floats, -1 = no hit")
    r.set_defaults(run=_cmd_render)

    g = commands.add_parser(
        "derivative", help="render the derivative image along a parameter",
        description="Write dI/dt, the derivative of the image along a direction in one "
                    "parameter's space (forward mode, with edge sampling), as EXR, and a "
                    "colour-mapped PNG beside it (blue negative, white zero, red positive; the "
                    "mean over RGB, scaled by a percentile of its magnitude). NAME: a name that "
                    "`edgepath info` lists (Mitsuba 3's names), e.g. SHAPE.vertex_positions, "
                    "SHAPE.emitter.radiance.value, BSDF.reflectance.value, sensor.x_fov, "
                    "envmap.data, or sensor.position (a translation of sensor.to_world).")
    _add_scene_options(g)
    g.add_argument("--param", required=True, metavar="NAME", help="the parameter (see edgepath info)")
    g.add_argument("--direction", required=True, type=_finite(), nargs="+", metavar="X",
                   help="SHAPE.vertex_positions, sensor.position: 3 numbers, a translation; "
                        "colours: 1 number (all channels) or 3, added to every texel; scalars "
                        "(sensor.x_fov, alpha): 1 number; sensor.to_world: 16 numbers")
    g.add_argument("-o", "--output", default="derivative.exr", metavar="FILE.exr",
                   help="the derivative image (default derivative.exr); the PNG goes beside it")
    g.add_argument("--percentile", type=_finite(0, 100, open_low=True), default=99.0,
                   help="the PNG's colour scale: this percentile of |dI| (default 99)")
    g.set_defaults(run=_cmd_derivative)

    n = commands.add_parser("info", help="print what a scene file holds",
                            description="Print counts (meshes, triangles, vertices, lights), "
                                        "bounds, the camera, the render settings and the names of "
                                        "the differentiable parameters.")
    _add_scene_options(n)
    n.set_defaults(run=_cmd_info)

    d = commands.add_parser("demo", help="inverse rendering: recover pose, colour and light from one image",
                            description="The built-in inverse-rendering demo: a box floats above a "
                                        "floor under a small area light. From one target image, Adam "
                                        "recovers the box's position, rotation and colour and the "
                                        "lamp's position and intensity, the shadow doing part of the "
                                        "work. Writes DIR/target.png, start.png, result.png, "
                                        "optimisation.gif and convergence.png.")
    d.add_argument("-o", "--output-dir", default="demo_out", metavar="DIR",
                   help="output directory (default demo_out)")
    d.add_argument("--iterations", type=_integer(1), default=150,
                   help="optimisation steps (default 150)")
    d.add_argument("--size", type=_integer(1, 16384), default=128,
                   help="image height and width (default 128)")
    d.add_argument("--spp", type=_integer(1), default=4, help="samples per pixel per step (default 4)")
    d.add_argument("--seed", type=_integer(0, 2**64 - 1), default=0, help="random seed (default 0)")
    d.add_argument("--threads", type=_integer(1, 4096), default=None,
                   help="worker threads (default: all cores)")
    d.add_argument("--no-secondary-edges", action="store_true",
                   help="leave the shadow and lamp outlines out of the gradient (for comparison: "
                        "the lamp then gets no gradient)")
    d.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    d.set_defaults(run=_cmd_demo)
    return parser


def _say(message: str) -> None:
    """One line on stderr, on a line of its own even after an unfinished progress line."""
    global _line_open
    print(("\n" if _line_open else "") + message, file=sys.stderr)
    _line_open = False


def main(argv: Optional[List[str]] = None) -> int:
    """Runs one command. Exit status: 0 done, 1 an error in the input (one line on stderr),
    2 bad arguments (argparse's usage and one line), 130 interrupted (Ctrl-C)."""
    try:
        args = build_parser().parse_args(argv)
        try:
            args.run(args)
        except (ValueError, OSError, MemoryError) as error:
            _say(f"edgepath {args.command}: error: {error}")
            return 1
    except KeyboardInterrupt:
        _say("edgepath: interrupted")
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
