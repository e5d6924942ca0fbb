"""The built-in demo: inverse rendering with shadows.

A box floats above a grey floor, lit by a small square area light above it; the camera sees
the box and the shadow it casts. From one target image, gradient descent recovers the box's
position and rotation, its colour, and the lamp's position and intensity. The shadows do part
of the work: the lamp's position reaches the image only through visibility (where the box's
shadow and the lamp's own outline fall, seen from the floor and the box), so its whole
gradient comes from the edge sampling of those boundaries (secondary edges; with
``secondary_edges=False`` the lamp gets no gradient), and the shadow's offset from the box
tells the box's height.

``edgepath demo`` (and ``make demo``) runs it and writes target, start and result images, an
animated GIF of the optimisation and a plot of loss and parameter error against iteration.
:func:`default_scene` is the older static scene (a red triangle in front of a wall).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import torch

from . import shapes
from .io import imwrite, to_srgb
from .render import render
from .scene import Camera, Material, Mesh, Scene


def quad(corners) -> Tuple[torch.Tensor, torch.Tensor]:
    """Vertices and indices of a quad given by 4 corners in order; the face normal follows
    the right-hand rule around them."""
    return shapes.quad(corners)


def default_scene(resolution: Tuple[int, int] = (256, 256)) -> Scene:
    """A red triangle in front of a grey wall, lit by a square area light behind the camera."""
    camera = Camera(position=torch.tensor([0.0, 0.0, -5.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                    up=torch.tensor([0.0, 1.0, 0.0]), fov=45.0, resolution=resolution)
    triangle = Mesh(vertices=torch.tensor([[-1.7, 1.0, 0.0], [1.0, 1.0, 0.0], [-0.5, -1.0, 0.0]]),
                    indices=torch.tensor([[0, 1, 2]], dtype=torch.int32),
                    material=Material(diffuse=torch.tensor([0.8, 0.2, 0.2]),
                                      specular=torch.tensor([0.04, 0.04, 0.04]), roughness=0.3))
    # A wall at z = 2 facing the camera (normal -z) and a lamp at z = -7 facing the scene (+z).
    wall_v, wall_i = quad([[-4, -4, 2], [-4, 4, 2], [4, 4, 2], [4, -4, 2]])
    wall = Mesh(vertices=wall_v, indices=wall_i, material=Material(diffuse=torch.tensor([0.5, 0.5, 0.5])))
    lamp_v, lamp_i = quad([[-2, -2, -7], [2, -2, -7], [2, 2, -7], [-2, 2, -7]])
    lamp = Mesh(vertices=lamp_v, indices=lamp_i, emission=torch.tensor([20.0, 20.0, 20.0]))
    return Scene(camera=camera, meshes=[triangle, wall, lamp])


# ---- the inverse-rendering demo -------------------------------------------------------------

@dataclass
class DemoParams:
    """The unknowns of the demo: the box's centre (x, y, z) and rotation about the vertical
    axis (radians), its diffuse colour, the lamp's centre in the horizontal plane (x, z) and
    its radiance."""
    position: torch.Tensor
    angle: torch.Tensor
    colour: torch.Tensor
    light: torch.Tensor
    intensity: torch.Tensor

    GROUPS = ("position", "angle", "colour", "light", "intensity")

    @staticmethod
    def of(position, angle, colour, light, intensity) -> "DemoParams":
        t = lambda x: torch.as_tensor(x, dtype=torch.float32).clone()  # noqa: E731
        return DemoParams(t(position), t(angle), t(colour), t(light), t(intensity))

    def detach(self) -> "DemoParams":
        return DemoParams(*(getattr(self, g).detach().clone() for g in self.GROUPS))


TRUTH = DemoParams.of(position=[0.15, 0.7, 0.0], angle=0.5, colour=[0.8, 0.3, 0.15],
                      light=[0.9, 1.0], intensity=30.0)
START = DemoParams.of(position=[-0.15, 0.55, 0.25], angle=0.1, colour=[0.4, 0.4, 0.4],
                      light=[-0.3, 0.5], intensity=15.0)

BOX_HALF_SIZE = (0.5, 0.3, 0.22)
LAMP_HEIGHT = 3.0
LAMP_HALF_SIZE = 0.35


def demo_scene(params: DemoParams, size: int = 128) -> Scene:
    """The demo's scene for the given unknowns (tensors; gradients flow back to them), seen
    on a ``size`` x ``size`` film."""
    box_v, box_i = shapes.box(half=BOX_HALF_SIZE)
    c, s = torch.cos(params.angle), torch.sin(params.angle)
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    rotation = torch.stack([torch.stack([c, zero, s]), torch.stack([zero, one, zero]),
                            torch.stack([-s, zero, c])])
    box = Mesh(box_v @ rotation.T + params.position, box_i,
               material=Material(diffuse=params.colour))
    fv, fi, fuv, fn = shapes.grid(size=(10.0, 10.0))
    floor = Mesh(fv, fi, uvs=fuv, normals=fn, material=Material(diffuse=torch.tensor([0.6, 0.6, 0.6])))
    # The lamp faces down: its corners run clockwise seen from above.
    h = LAMP_HALF_SIZE
    offsets = torch.tensor([[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]])
    centre = torch.stack([params.light[0], torch.tensor(LAMP_HEIGHT), params.light[1]])
    lamp = Mesh(offsets + centre, torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32),
                emission=params.intensity * torch.ones(3))
    camera = Camera(position=torch.tensor([0.0, 2.4, 3.6]), look_at=torch.tensor([0.0, 0.25, -0.2]),
                    fov=45.0, resolution=(size, size))
    return Scene(camera=camera, meshes=[box, floor, lamp])


def parameter_errors(estimate: DemoParams, truth: DemoParams = TRUTH) -> Dict[str, float]:
    """Distances to the truth: position and lamp position (scene units), angle (degrees),
    colour (Euclidean, RGB), intensity (relative)."""
    e, t = estimate.detach(), truth
    return {"position": float((e.position - t.position).norm()),
            "angle": math.degrees(abs(float(e.angle - t.angle))),
            "colour": float((e.colour - t.colour).norm()),
            "light": float((e.light - t.light).norm()),
            "intensity": abs(float(e.intensity / t.intensity) - 1.0)}


def relative_error(errors: Dict[str, float], start_errors: Dict[str, float]) -> float:
    """The mean over the parameter groups of each group's error over its error at the start
    (1 at the start, 0 at the truth)."""
    return sum(errors[g] / start_errors[g] for g in start_errors) / len(start_errors)


class ProgressBar:
    """A one-line progress bar on a stream (stderr by default): iteration, loss, rate, time
    left. Redrawn in place on a terminal; otherwise printed about ten times in all."""

    def __init__(self, total: int, stream=None, width: int = 30):
        self.total, self.width = total, width
        self.stream = sys.stderr if stream is None else stream
        self.interactive = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.perf_counter()
        self.last_line = -1

    def update(self, done: int, text: str = "") -> None:
        elapsed = time.perf_counter() - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        left = (self.total - done) / rate if rate > 0 else 0.0
        filled = int(self.width * done / max(self.total, 1))
        line = (f"[{'#' * filled}{'.' * (self.width - filled)}] {done}/{self.total} {text} "
                f"{rate:.1f} it/s, {elapsed:.0f} s, {left:.0f} s left")
        if self.interactive:
            self.stream.write("\r" + line)
            self.stream.flush()
        elif done == self.total or done * 10 // max(self.total, 1) > self.last_line:
            self.last_line = done * 10 // max(self.total, 1)
            self.stream.write(line + "\n")
            self.stream.flush()

    def close(self) -> None:
        if self.interactive:
            self.stream.write("\n")
            self.stream.flush()


def to_srgb8(image: torch.Tensor) -> np.ndarray:
    """Linear radiance (H, W, 3) to 8-bit sRGB, clamped to [0, 1], as a numpy array."""
    srgb = to_srgb(image.detach().to(torch.float64))
    return (srgb * 255.0 + 0.5).to(torch.uint8).numpy()


def write_gif(frames: List[np.ndarray], path: str, duration_ms: int = 80) -> None:
    """An animated GIF of 8-bit RGB frames, looping, the last frame held for a second."""
    from PIL import Image
    images = [Image.fromarray(f) for f in frames]
    durations = [duration_ms] * (len(images) - 1) + [1000]
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0)


def plot_history(history: Dict[str, list], path: str) -> None:
    """Loss and parameter errors (each relative to its value at the start) against
    iteration, as a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, (ax_loss, ax_err) = plt.subplots(1, 2, figsize=(11, 4))
    iterations = np.arange(len(history["loss"]))
    ax_loss.semilogy(iterations, history["loss"], color="tab:blue", label="estimate")
    if "noise_loss" in history:
        ax_loss.axhline(history["noise_loss"], color="gray", linestyle="--",
                        label="true parameters (Monte Carlo noise)")
    ax_loss.legend(fontsize=8)
    ax_loss.set_xlabel("iteration")
    ax_loss.set_ylabel("image loss (mean squared error)")
    ax_loss.set_title("loss")
    ax_loss.grid(True, which="both", alpha=0.3)
    start = history["errors"][0]
    for group in start:
        ax_err.semilogy(iterations, [max(e[group] / start[group], 1e-4) for e in history["errors"]],
                        label=group, linewidth=1)
    ax_err.semilogy(iterations, history["relative_error"], color="black", linewidth=2, label="mean")
    ax_err.set_xlabel("iteration")
    ax_err.set_ylabel("error / error at start")
    ax_err.set_title("parameter error")
    ax_err.grid(True, which="both", alpha=0.3)
    ax_err.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def image_loss(image: torch.Tensor, target: torch.Tensor, coarsest: int = 8) -> torch.Tensor:
    """Mean squared error summed over an image pyramid (the images and their 2x, 4x, ...
    box-filtered reductions, down to about ``coarsest`` pixels across): the coarse levels
    still see the overlap of a box and its shadow with their targets when the estimate is
    far off."""
    a, b = image.permute(2, 0, 1).unsqueeze(0), target.permute(2, 0, 1).unsqueeze(0)
    loss = (a - b).square().mean()
    while min(a.shape[-2:]) >= 2 * coarsest:
        a, b = torch.nn.functional.avg_pool2d(a, 2), torch.nn.functional.avg_pool2d(b, 2)
        loss = loss + (a - b).square().mean()
    return loss


@dataclass
class DemoResult:
    """What :func:`run_demo` returns: the loss and parameter errors at every iteration (before
    that iteration's step), the final estimate and its errors, and the files written."""
    history: Dict[str, list]
    estimate: DemoParams
    errors: Dict[str, float]
    seconds: float
    files: List[str] = field(default_factory=list)


def run_demo(iterations: int = 150, size: int = 128, spp: int = 4, output_dir: Optional[str] = "demo_out",
             seed: int = 0, num_threads: Optional[int] = None, lr: float = 1.0,
             progress: bool = True, frames: int = 50, secondary_edges: bool = True,
             log: Callable[[str], None] = print) -> DemoResult:
    """Runs the demo: renders the target, optimises from :data:`START` with Adam for
    ``iterations`` steps of ``spp`` samples per pixel on a ``size`` x ``size`` film, and
    (unless ``output_dir`` is None) writes target.png, start.png, result.png,
    optimisation.gif (``frames`` frames: target | current estimate) and convergence.png.
    ``secondary_edges=False`` leaves the moving shadow's boundary out of the gradient (for
    comparison)."""
    if iterations < 1:
        raise ValueError(f"iterations: must be >= 1, got {iterations}")
    if size < 8:
        raise ValueError(f"size: must be >= 8, got {size}")
    if spp < 1:
        raise ValueError(f"spp: must be >= 1, got {spp}")
    if output_dir is not None:
        try:
            import matplotlib  # noqa: F401
            import PIL  # noqa: F401
        except ImportError as error:
            raise ImportError(f"the demo writes its GIF with Pillow and its plot with matplotlib: "
                              f"pip install pillow matplotlib ({error})") from error
    began = time.perf_counter()
    options = dict(max_bounces=1, num_threads=num_threads)
    target = render(demo_scene(TRUTH, size), spp=max(128, 32 * spp), seed=seed + 1_000_003, **options)

    # Unconstrained variables: colour and intensity through their logarithms.
    position = START.position.clone().requires_grad_()
    angle = START.angle.clone().requires_grad_()
    log_colour = START.colour.log().requires_grad_()
    light = START.light.clone().requires_grad_()
    log_intensity = START.intensity.log().requires_grad_()
    optimizer = torch.optim.Adam([
        {"params": [position], "lr": 0.02 * lr},
        {"params": [angle], "lr": 0.03 * lr},
        {"params": [log_colour], "lr": 0.03 * lr},
        {"params": [light], "lr": 0.05 * lr},
        {"params": [log_intensity], "lr": 0.03 * lr},
    ], betas=(0.8, 0.95))
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda i: 0.1 ** (i / max(iterations, 1)))

    def current() -> DemoParams:
        return DemoParams(position, angle, log_colour.exp(), light, log_intensity.exp())

    start_errors = parameter_errors(START)
    history: Dict[str, list] = {"loss": [], "errors": [], "relative_error": []}
    with torch.no_grad():  # the loss's floor: what Monte Carlo noise alone gives
        history["noise_loss"] = float(image_loss(
            render(demo_scene(TRUTH, size), spp=spp, seed=seed + 3_000_017, **options), target))
    frame_every = max(1, iterations // max(frames, 1))
    gif_frames: List[np.ndarray] = []
    target8 = to_srgb8(target)
    bar = ProgressBar(iterations) if progress else None
    try:
        for step in range(iterations):
            optimizer.zero_grad()
            estimate = current()
            errors = parameter_errors(estimate)
            image = render(demo_scene(estimate, size), spp=spp, seed=seed + step,
                           secondary_edges=secondary_edges, **options)
            loss = image_loss(image, target)
            loss.backward()
            optimizer.step()
            schedule.step()
            history["loss"].append(loss.item())
            history["errors"].append(errors)
            history["relative_error"].append(relative_error(errors, start_errors))
            if output_dir is not None and (step % frame_every == 0 or step == iterations - 1):
                gif_frames.append(np.concatenate([target8, to_srgb8(image)], axis=1))
            if bar is not None:
                bar.update(step + 1, f"loss {loss.item():.3g}, "
                                     f"error {history['relative_error'][-1]:.3f}")
    finally:  # the bar's line is finished even when Ctrl-C or an error stops the loop
        if bar is not None:
            bar.close()

    final = current().detach()
    final_errors = parameter_errors(final)
    result = DemoResult(history=history, estimate=final, errors=final_errors,
                        seconds=time.perf_counter() - began)
    if output_dir is not None:
        os.makedirs(output_dir, exist_ok=True)
        still = dict(spp=max(128, 32 * spp), seed=seed + 2_000_003, **options)
        pictures = {"target.png": target,
                    "start.png": render(demo_scene(START, size), **still),
                    "result.png": render(demo_scene(final, size), **still)}
        for name, picture in pictures.items():
            imwrite(picture, os.path.join(output_dir, name))
            result.files.append(os.path.join(output_dir, name))
        write_gif(gif_frames, os.path.join(output_dir, "optimisation.gif"))
        plot_history(history, os.path.join(output_dir, "convergence.png"))
        result.files += [os.path.join(output_dir, "optimisation.gif"),
                         os.path.join(output_dir, "convergence.png")]
    result.seconds = time.perf_counter() - began

    def fmt(p: DemoParams) -> str:
        return (f"position {[round(x, 3) for x in p.position.tolist()]}, "
                f"angle {math.degrees(float(p.angle)):.1f} deg, "
                f"colour {[round(x, 3) for x in p.colour.tolist()]}, "
                f"light {[round(x, 3) for x in p.light.tolist()]}, intensity {float(p.intensity):.2f}")
    log(f"truth:  {fmt(TRUTH)}")
    log(f"start:  {fmt(START)}")
    log(f"result: {fmt(final)}")
    log("errors: " + ", ".join(f"{g} {start_errors[g]:.3g} -> {final_errors[g]:.3g}" for g in start_errors)
        + " (position, light: scene units; angle: degrees; colour: RGB distance; intensity: relative)")
    log(f"loss {history['loss'][0]:.4g} -> {history['loss'][-1]:.4g} in {iterations} iterations "
        f"(at the true parameters: {history['noise_loss']:.4g}), {result.seconds:.1f} s")
    if result.files:
        log("wrote " + ", ".join(result.files))
    return result
