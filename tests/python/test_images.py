"""Image helpers: Radiance .hdr files, the sRGB curve, and the picture a notebook shows."""

import io

import numpy as np
import pytest
import torch
from PIL import Image

import edgepath as ep


def hdr_image(shape=(6, 9, 3), seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.exp(torch.empty(shape).uniform_(-3.0, 4.0, generator=g))  # 0.05 .. 55


def test_hdr_round_trip_keeps_rgbe_precision(tmp_path):
    image = hdr_image()
    ep.imwrite(image, tmp_path / "env.hdr")
    back = ep.imread(tmp_path / "env.hdr")
    assert back.shape == image.shape and back.dtype == torch.float32
    # RGBE: one 8-bit exponent per pixel, 8-bit mantissas: each channel within 1/128 of the
    # pixel's largest channel. Channel order is RGB both ways (a swap would be far off).
    scale = image.max(dim=2, keepdim=True).values
    assert float(((back - image).abs() / scale).max()) < 1 / 128
    assert float(((back - image).abs() / scale).max()) > 0  # really stored in 8+8 bits


def test_hdr_grey_and_numpy_input(tmp_path):
    grey = hdr_image((5, 4)).numpy()
    before = grey.copy()
    ep.imwrite(grey, tmp_path / "grey.HDR")
    back = ep.imread(tmp_path / "grey.HDR")
    assert back.shape == (5, 4, 3)
    assert torch.equal(back[..., 0], back[..., 1]) and torch.equal(back[..., 0], back[..., 2])
    assert float((back[..., 0] - torch.from_numpy(grey)).abs().div(torch.from_numpy(grey)).max()) < 1 / 128
    assert np.array_equal(grey, before)


@pytest.mark.parametrize("image, message", [
    (-torch.ones(2, 2, 3), r"image: a \.hdr file holds finite non-negative values"),
    (torch.full((2, 2, 3), float("inf")), r"image: a \.hdr file holds finite non-negative"),
    (torch.ones(2, 2, 4), r"image: a \.hdr file holds grey or RGB, got 4 channels"),
])
def test_hdr_refuses_what_it_cannot_hold(tmp_path, image, message):
    with pytest.raises(ValueError, match=message):
        ep.imwrite(image, tmp_path / "bad.hdr")
    assert not (tmp_path / "bad.hdr").exists()


def test_hdr_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.hdr"):
        ep.imread(tmp_path / "missing.hdr")
    (tmp_path / "junk.hdr").write_bytes(b"#?RADIANCE\nnot really\n")
    with pytest.raises(OSError, match=r"junk\.hdr: not a readable Radiance HDR"):
        ep.imread(tmp_path / "junk.hdr")


def test_hdr_environment_map_in_a_scene_file(tmp_path):
    values = hdr_image((8, 16, 3), seed=1)
    ep.imwrite(values, tmp_path / "sky.hdr")
    (tmp_path / "scene.xml").write_text("""<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="8"/></film></sensor>
  <emitter type="envmap"><string name="filename" value="sky.hdr"/></emitter>
  <shape type="sphere"><float name="radius" value="0.5"/>
    <transform name="to_world"><translate z="3"/></transform></shape>
</scene>""")
    loaded = ep.load_mitsuba(tmp_path / "scene.xml")
    assert torch.equal(loaded.scene.envmap.values, ep.imread(tmp_path / "sky.hdr"))
    image = loaded.render(spp=2)
    assert torch.isfinite(image).all() and float(image.mean()) > 0


def test_to_srgb_is_the_curve_png_files_store(tmp_path):
    x = torch.tensor([[[0.0, 0.002, 0.0031308], [0.01, 0.2, 0.5], [0.9, 1.0, 3.0]]])  # (1, 3, 3)
    s = ep.to_srgb(x)
    assert s[0, 0, 0] == 0 and s[0, 2, 1] == pytest.approx(1.0) and s[0, 2, 2] == pytest.approx(1.0)
    assert float(s[0, 0, 1]) == pytest.approx(12.92 * 0.002)
    assert float(s[0, 1, 2]) == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055)
    assert float(s[0, 0, 2]) == pytest.approx(0.04045, abs=1e-5)  # the two pieces meet
    ep.imwrite(x, tmp_path / "x.png")
    stored = torch.from_numpy(np.array(Image.open(tmp_path / "x.png").convert("RGB"))).float()
    assert torch.equal(stored, torch.round(s * 255))
    assert isinstance(ep.to_srgb(x.numpy()), torch.Tensor)


def test_to_srgb_gradient_is_finite_and_matches_the_derivative():
    x = torch.tensor([0.0, 0.001, 0.25, 0.8, 2.0], dtype=torch.float64, requires_grad=True)
    ep.to_srgb(x).sum().backward()
    expected = torch.tensor([12.92, 12.92, 1.055 / 2.4 * 0.25 ** (1 / 2.4 - 1),
                             1.055 / 2.4 * 0.8 ** (1 / 2.4 - 1), 0.0], dtype=torch.float64)
    assert torch.allclose(x.grad, expected)


@pytest.mark.parametrize("channels", [None, 1, 2, 3, 4])
def test_show_returns_the_png_imwrite_writes(tmp_path, channels):
    shape = (7, 5) if channels is None else (7, 5, channels)
    image = torch.rand(shape, generator=torch.Generator().manual_seed(2)) * 1.2
    picture = ep.show(image)
    png = picture._repr_png_()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and png == picture.png
    ep.imwrite(image, tmp_path / "ref.png")
    mode = {None: "L", 1: "L", 2: "LA", 3: "RGB", 4: "RGBA"}[channels]
    shown = np.asarray(Image.open(io.BytesIO(png)).convert(mode))
    written = np.asarray(Image.open(tmp_path / "ref.png").convert(mode))
    assert shown.shape[:2] == (7, 5)
    assert np.array_equal(shown, written)
    picture.save(tmp_path / "saved.png")
    assert (tmp_path / "saved.png").read_bytes() == png
    assert repr(picture).startswith("Picture(5x7 PNG")


def test_show_refuses_what_is_not_an_image():
    with pytest.raises(ValueError, match=r"image: expected shape \(H, W\) or \(H, W, C\)"):
        ep.show(torch.zeros(3, 4, 5))
    with pytest.raises(ValueError, match="image: expected a torch.Tensor or numpy.ndarray"):
        ep.show([[0.0]])
