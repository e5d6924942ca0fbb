"""edgepath: a differentiable Monte Carlo path tracer for triangle meshes.

    import torch, edgepath as ep
    scene = ep.Scene(camera=ep.Camera(...), meshes=[ep.Mesh(...), ...])
    image = ep.render(scene, spp=16)          # (H, W, 3) float32 tensor, linear radiance
    ep.imwrite(image, "out.png")
"""

from .io import imread, imwrite, load_obj
from .render import render
from .scene import Camera, EnvironmentMap, Material, Mesh, Scene

__version__ = "0.1.0"

__all__ = ["Camera", "EnvironmentMap", "Material", "Mesh", "Scene", "render", "imread",
           "imwrite", "load_obj", "__version__"]
