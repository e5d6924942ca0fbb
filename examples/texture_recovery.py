"""Texture recovery: paint a sphere's texture from four photographs of it.

A sphere with a latitude-longitude texture (stripes and a few spots) is seen from four sides
under lamps beside the cameras. Starting from a plain grey texture, gradient descent on the
texels recovers the pattern wherever the cameras see it (not near the poles).

    python examples/texture_recovery.py [--iterations 150] [--size 64] [--output-dir DIR]
"""

import math

import torch

import edgepath as ep
from edgepath import shapes
from _common import lamp, orbit_cameras, output_dir, parser, plot, report, row, run, save_images

TEXTURE_SIZE = (32, 64)
SPHERE = shapes.sphere(radius=1.0, rings=24, segments=48)
VIEWS = 4


def true_texture() -> torch.Tensor:
    """Stripes along the latitude, three coloured spots (32 x 64 x 3, values in (0, 1))."""
    h, w = TEXTURE_SIZE
    v = (torch.arange(h).float() + 0.5) / h
    u = (torch.arange(w).float() + 0.5) / w
    vv, uu = torch.meshgrid(v, u, indexing="ij")
    stripes = 0.5 + 0.4 * torch.sign(torch.sin(vv * math.pi * 6))
    texture = stripes.unsqueeze(-1) * torch.tensor([0.9, 0.85, 0.6])
    for cu, cv, colour in ((0.15, 0.5, (0.9, 0.1, 0.1)), (0.5, 0.4, (0.1, 0.6, 0.2)),
                           (0.8, 0.6, (0.1, 0.2, 0.9))):
        spot = ((uu - cu).square() * 4 + (vv - cv).square()) < 0.012
        texture[spot] = torch.tensor(colour)
    return texture.clamp(0.05, 0.95)


LAMPS = [lamp((4.0 * math.sin(math.radians(a + 30)), 2.5, 4.0 * math.cos(math.radians(a + 30))), 1.5, 5.0)
         for a in range(0, 360, 360 // VIEWS)]


def make_scene(texture: torch.Tensor, camera: ep.Camera) -> ep.Scene:
    v, i, uv, n = SPHERE
    ball = ep.Mesh(v, i, uvs=uv, normals=n, material=ep.Material(diffuse=texture))
    return ep.Scene(camera, [ball] + LAMPS)


def main(argv=None):
    args = parser(__doc__.splitlines()[0], iterations=150, size=64, spp=8).parse_args(argv)
    out = output_dir(args, "texture_recovery")
    truth = true_texture()
    cameras = orbit_cameras(args.size, count=VIEWS, distance=3.5, height=0.5, fov=40.0)
    # One scene for every step and view, the views in one call: only the texture changes
    # between steps, so nothing is built after the first step (scene.build_counts()). Each
    # view has a seed of its own (seed=[...]): the rig turns with the lamps, so the views are
    # alike up to a rotation, and with one seed for all they would have the same noise, which
    # would add up in the loss instead of averaging out.
    scene = make_scene(truth, cameras[0])
    targets = ep.render(scene, spp=128, seed=[args.seed + 10_000 + k for k in range(VIEWS)], cameras=cameras)
    # Texels as logits: the albedo stays in (0, 1).
    logits = torch.zeros(TEXTURE_SIZE + (3,), requires_grad=True)
    optimizer = torch.optim.Adam([logits], lr=0.1)
    # Rows 8..24 (latitudes within about 45 degrees of the equator): what the cameras see well.
    band = slice(TEXTURE_SIZE[0] // 4, 3 * TEXTURE_SIZE[0] // 4)
    losses, errors = [], []
    for step in range(args.iterations):
        optimizer.zero_grad()
        texture = torch.sigmoid(logits)
        scene.meshes[0].material = ep.Material(diffuse=texture)
        images = ep.render(scene, spp=args.spp, backward_spp=max(1, args.spp // 2), cameras=cameras,
                           seed=[args.seed + VIEWS * step + k for k in range(VIEWS)])
        loss = (images - targets).square().mean()  # the views' mean of each view's mean
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        errors.append(float((texture.detach()[band] - truth[band]).abs().mean()))
        report(args, step, losses[-1], extra=f"  texel error (band) {errors[-1]:.4f}")

    recovered = torch.sigmoid(logits.detach())
    scene.meshes[0].material = ep.Material(diffuse=recovered)
    views = ep.render(scene, spp=128, cameras=cameras)
    big = lambda t: t.repeat_interleave(4, 0).repeat_interleave(4, 1)  # noqa: E731
    save_images(out, {"target": row(targets), "result": row(views),
                      "texture_true_vs_recovered": row([big(truth), big(recovered)])})
    plot(f"{out}/loss.png", {"image loss": losses, "mean texel error (seen band)": errors}, "value",
         "texture recovery")
    print(f"texture recovery: loss {losses[0]:.4g} -> {losses[-1]:.4g}, mean texel error in the "
          f"seen band {errors[0]:.3f} -> {errors[-1]:.4f}; pictures in {out}")
    return {"loss": losses, "texel_error": errors, "texture": recovered,
            "build_counts": scene.build_counts()}


if __name__ == "__main__":
    run(main)
