"""Tangent-space normal maps (``Material(normal_map=...)``): the frame against its closed form,
derivative images against finite differences, and recovering a bump from shading under three coloured lamps.

The scenes are a square in the plane z = 0 facing an orthographic camera, with u along +x and v
along -y (image rows downwards): the frame of the map is s = +x (dp/du), n = +z,
t = cross(n, s) = +y (towards the image's upper rows, as Mitsuba 3 renders its normalmap: see
test_normalmap_matches_mitsuba), so a texel value v maps the normal to m = normalize(2 v - 1).
"""

import math
from pathlib import Path

import pytest
import torch

import edgepath as ep

import conformance as C

ERROR_MEAN, ERROR_MAX = 0.02, 0.3


def ortho_camera(resolution):
    return ep.Camera(position=torch.tensor([0.0, 0.0, 2.0]), look_at=torch.tensor([0.0, 0.0, 0.0]),
                     up=torch.tensor([0.0, 1.0, 0.0]), camera_type="orthographic", ortho_scale=1.0,
                     resolution=resolution)


def square(normal_map, uv_scale=1.0, half=1.5):
    """A square of half side `half` (the view's is 1), uvs u = (x + half) / (2 half) and
    v = (half - y) / (2 half) (v down, as an image's rows) times uv_scale."""
    v = torch.tensor([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]) * half
    uv = torch.tensor([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]) * uv_scale
    return ep.Mesh(v, torch.tensor([[0, 1, 2], [0, 2, 3]]), uvs=uv,
                   material=ep.Material(diffuse=0.8, normal_map=normal_map))


def lamp(direction, colour, distance=4.0, half=0.25):
    """A small square emitter towards `direction` from the origin, facing it."""
    n = torch.nn.functional.normalize(torch.tensor(direction), dim=0)
    a = torch.nn.functional.normalize(torch.linalg.cross(n, torch.tensor([0.0, 0.0, 1.0]) if abs(float(n[2])) < 0.9
                                                         else torch.tensor([1.0, 0.0, 0.0]), dim=0), dim=0)
    b = torch.linalg.cross(n, a, dim=0)
    c = n * distance
    v = torch.stack([c - a * half - b * half, c + a * half - b * half, c + a * half + b * half,
                     c - a * half + b * half])
    return ep.Mesh(v, torch.tensor([[0, 1, 2], [0, 2, 3]]), emission=torch.tensor(colour),
                   two_sided_emission=True)


def coloured_lamps():
    """A red lamp towards +x, a green one towards +y, a blue one towards -x -y, all above the
    square and outside the view: the three colours of a white diffuse surface measure its
    normal's direction."""
    return [lamp([1.0, 0.0, 0.6], [80.0, 0.0, 0.0]), lamp([0.0, 1.0, 0.6], [0.0, 80.0, 0.0]),
            lamp([-0.7, -0.7, 0.8], [0.0, 0.0, 80.0])]


@pytest.mark.parametrize("texel, expected", [((0.8, 0.5, 0.9), (0.6, 0.0, 0.8)),
                                             ((0.5, 0.8, 0.9), (0.0, 0.6, 0.8)),
                                             ((0.5, 0.5, 1.0), (0.0, 0.0, 1.0))])
def test_a_constant_map_tilts_the_shading_normal_in_the_tangent_frame(texel, expected):
    normal_map = torch.tensor(texel).reshape(1, 1, 3)
    scene = ep.Scene(ortho_camera((4, 4)), [square(normal_map)])
    out = ep.render_channels(scene, ["shading_normal", "geometry_normal"], spp=4)
    assert torch.allclose(out["shading_normal"], torch.tensor(expected).expand(4, 4, 3), atol=1e-6)
    assert bool((out["geometry_normal"] == torch.tensor([0.0, 0.0, 1.0])).all())
    assert torch.equal(normal_map, torch.tensor(texel).reshape(1, 1, 3))  # not modified


def bump_map(n):
    """An n x n map of a bump: normals tilted away from the centre."""
    c = (torch.arange(n) + 0.5) / n - 0.5
    y, x = torch.meshgrid(c, c, indexing="ij")
    m = torch.stack([1.2 * x, -1.2 * y, torch.ones_like(x)], -1)  # t = +y: rows go down
    m = m / m.norm(dim=-1, keepdim=True)
    return 0.5 * (m + 1)


# The derivative images sample the lamps only (sampling="light"): a direction drawn from the
# BSDF turns with the normal, so that the same random numbers may hit a lamp on one side of a
# finite difference and miss it on the other, a jump that swamps the difference at a few pixels
# (the derivative holds sampled directions fixed; both agree in expectation).
def test_radiance_derivative_in_the_texels_matches_finite_differences():
    normal_map = bump_map(4)
    scene = ep.Scene(ortho_camera((10, 10)), [square(normal_map)] + coloured_lamps())
    direction = torch.rand(normal_map.shape, generator=torch.Generator().manual_seed(3)) - 0.5
    fd = ep.finite_difference_image(scene, normal_map, direction, eps=2e-3, spp=64, seed=4, sampling="light")
    d = ep.derivative_image(scene, normal_map, direction, spp=64, seed=4, sampling="light")
    scale = float(fd.abs().max())
    mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
    print(f"normal map texels: mean err {mean_err:.4f}, max err {max_err:.4f}")
    assert scale > 0.1 and mean_err <= ERROR_MEAN and max_err <= ERROR_MAX


def test_radiance_derivative_in_the_uvs_matches_finite_differences():
    """The map's frame and lookup move with the uvs (the interior term; the uvs move no edge)."""
    scene = ep.Scene(ortho_camera((10, 10)), [square(bump_map(4), uv_scale=0.8)] + coloured_lamps())
    uvs = scene.meshes[0].uvs
    direction = torch.tensor([[0.2, -0.1], [0.3, 0.2], [-0.2, 0.25], [0.1, -0.3]])
    fd = ep.finite_difference_image(scene, uvs, direction, eps=2e-3, spp=64, seed=4, sampling="light")
    d = ep.derivative_image(scene, uvs, direction, spp=64, seed=4, sampling="light")
    scale = float(fd.abs().max())
    mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
    print(f"uvs: mean err {mean_err:.4f}, max err {max_err:.4f}, scale {scale:.4f}")
    # scale: the finite difference's largest pixel, 0.09-0.17 over seeds (a pixel's noise):
    # the derivative does not vanish
    assert scale > 0.05 and mean_err <= ERROR_MEAN and max_err <= ERROR_MAX


def test_radiance_derivative_in_the_vertices_matches_finite_differences():
    """Turning the square in its plane (its outline stays outside the view) turns dp/du, the
    map's frame and so the mapped normals with it (a map without rotational symmetry, unlike
    the bump, whose turned image is the same)."""
    gen = torch.Generator().manual_seed(7)
    ripples = torch.cat([0.5 + 0.4 * (torch.rand(4, 4, 2, generator=gen) - 0.5), torch.full((4, 4, 1), 0.9)], -1)
    scene = ep.Scene(ortho_camera((10, 10)), [square(ripples)] + coloured_lamps())
    v = scene.meshes[0].vertices
    direction = torch.stack([-v[:, 1], v[:, 0], torch.zeros(4)], 1)  # a rotation about z
    fd = ep.finite_difference_image(scene, v, direction, eps=2e-3, spp=64, seed=4, sampling="light")
    d = ep.derivative_image(scene, v, direction, spp=64, seed=4, sampling="light")
    scale = float(fd.abs().max())
    mean_err, max_err = C.image_error(d / scale, fd / scale, C.GRADIENT_FLOOR)
    print(f"vertices: mean err {mean_err:.4f}, max err {max_err:.4f}")
    assert scale > 0.1 and mean_err <= ERROR_MEAN and max_err <= ERROR_MAX


def mapped_normals(texels):
    m = 2 * texels - 1
    return m / m.norm(dim=-1, keepdim=True)


def test_recover_a_bump_from_shading():
    """From a flat map, gradient descent on the image under the coloured lamps finds the bump:
    the mean angle between the recovered and the true normals shrinks to a fifth (measured:
    23.8 to 3.7 degrees). The loss multiplies the differences of two independent renders, an
    unbiased estimate of the squared difference of their expectation: the square of one noisy
    render would add its variance, which depends on the normals, and pull them off."""
    target_map = bump_map(4)
    camera = ortho_camera((16, 16))
    target = ep.render(ep.Scene(camera, [square(target_map, half=1.0)] + coloured_lamps()), spp=256, seed=1,
                       sampling="light")
    texels = torch.tensor([0.5, 0.5, 1.0]).expand(4, 4, 3).clone().requires_grad_(True)
    scene = ep.Scene(camera, [square(texels, half=1.0)] + coloured_lamps())
    optimiser = torch.optim.Adam([texels], lr=0.02)
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimiser, gamma=0.97)

    def angle():
        cos = (mapped_normals(texels.detach()) * mapped_normals(target_map)).sum(-1).clamp(-1, 1)
        return float(torch.acos(cos).mean())

    start = angle()
    for step in range(100):
        one = ep.render(scene, spp=4, seed=2 * step + 10, sampling="light")
        two = ep.render(scene, spp=4, seed=2 * step + 11, sampling="light")
        loss = ((one - target) * (two - target)).sum()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
    end = angle()
    print(f"mean normal angle {math.degrees(start):.2f} -> {math.degrees(end):.2f} degrees")
    assert end < 0.2 * start, (start, end)


def normal_map_pattern():
    """The 8 x 8 map of mitsuba_refs/normalmap_rectangle.xml: normals leaning along s and t by
    sines of the column and of the row (tilts up to 27 and 22 degrees)."""
    i = (torch.arange(8, dtype=torch.float64) + 0.5) / 8
    row, col = torch.meshgrid(i, i, indexing="ij")
    m = torch.stack([0.5 * torch.sin(2 * math.pi * col), 0.4 * torch.sin(2 * math.pi * row),
                     torch.ones_like(row)], -1)
    return (0.5 * (m / m.norm(dim=-1, keepdim=True) + 1)).float()


def test_normalmap_matches_mitsuba():
    """A Mitsuba scene file with a normalmap BSDF against Mitsuba 3's image
    (mitsuba_refs/make_references.py): each channel's mean within 2% and Mitsuba's metric on
    4 x 4 blocks of pixels, as for the other Mitsuba references (tests/python/test_specular.py).
    With the frame's second axis reversed (t = cross(s, n)) the means are 4.6% darker and the
    blocks' mean error is 0.10 (measured; 0.2% and 0.005 as it is)."""
    refs = Path(__file__).resolve().parent / "mitsuba_refs"
    stored = ep.imread(refs / "normalmap_rectangle_map.exr")
    assert torch.allclose(stored, normal_map_pattern(), atol=1e-3)  # the map the file uses
    loaded = ep.load_mitsuba(refs / "normalmap_rectangle.xml")
    ref = ep.imread(refs / "normalmap_rectangle.exr")[..., :3].float()
    image = loaded.render(spp=256)

    def blocks(x):
        return torch.nn.functional.avg_pool2d(x.permute(2, 0, 1)[None], 4)[0]

    relative = image.mean((0, 1)) / ref.mean((0, 1)) - 1
    err = (blocks(image).double() - blocks(ref).double()).abs() / blocks(ref).double().abs().clamp_min(0.02)
    print("channel means", relative.tolist(), "blocks", float(err.mean()), float(err.max()))
    assert float(relative.abs().max()) < 0.02
    assert float(err.mean()) < 0.02 and float(err.max()) < 0.2


def test_normal_map_errors_name_the_field():
    scene = ep.Scene(ortho_camera((4, 4)), [square(torch.ones(2, 2))])
    with pytest.raises(ValueError, match=r"meshes\[0\]\.material\.normal_map: expected shape \(H, W, 3\)"):
        ep.render(scene, spp=1)
    bad = torch.full((2, 2, 3), 0.5)
    bad[1, 0, 2] = float("inf")
    scene = ep.Scene(ortho_camera((4, 4)), [square(bad)])
    with pytest.raises(ValueError, match=r"meshes\[0\]\.material\.normal_map: value inf at flat index 8 is not finite"):
        ep.render(scene, spp=1)
