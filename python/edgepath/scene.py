"""Scene classes: plain holders of the tensors that describe a scene.

They keep exactly what they are given (no copies, no conversions), so a tensor with
``requires_grad`` stays the leaf the caller optimises. Everything is checked when the scene is
rendered (see ``_validate``), with errors that name the field, e.g. ``meshes[1].vertices``.

Conventions (as Mitsuba 3): images are (height, width, channels), row 0 at the top; the camera
looks from ``position`` towards ``look_at``, the image's right is normalize(cross(forward, up));
``fov`` is horizontal, in degrees; uv v = 0 is the top row of a texture image.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple, Union

import torch

Constant = Union[float, torch.Tensor]


# The core's bound on coordinates (scene/desc.h, kMaxCoordinate).
MAX_COORDINATE = 1e12


def frame_from_to_world(to_world: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(position, look_at, up) of a 4x4 camera-to-world matrix in Mitsuba's convention:
    columns are local x (towards the image's left), local y (up), local z (forward) and the
    translation. Built from torch ops, so gradients flow back to the matrix.

    ``look_at`` lies along local z as far from ``position`` as the position is from the origin
    (a power of two times the column, at least once it, within the coordinates' bound), so
    that ``look_at - position`` keeps the direction to float precision wherever the camera is:
    one step of a unit column is lost to rounding at 1e7 units and more."""
    position, forward = to_world[:3, 3], to_world[:3, 2]
    far = float(position.detach().abs().max())
    step = float(forward.detach().abs().max())
    reach = min(far, (MAX_COORDINATE - far) / step) if step > 0 else 1.0
    scale = 2.0 ** math.floor(math.log2(reach)) if reach >= 2 else 1.0
    return position, position + forward * scale, to_world[:3, 1]


class Camera:
    """A pinhole (``camera_type="perspective"``), thin lens (``"thinlens"``), orthographic,
    fisheye (``"fisheye"``, equidistant) or panorama (``"panorama"``, equirectangular) camera.

    Place it with ``position``/``look_at``/``up`` (tensors of shape (3,)), or with ``to_world``
    (4x4 camera-to-world matrix, see ``frame_from_to_world``), not both. ``resolution`` is
    (height, width) of the full film. ``fov``: horizontal field of view in degrees (a fisheye's
    full angle across the film's width, up to 360; outside its image circle the film is black;
    a panorama covers every direction and ignores it);
    ``ortho_scale``: half the width of an orthographic view; both a float or a 0-d tensor.
    ``aperture_radius`` and ``focus_distance`` (a float or a 0-d tensor each, both
    differentiable): a thin lens's aperture (a disk around ``position``, 0 = a pinhole) and the
    distance along the viewing direction of the plane it keeps in focus (Mitsuba's ``thinlens``);
    the other cameras ignore them.
    ``pixel_filter``: "box" (one pixel), "gaussian" (``filter_stddev`` pixels) or "tent"
    (``filter_radius`` pixels, at least 0.5).
    ``crop_window``: None or (x, y, width, height) in full-film pixels; renders only that part.
    """

    def __init__(self, position: Optional[torch.Tensor] = None,
                 look_at: Optional[torch.Tensor] = None,
                 up: Optional[torch.Tensor] = None,
                 fov: Constant = 45.0,
                 resolution: Tuple[int, int] = (256, 256),
                 camera_type: str = "perspective",
                 ortho_scale: Constant = 1.0,
                 to_world: Optional[torch.Tensor] = None,
                 pixel_filter: str = "box",
                 filter_stddev: float = 0.5,
                 crop_window: Optional[Tuple[int, int, int, int]] = None,
                 filter_radius: float = 1.0,
                 aperture_radius: Constant = 0.0,
                 focus_distance: Constant = 1.0):
        self.position = position
        self.look_at = look_at
        self.up = up
        self.fov = fov
        self.resolution = resolution
        self.camera_type = camera_type
        self.ortho_scale = ortho_scale
        self.to_world = to_world
        self.pixel_filter = pixel_filter
        self.filter_stddev = filter_stddev
        self.crop_window = crop_window
        self.filter_radius = filter_radius
        self.aperture_radius = aperture_radius
        self.focus_distance = focus_distance

    def frame(self) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(position, look_at, up), from ``to_world`` if it is set."""
        if self.to_world is not None:
            return frame_from_to_world(self.to_world)
        up = self.up if self.up is not None else torch.tensor([0.0, 1.0, 0.0])
        return self.position, self.look_at, up

    def __repr__(self):
        return (f"Camera(resolution={tuple(self.resolution)}, camera_type={self.camera_type!r}, "
                f"fov={self.fov})")


class Material:
    """A surface's BSDF, by ``kind``:

    "standard" (the default): diffuse (Lambert) plus a GGX specular lobe. ``diffuse`` /
    ``specular``: constant (shape (3,) or (1,), or a float) or texture (H, W, 3);
    ``roughness``: GGX alpha, a float, shape (1,), or texture (H, W) / (H, W, 1).

    "conductor": a smooth mirror reflecting ``specular`` at normal incidence (Schlick's
    Fresnel; 1.0 for a perfect mirror); ``diffuse`` and ``roughness`` are unused.

    "dielectric": glass, reflecting and refracting by the Fresnel equations with the relative
    index of refraction ``ior`` (inside over outside; a float, shape (1,), or texture (H, W));
    two-sided. Smooth where ``roughness`` is 0 (its default for this kind), elsewhere rough with
    it as GGX alpha (Walter et al. 2007, as Mitsuba's ``roughdielectric``); ``diffuse`` and
    ``specular`` are unused.

    "plastic": a diffuse base under a dielectric coating of relative index ``ior`` (a float or
    shape (1,)), as Mitsuba 3's ``roughplastic`` (GGX alpha ``roughness``, a float or shape
    (1,); 0.1 by default) or, where ``roughness`` is 0, its ``plastic`` (a smooth coating: a
    mirror reflection). The coating reflects ``specular`` (default 1.0) times its Fresnel
    reflectance; the base ``diffuse`` seen through it, divided by 1 - R for the light the
    coating reflects back into it (R its internal reflectance), or by 1 - ``diffuse`` R with
    ``nonlinear=True`` (Mitsuba's ``nonlinear``: saturated colours). ``roughness`` and ``ior``
    stay differentiable (the coating's transmittance tables carry their derivatives).

    ``two_sided``: False makes the back of a surface black (as Mitsuba's BSDFs). Every tensor
    is differentiable, ``ior`` included.

    ``normal_map``: None or a texture (H, W, 3), a tangent-space normal map as Mitsuba's
    ``normalmap``: a texel value v is the direction 2 v - 1 in the frame of the shading normal
    whose first axis is the triangle's dp/du (from its uvs, or its barycentrics without uvs);
    differentiable in its texels, and in the vertices, normals and uvs through the frame."""

    def __init__(self, diffuse: Constant = 0.5, specular: Optional[Constant] = None,
                 roughness: Optional[Constant] = None, two_sided: bool = False,
                 kind: str = "standard", ior: Constant = 1.5,
                 normal_map: Optional[torch.Tensor] = None, nonlinear: bool = False):
        self.diffuse = diffuse
        # None: 0.0 (a plastic: 1.0, Mitsuba's default)
        if specular is None:
            specular = 1.0 if kind == "plastic" else 0.0
        self.specular = specular
        # None: 0.5 (a dielectric: 0, smooth; a plastic: 0.1, Mitsuba's default)
        if roughness is None:
            roughness = {"dielectric": 0.0, "plastic": 0.1}.get(kind, 0.5)
        self.roughness = roughness
        self.two_sided = two_sided
        self.kind = kind
        self.ior = ior
        self.normal_map = normal_map
        self.nonlinear = nonlinear

    def __repr__(self):
        return f"Material(kind={self.kind!r}, two_sided={self.two_sided})"


class Spot:
    """A spot light's angular profile, as Mitsuba's ``spot``: emission is scaled by 1 within
    ``beam_width`` degrees of the axis ``direction`` (a (3,) tensor, any length), by 0 beyond
    ``cutoff_angle`` degrees, and linearly in the angle between (a continuous falloff, so its
    derivatives need no boundary terms). ``beam_width`` defaults to three quarters of
    ``cutoff_angle`` (as Mitsuba); 0 <= beam_width < cutoff_angle <= 180. Every value is
    differentiable (a tensor with ``requires_grad``)."""

    def __init__(self, direction: torch.Tensor, cutoff_angle: Constant = 20.0,
                 beam_width: Optional[Constant] = None):
        self.direction = direction
        self.cutoff_angle = cutoff_angle
        self.beam_width = beam_width

    def __repr__(self):
        return f"Spot(cutoff_angle={self.cutoff_angle}, beam_width={self.beam_width})"


class PointLight:
    """A light at a point (Mitsuba's ``point``, or its ``spot`` with ``spot``): radiant
    ``intensity`` (W/sr; a float, or (3,) / (1,)) from ``position`` (3,) in every direction, or
    scaled by a ``Spot`` profile. A delta light: found by next-event estimation only, it casts
    hard shadows whose moving outlines have no boundary terms (as in Mitsuba), so derivatives
    of the image where a shadow edge moves are missing; the shading it gives (intensity,
    position, the spot's profile, the lit surfaces) is differentiated exactly. For shadows
    with derivatives, give the light a radius (``edgepath.lights``)."""

    def __init__(self, position: torch.Tensor, intensity: Constant = 1.0,
                 spot: Optional[Spot] = None):
        self.position = position
        self.intensity = intensity
        self.spot = spot

    def __repr__(self):
        return f"PointLight(intensity={self.intensity}, spot={self.spot!r})"


class Mesh:
    """A triangle mesh. ``vertices`` (N, 3) float, ``indices`` (M, 3) int32/int64.

    Optional: ``uvs`` (K, 2) with ``uv_indices`` (M, 3) (or one uv per vertex without),
    ``normals`` (K, 3) shading normals with ``normal_indices`` (M, 3) (or one per vertex),
    ``material`` (default: diffuse 0.5, or black diffuse if the mesh emits), ``emission``:
    radiance, constant (3,) or texture (H, W, 3) over the uvs, which makes the mesh an area
    light emitting on the side of its face normal (both sides if ``two_sided_emission``).
    ``colors``: (N, 3) vertex colours, non-negative, one row per vertex (indexed by
    ``indices``); interpolated by the barycentrics, they multiply the material's diffuse
    reflectance (constant or texture) and are differentiable.
    ``spot``: a ``Spot`` profile that scales the emission by the direction it leaves in.
    ``light_sampling``: how next-event estimation samples an emitting mesh: "area" (a triangle
    by power, a point uniformly on it) or "solid_angle" (a direction uniformly in the cone of
    the mesh's bounding sphere, towards the first of its triangles along it: for small convex
    lights around a point, such as ``lights.sphere_light``, whose visible side it samples
    evenly) or "spherical_triangle" (a triangle by power, then a direction uniformly in the
    solid angle it subtends, falling back to area sampling where that angle is below 3e-4 sr
    or above 6.2 sr: for large lights close to what they light, such as a quad over a floor)."""

    def __init__(self, vertices: torch.Tensor, indices: torch.Tensor,
                 uvs: Optional[torch.Tensor] = None, normals: Optional[torch.Tensor] = None,
                 uv_indices: Optional[torch.Tensor] = None,
                 normal_indices: Optional[torch.Tensor] = None,
                 material: Optional[Material] = None,
                 emission: Optional[Constant] = None,
                 two_sided_emission: bool = False,
                 colors: Optional[torch.Tensor] = None,
                 spot: Optional[Spot] = None,
                 light_sampling: str = "area"):
        self.vertices = vertices
        self.indices = indices
        self.uvs = uvs
        self.normals = normals
        self.uv_indices = uv_indices
        self.normal_indices = normal_indices
        self.material = material
        self.emission = emission
        self.two_sided_emission = two_sided_emission
        self.colors = colors
        self.spot = spot
        self.light_sampling = light_sampling

    def __repr__(self):
        n = tuple(self.vertices.shape) if isinstance(self.vertices, torch.Tensor) else "?"
        m = tuple(self.indices.shape) if isinstance(self.indices, torch.Tensor) else "?"
        return f"Mesh(vertices={n}, indices={m}, emissive={self.emission is not None})"


class EnvironmentMap:
    """Lat-long environment light: ``values`` (H, W, 3) radiance, Mitsuba's mapping (row 0 is
    +y, the image centre looks along +z). ``to_world``: None, a 3x3 rotation or a 4x4 matrix
    (its translation is ignored); ``scale`` multiplies the radiance."""

    def __init__(self, values: torch.Tensor, to_world: Optional[torch.Tensor] = None,
                 scale: Constant = 1.0):
        self.values = values
        self.to_world = to_world
        self.scale = scale

    def __repr__(self):
        shape = tuple(self.values.shape) if isinstance(self.values, torch.Tensor) else "?"
        return f"EnvironmentMap(values={shape}, scale={self.scale})"


class Scene:
    """A camera, a list of meshes (some of them emitters), an optional environment map, and
    a list of ``PointLight``s (lights at a point, without a radius)."""

    def __init__(self, camera: Camera, meshes: Sequence[Mesh],
                 envmap: Optional[EnvironmentMap] = None,
                 point_lights: Sequence[PointLight] = ()):
        self.camera = camera
        self.meshes = meshes
        self.envmap = envmap
        self.point_lights = point_lights
        # The renderer's own scene (ray-tracing BVH, edge list), kept across renders and
        # updated from what changed (edgepath.render); never copied with the scene.
        self._core_cache = None

    def build_counts(self) -> dict:
        """How often renders of this scene built its ray-tracing BVHs afresh (``"builds"``: the
        first render, and any change of topology), refitted them (``"refits"``: only vertex
        positions moved) and reused them (``"reuses"``: only materials, lights, textures, the
        environment or the camera changed, or nothing). Two BVHs, each built at its first use and
        counted apart: an exact one for renders a gradient follows, and a fast one for images
        alone (docs/python-api.md)."""
        cache = getattr(self, "_core_cache", None)
        return cache.counts() if cache is not None else {"builds": 0, "refits": 0, "reuses": 0}

    def edge_hierarchy_counts(self) -> dict:
        """How often gradient passes of renders of this scene built its edge hierarchy afresh
        (``"builds"``: the first pass that samples the edges seen from path vertices, a change
        of topology or of which meshes' vertices need gradients), refitted it (``"refits"``:
        only vertex positions moved) and reused it (``"reuses"``: nothing it depends on moved;
        materials, lights, the environment or the camera changed, or nothing). One count per
        view of a call with several cameras."""
        cache = getattr(self, "_core_cache", None)
        return cache.hierarchy_counts() if cache is not None else {"builds": 0, "refits": 0, "reuses": 0}

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_core_cache"] = None
        return state

    def __repr__(self):
        lights = getattr(self, "point_lights", ())
        return (f"Scene(camera={self.camera!r}, meshes={len(self.meshes)}, envmap={self.envmap!r}"
                + (f", point_lights={len(lights)})" if lights else ")"))
