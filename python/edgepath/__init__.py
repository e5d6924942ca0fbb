"""edgepath: a differentiable Monte Carlo path tracer for triangle meshes.

    import torch, edgepath as ep
    scene = ep.Scene(camera=ep.Camera(...), meshes=[ep.Mesh(...), ...])
    image = ep.render(scene, spp=16)          # (H, W, 3) float32 tensor, linear radiance
    loss(image).backward()                    # gradients into every tensor that requires grad
    ep.imwrite(image, "out.png")
"""

from . import lights, shapes
from .io import Picture, imread, imwrite, load_obj, load_ply, save_obj, show, to_srgb
from .mitsuba import MitsubaError, MitsubaScene, load_mitsuba
from .render import (CHANNELS, ID_CHANNELS, derivative_channels, derivative_image,
                     finite_difference_channels, finite_difference_image, render, render_channels)
from .scene import Camera, EnvironmentMap, Material, Mesh, PointLight, Scene, Spot

# The one place the version is written: pyproject.toml and CMakeLists.txt read it from here.
__version__ = "0.1.0"

__all__ = ["CHANNELS", "ID_CHANNELS", "Camera", "EnvironmentMap", "Material", "Mesh", "PointLight",
           "Scene", "Spot",
           "render", "render_channels", "derivative_image", "derivative_channels",
           "finite_difference_image", "finite_difference_channels", "imread", "imwrite", "load_obj",
           "load_ply", "save_obj", "to_srgb", "show", "Picture", "shapes", "lights", "load_mitsuba",
           "MitsubaScene", "MitsubaError", "__version__"]
