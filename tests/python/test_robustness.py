"""Hostile and real-world input at the core's border: ranges Embree and the kernels assume (a
process must never abort), degenerate triangles (skipped, not refused), Ctrl-C during long
calls, memory over many calls, values the core would silently misread, and the precision of
ray offsets far from the origin."""

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import pytest
import torch

import edgepath as ep
from edgepath import shapes
from test_api import to_world_look_at


def small_scene(resolution=(16, 16), **camera_args):
    """A triangle facing a camera at z = -5, lit by a square lamp behind the camera."""
    camera = dict(position=torch.tensor([0., 0., -5.]), look_at=torch.tensor([0., 0., 0.]),
                  resolution=resolution)
    camera.update(camera_args)
    tri = ep.Mesh(torch.tensor([[-1., -1., 0.], [0., 1., 0.], [1., -1., 0.]]),
                  torch.tensor([[0, 1, 2]]), material=ep.Material(diffuse=torch.tensor([.8, .4, .2])))
    lamp = ep.Mesh(torch.tensor([[-2., -2., -7.], [2., -2., -7.], [2., 2., -7.], [-2., 2., -7.]]),
                   torch.tensor([[0, 1, 2], [0, 2, 3]]), emission=torch.tensor([20., 20., 20.]))
    return ep.Scene(ep.Camera(**camera), [tri, lamp])


def run_child(code: str, *args, timeout=120):
    """Runs `code` in a fresh interpreter (a crash there cannot take the test run down)."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), *args], capture_output=True,
                          text=True, timeout=timeout)


# What a child process starts with: this file's small_scene.
CHILD_PRELUDE = f"""
import sys, time, torch, edgepath as ep
sys.path.insert(0, {str(os.path.dirname(os.path.abspath(__file__)))!r})
from test_robustness import small_scene
"""


# ---- ranges: never an abort ------------------------------------------------------------------

OUT_OF_RANGE = {
    "far camera": ("s = small_scene(position=torch.tensor([0., 0., -2e18]))", r"camera\.position"),
    "camera at 1e17": ("s = small_scene(position=torch.tensor([1e17, 0., -5.]))", r"camera\.position"),
    # Embree would miss a triangle this large this far away (products of three lengths overflow)
    "vertex at 2e12": ("s = small_scene(); s.meshes[0].vertices[1, 0] = 2e12",
                       r"meshes\[0\]\.vertices: value 2e\+12 of vertex 1 is out of range \(\|x\| <= 1e\+12\)"),
    "orthographic scale": ("s = small_scene(camera_type='orthographic', ortho_scale=1e19)",
                           r"camera\.ortho_scale"),
    "vertex at 1e19": ("s = small_scene(); s.meshes[0].vertices[1, 0] = 1e19",
                       r"meshes\[0\]\.vertices: value 1e\+19 of vertex 1"),
    # Products of three lengths would underflow: the scene's least extent is 1e-10
    "scene 3.5e-11 across": ("s = small_scene()\nfor m in s.meshes: m.vertices = m.vertices * 5e-12",
                           r"meshes: the vertices span 3\.5e-11 units"),
}


@pytest.mark.parametrize("name", list(OUT_OF_RANGE))
def test_coordinates_out_of_range_are_errors_not_aborts(name):
    """Embree asserts its rays are within about 1.8e18, and misses a large triangle far away
    beyond about 2e12: such scenes must be refused with the field named, in a process that goes
    on."""
    setup, field = OUT_OF_RANGE[name]
    result = run_child(CHILD_PRELUDE + setup + """
try:
    ep.render(s, spp=1)
except ValueError as error:
    print("ValueError:", error)
print("alive")
""")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "alive" in result.stdout
    assert re.search("ValueError: " + field, result.stdout), result.stdout


def test_largest_coordinates_in_range_render_finite():
    """Just inside the bound (1e12) everything still renders, with finite gradients."""
    s = small_scene(position=torch.tensor([0., 0., -1e12]), fov=1e-6)
    assert torch.isfinite(ep.render(s, spp=1, max_bounces=2)).all()
    s = small_scene(camera_type="orthographic", ortho_scale=1e12, resolution=(4, 16))
    assert torch.isfinite(ep.render(s, spp=1, max_bounces=2)).all()
    s = small_scene()
    s.meshes[1].vertices = s.meshes[1].vertices * 1.4e11
    s.meshes[1].vertices.requires_grad_(True)
    image = ep.render(s, spp=1, max_bounces=2)
    image.sum().backward()
    assert torch.isfinite(image).all() and torch.isfinite(s.meshes[1].vertices.grad).all()


# ---- degenerate triangles --------------------------------------------------------------------

def scene_with_extra(vertices_extra, tri_extra, shift=0.0):
    """small_scene's triangle mesh with extra vertices and triangles appended (shifted)."""
    s = small_scene()
    mesh = s.meshes[0]
    n = mesh.vertices.shape[0]
    mesh.vertices = torch.cat([mesh.vertices, torch.tensor(vertices_extra)]) + shift
    mesh.indices = torch.cat([mesh.indices, torch.tensor(tri_extra, dtype=torch.int64).reshape(-1, 3) + n])
    s.camera.position = s.camera.position + shift
    s.camera.look_at = s.camera.look_at + shift
    s.meshes[1].vertices = s.meshes[1].vertices + shift
    return s


def test_degenerate_triangles_render_as_nothing_with_zero_gradients():
    """A zero-area triangle (three collinear vertices, drawn where it would cover pixels if it
    had area) and one with two coincident vertices: the scene renders as without them, their
    own vertices get zero gradients, the others finite ones, and one warning names the mesh and
    the count."""
    extra = [[-0.5, 0.5, -1.], [0., 0.5, -1.], [0.5, 0.5, -1.], [0., -0.5, -1.], [0.5, -0.5, -1.]]
    s = scene_with_extra(extra, [[0, 1, 2], [3, 4, 4]])
    clean = scene_with_extra(extra, [])
    with pytest.warns(RuntimeWarning, match=r"meshes\[0\]: 2 of 3 triangles are degenerate"):
        image = ep.render(s, spp=4, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        expected = ep.render(clean, spp=4, seed=1)
    assert float(expected.sum()) > 0
    assert torch.equal(image, expected)

    vertices = s.meshes[0].vertices.detach().clone().requires_grad_(True)
    s.meshes[0].vertices = vertices
    with pytest.warns(RuntimeWarning):
        ep.render(s, spp=4, max_bounces=2).sum().backward()
    assert torch.isfinite(vertices.grad).all()
    assert vertices.grad[:3].abs().sum() > 0  # the real triangle's silhouette moves the image
    assert torch.equal(vertices.grad[3:], torch.zeros(5, 3))


def test_degenerate_triangles_far_from_the_rest_of_a_moving_mesh():
    """Degenerate triangles in a cluster of their own, at a vertex far from the others, on a mesh
    whose vertices require grad (the refittable BVH, Embree's two-level builder): they used to
    be boxes of zero size there, which failed an assertion of the builder and aborted the
    process (found by the fuzzer). Run in a child: it renders, with finite gradients."""
    result = run_child(CHILD_PRELUDE + textwrap.dedent("""
        import warnings
        from edgepath import shapes
        def scene(far):
            v, i = shapes.box((0., .5, 0.), (.3, .3, .3))
            v = v.clone()
            v[0, 0] = far
            floor = ep.Mesh(torch.tensor([[-1., 0., -1.], [1., 0., -1.], [1., 0., 1.], [-1., 0., 1.]]),
                            torch.tensor([[0, 2, 1], [0, 3, 2]]))
            lamp = ep.Mesh(torch.tensor([[-.2, 2., -.2], [.2, 2., -.2], [.2, 2., .2], [-.2, 2., .2]]),
                           torch.tensor([[0, 1, 2], [0, 2, 3]]), emission=torch.tensor([5., 5., 5.]))
            camera = ep.Camera(position=torch.tensor([0., 1.5, 3.]), look_at=torch.tensor([0., .3, 0.]),
                               resolution=(6, 8))
            return ep.Scene(camera, [floor, ep.Mesh(v.requires_grad_(True), i), lamp])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s = scene(1e6)
            image = ep.render(s, spp=2, seed=1, max_bounces=2)
            image.sum().backward()
        print(bool(torch.isfinite(image).all()), bool(torch.isfinite(s.meshes[1].vertices.grad).all()),
              any("triangles are degenerate" in str(w.message) for w in caught))
        """))
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["True", "True", "True"], result.stdout + result.stderr[-2000:]


def test_triangle_collapsing_during_an_optimisation_step():
    """Moving a vertex onto the opposite edge makes the triangle flat for one step: the step
    renders (with a warning) and backpropagates finite gradients instead of raising."""
    s = small_scene()
    v = torch.tensor([[-1., -1., 0.], [0., -1., 0.], [1., -1., 0.]], requires_grad=True)
    s.meshes[0].vertices = v
    with pytest.warns(RuntimeWarning, match="degenerate"):
        image = ep.render(s, spp=2, max_bounces=2)
        image.sum().backward()
    assert torch.isfinite(v.grad).all()
    assert float(image.detach().sum()) == 0.0  # nothing but the lamp behind the camera


def test_degenerate_test_is_relative_to_the_triangle():
    """The same small mesh moved to 1e6 from the origin (where a coordinate's ulp is 0.06, twice
    a tenth of its triangles' size) or scaled down by 1e-6 has no degenerate triangle."""
    v, i, _, _ = shapes.sphere((0., 0., 0.), 0.5, 8, 16)
    for transform in (lambda x: x + 1e6, lambda x: x * 1e-6):
        moved = transform(v.double()).float()
        cam_pos = transform(torch.tensor([[0., 0., -3.]], dtype=torch.float64)).float()[0]
        cam_at = transform(torch.zeros(1, 3, dtype=torch.float64)).float()[0]
        scene = ep.Scene(ep.Camera(position=cam_pos, look_at=cam_at, resolution=(8, 8)),
                         [ep.Mesh(moved, i, emission=torch.ones(3))])
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert float(ep.render(scene, spp=1, max_bounces=0).sum()) > 0


# ---- Ctrl-C ----------------------------------------------------------------------------------

INTERRUPT_CHILD = CHILD_PRELUDE + """
s = small_scene(resolution=(64, 64))
v = s.meshes[0].vertices.requires_grad_(True)
ep.render(s, spp=1, max_bounces=2)
calls = {
    "render": lambda: ep.render(s, spp=10**6),
    "backward": lambda: ep.render(s, spp=1, backward_spp=10**6).sum().backward(),
    "derivative_image": lambda: ep.derivative_image(s, v, torch.ones_like(v), spp=10**6),
}
print("ready", flush=True)
try:
    calls[sys.argv[1]]()
    print("finished", flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
    with torch.no_grad():
        print("usable", bool(torch.isfinite(ep.render(s, spp=1)).all()), flush=True)
"""


@pytest.mark.parametrize("call", ["render", "backward", "derivative_image"])
def test_ctrl_c_stops_long_core_calls(call):
    """SIGINT during a call that would take minutes raises KeyboardInterrupt within half a
    second, and the interpreter renders again afterwards."""
    # SIGINT at its default in the child: a shell's background job inherits it ignored, and Python
    # then installs no KeyboardInterrupt handler (the signal would be lost, the test hang).
    # Unbuffered: readline takes a byte at a time, so what follows its line stays in the pipe for
    # communicate (which reads the pipe itself: anything a buffered readline had taken past its
    # line would be lost to it).
    child = subprocess.Popen([sys.executable, "-c", INTERRUPT_CHILD, call], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, bufsize=0,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert child.stdout.readline().decode().strip() == "ready"
        time.sleep(0.5)  # inside the core call
        start = time.monotonic()
        child.send_signal(signal.SIGINT)
        line = child.stdout.readline().decode().strip()
        latency = time.monotonic() - start
        out, err = (b.decode() for b in child.communicate(timeout=60))
    finally:
        if child.poll() is None:
            child.kill()
    assert line == "interrupted", err[-2000:]
    assert latency < 0.5, f"{call}: KeyboardInterrupt after {latency:.3f} s"
    assert "usable True" in out
    assert child.returncode == 0


def interrupt_at_call(n):
    """A trace function that raises KeyboardInterrupt at the n-th Python function call (0-based)
    it sees, as a Ctrl-C handler would there; counts[0] is the number of calls seen."""
    counts = [0]

    def trace(frame, event, arg):
        if event == "call":
            counts[0] += 1
            if counts[0] - 1 == n:
                raise KeyboardInterrupt
        return None
    return trace, counts


@pytest.mark.parametrize("backward", [False, True])
def test_ctrl_c_at_any_python_call_of_a_render_is_never_lost(backward):
    """A Ctrl-C is handled at whichever Python bytecode runs when it arrives. Raised at each
    Python call of ep.render (and of its backward) in turn, KeyboardInterrupt reaches the caller
    every time: none lands in code whose caller discards it (torch's Tensor.__dlpack__ was, when
    the core's arguments were read as torch tensors, and the interrupt was lost)."""
    scene = small_scene((8, 8))
    diffuse = scene.meshes[0].material.diffuse.requires_grad_()

    def call():
        image = ep.render(scene, spp=1)
        if backward:
            image.sum().backward()

    lost, n = [], 0
    while True:  # until a call makes fewer than n + 1 Python calls (later calls reuse a cache)
        trace, counts = interrupt_at_call(n)
        sys.settrace(trace)
        try:
            call()
            if counts[0] <= n:
                break
            lost.append(n)
        except KeyboardInterrupt:
            pass
        finally:
            sys.settrace(None)
        diffuse.grad = None
        n += 1
    assert n > 100, n
    assert not lost, f"KeyboardInterrupt lost at calls {lost[:10]} of {n}"


# ---- memory ----------------------------------------------------------------------------------

def test_no_memory_growth_over_many_calls():
    """Render + backward on all threads, repeated: resident memory does not grow (each call
    used to keep 7-15 KiB in oneTBB's per-arena bookkeeping)."""
    result = run_child(CHILD_PRELUDE + """
def rss_kib():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 1024
s = small_scene(resolution=(32, 32))
v = s.meshes[0].vertices.requires_grad_(True)
def step():
    ep.render(s, spp=1, max_bounces=2, num_threads=2).sum().backward()
for _ in range(100):
    step()
before = rss_kib()
for _ in range(400):
    step()
print("growth_kib", rss_kib() - before)
""", timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    growth = float(result.stdout.split("growth_kib")[1])
    assert growth < 512, f"resident memory grew by {growth:.0f} KiB over 400 calls"


# ---- values the core would misread -----------------------------------------------------------

def to_world_at(z=-5.0):
    m = torch.eye(4)
    m[2, 3] = z
    return m


def camera_matrix_with(row, col, value):
    m = to_world_at()
    m[row, col] = value
    return m


BAD_INPUT = {
    "crop window past int32": (lambda: small_scene(crop_window=(2**31 - 1, 0, 2, 2)), {},
                               r"camera\.crop_window: .*does not fit"),
    "spp 2**31": (small_scene, dict(spp=2**31), r"spp: must be <= 2147483647"),
    "edge_samples 2**63": (small_scene, dict(edge_samples=2**63), r"edge_samples: must be <="),
    "resolution with more than 2**31 pixels": (lambda: small_scene(resolution=(2**16, 2**16)), {},
                                               r"camera\.resolution: .*pixels"),
    "NaN in to_world's first column": (
        lambda: small_scene(position=None, look_at=None, to_world=camera_matrix_with(1, 0, float("nan"))),
        {}, r"camera\.to_world: contains NaN"),
    "shear in to_world": (
        lambda: small_scene(position=None, look_at=None, to_world=camera_matrix_with(0, 1, 0.5)),
        {}, r"camera\.to_world: columns 0 and 1 are not orthogonal"),
    "to_world scaled unevenly": (
        lambda: small_scene(position=None, look_at=None, to_world=camera_matrix_with(0, 0, 2.0)),
        {}, r"camera\.to_world: scales its axes differently"),
    "to_world's bottom row": (
        lambda: small_scene(position=None, look_at=None, to_world=camera_matrix_with(3, 0, 0.5)),
        {}, r"camera\.to_world: bottom row"),
    "zero envmap to_world": (
        lambda: ep.Scene(small_scene().camera, small_scene().meshes,
                         ep.EnvironmentMap(torch.ones(4, 8, 3), to_world=torch.zeros(3, 3))),
        {}, r"envmap\.to_world: is not a rotation"),
    "radiance 1e38": (
        lambda: ep.Scene(small_scene().camera, [small_scene().meshes[0],
                                                ep.Mesh(small_scene().meshes[1].vertices,
                                                        small_scene().meshes[1].indices,
                                                        emission=torch.full((3,), 1e38))]),
        {}, r"meshes\[1\]\.emission: radiance 1e\+38 .*out of range"),
    "envmap radiance 1e38 by its scale": (
        lambda: ep.Scene(small_scene().camera, small_scene().meshes,
                         ep.EnvironmentMap(torch.ones(4, 8, 3), scale=1e38)),
        {}, r"envmap\.values: radiance 1e\+38"),
}


@pytest.mark.parametrize("name", list(BAD_INPUT))
def test_input_the_core_would_misread_is_refused(name):
    make, options, message = BAD_INPUT[name]
    with pytest.raises(ValueError, match=message):
        ep.render(make(), spp=options.pop("spp", 1), **options)


def test_huge_max_bounces_works():
    """max_bounces up to 2**31 - 1 renders and differentiates (paths end when they escape) instead
    of reserving room for 2**31 vertices per path."""
    s = small_scene()
    s.meshes[0].vertices.requires_grad_(True)
    image = ep.render(s, spp=1, max_bounces=2**31 - 1)
    image.sum().backward()
    assert torch.isfinite(image).all() and torch.isfinite(s.meshes[0].vertices.grad).all()
    with pytest.raises(ValueError, match=r"max_bounces: must be <= 2147483647"):
        ep.render(s, spp=1, max_bounces=2**31)


def test_camera_to_world_with_uniform_scale_is_the_same_camera():
    """A rotation times a uniform scale is allowed and renders as the unscaled matrix."""
    scaled = to_world_at()
    scaled[:3, :3] *= 3.0
    a = ep.render(small_scene(position=None, look_at=None, to_world=scaled), spp=2)
    b = ep.render(small_scene(position=None, look_at=None, to_world=to_world_at()), spp=2)
    assert float(b.sum()) > 0
    assert torch.allclose(a, b, rtol=1e-5, atol=1e-6)


def test_bright_radiance_within_range_stays_finite():
    s = small_scene()
    s.meshes[1].emission = torch.full((3,), 1e16)
    image = ep.render(s, spp=2, max_bounces=3)
    assert torch.isfinite(image).all() and float(image.max()) > 1e13


def test_light_in_a_glossy_floors_plane_gives_finite_gradients():
    """A point light just above a glossy floor's plane: the light arrives at grazing angles, where
    the GGX shadowing term's derivative once overflowed (zero times infinity: every gradient NaN,
    the image finite). The gradients are finite and, as the height goes to zero, tend to their
    value a little higher up."""
    def gradients(height):
        v = torch.tensor([[-1., 0., -1.], [1., 0., -1.], [1., 0., 1.], [-1., 0., 1.]], requires_grad=True)
        roughness = torch.tensor([0.3], requires_grad=True)
        floor = ep.Mesh(v, torch.tensor([[0, 2, 1], [0, 3, 2]]),
                        material=ep.Material(diffuse=torch.tensor([.5, .5, .5]),
                                             specular=torch.tensor([.2, .2, .2]), roughness=roughness))
        light = torch.tensor([height, height, height], requires_grad=True)
        camera = ep.Camera(position=torch.tensor([0., 1.5, 3.]), look_at=torch.tensor([0., 0., 0.]),
                           resolution=(12, 16))
        lamp = ep.PointLight(light, intensity=torch.tensor([2., 2., 2.]))
        s = ep.Scene(camera, [floor], point_lights=[lamp])
        image = ep.render(s, spp=2, max_bounces=1, seed=1)
        image.sum().backward()
        assert torch.isfinite(image).all()
        return torch.cat([v.grad.flatten(), roughness.grad, light.grad])

    reference = gradients(1e-9)
    assert torch.isfinite(reference).all() and float(reference.abs().max()) > 1.0
    for height in (1e-15, 1e-20, 1e-30):
        g = gradients(height)
        assert torch.isfinite(g).all(), height
        assert torch.allclose(g, reference, rtol=1e-3, atol=1e-3 * float(reference.abs().max())), height


def overflow_scene(diffuse):
    """A floor and a box under a lamp, the floor's diffuse reflectance `diffuse`: in range, but
    far above 1 its product over three bounces overflows float32."""
    floor = ep.Mesh(torch.tensor([[-1., 0., -1.], [1., 0., -1.], [1., 0., 1.], [-1., 0., 1.]]),
                    torch.tensor([[0, 2, 1], [0, 3, 2]]), material=ep.Material(diffuse=diffuse))
    box = ep.Mesh(torch.tensor([[-.3, .2, -.3], [.3, .2, -.3], [.3, .8, .3], [-.3, .8, .3]]),
                  torch.tensor([[0, 1, 2], [0, 2, 3]]),
                  material=ep.Material(diffuse=torch.tensor([.7, .3, .2])))
    lamp = ep.Mesh(torch.tensor([[-.2, 2., -.2], [.2, 2., -.2], [.2, 2., .2], [-.2, 2., .2]]),
                   torch.tensor([[0, 1, 2], [0, 2, 3]]), emission=torch.tensor([5., 5., 5.]))
    camera = ep.Camera(position=torch.tensor([0., 1.5, 3.]), look_at=torch.tensor([0., 0., 0.]),
                       resolution=(12, 16))
    return ep.Scene(camera, [floor, box, lamp], envmap=ep.EnvironmentMap(torch.full((4, 8, 3), 0.5)))


def test_an_image_that_overflows_is_an_error_not_inf():
    """Each value in range, their product over the bounces beyond float32: an error that says
    so, for one view and for many, never an image of Inf or NaN. Just below, a finite image."""
    with pytest.raises(ValueError, match=r"the rendered image: \d+ non-finite values .*float32 overflowed"):
        ep.render(overflow_scene(1e30), spp=2, max_bounces=3)
    scene = overflow_scene(1e30)
    with pytest.raises(ValueError, match=r"the rendered images: \d+ non-finite values"):
        ep.render(scene, cameras=[scene.camera, scene.camera], spp=2, max_bounces=3)
    image = ep.render(overflow_scene(1e9), spp=2, max_bounces=3)
    assert torch.isfinite(image).all() and float(image.max()) > 1e16


def test_a_gradient_that_overflows_warns_and_passes_inf_on():
    """A loss scaled beyond float32 overflows the vertices' gradient: a warning naming them, and
    the Inf handed on as torch's own operations hand it on (what a gradient scaler tests for).
    A loss that is itself NaN warns of nothing: the gradients follow from it."""
    def gradient(scale):
        scene = overflow_scene(torch.tensor([.5, .5, .5]))
        vertices = scene.meshes[0].vertices.requires_grad_(True)
        (ep.render(scene, spp=2, seed=1) * scale).sum().backward()
        return vertices.grad

    with pytest.warns(RuntimeWarning, match=r"the gradient with respect to meshes\[0\]\.vertices: "
                                            r"\d+ non-finite values"):
        g = gradient(3e38)
    assert not torch.isfinite(g).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert torch.isfinite(gradient(1.0)).all()
        assert not torch.isfinite(gradient(float("nan"))).all()


# ---- ray offsets -----------------------------------------------------------------------------

def offset_scene(shift=0.0, scale=1.0):
    """A floor, a box, a sphere with shading normals and an area light: shadow rays, bounces
    and contact, all placed at `shift` and scaled by `scale` (in double, then rounded)."""
    def place(v):
        return (v.double() * scale + shift).float()
    fv, fi, _, _ = shapes.grid((6., 6.), (4, 4))
    bv, bi = shapes.box((0., 0.5, 0.), (0.5, 0.5, 0.5))
    sv, si, _, sn = shapes.sphere((1.5, 0.6, 0.5), 0.6, 12, 24)
    lv, li = shapes.quad([[-1, 3, -1], [1, 3, -1], [1, 3, 1], [-1, 3, 1]])
    meshes = [ep.Mesh(place(fv), fi, material=ep.Material(diffuse=torch.tensor([.7, .7, .7]))),
              ep.Mesh(place(bv), bi, material=ep.Material(diffuse=torch.tensor([.6, .3, .2]))),
              ep.Mesh(place(sv), si, normals=sn, material=ep.Material(diffuse=torch.tensor([.2, .5, .3]))),
              ep.Mesh(place(lv), li, emission=torch.tensor([8., 8., 8.]))]
    camera = ep.Camera(position=place(torch.tensor([[0., 2.5, -6.]]))[0],
                       look_at=place(torch.tensor([[0., 0.5, 0.]]))[0], resolution=(32, 32))
    return ep.Scene(camera, meshes)


@pytest.mark.parametrize("placement", [dict(shift=1e4), dict(shift=1e5), dict(shift=-1e5),
                                       dict(scale=1e-5), dict(scale=1e4)],
                         ids=["shift 1e4", "shift 1e5", "shift -1e5", "scale 1e-5", "scale 1e4"])
def test_image_does_not_depend_on_where_the_scene_is(placement):
    """With ray offsets bounded by the hit point's rounding error, the same scene far from the
    origin or at another scale renders the same image sum to 1% (relative offsets made it 4-6%
    brighter)."""
    options = dict(spp=8, max_bounces=3, seed=1)
    base = float(ep.render(offset_scene(), **options).double().sum())
    moved = float(ep.render(offset_scene(**placement), **options).double().sum())
    assert base > 0
    assert moved == pytest.approx(base, rel=1e-2)


def scaled_gradients(scale):
    """offset_scene at ``scale``: its image sum, and the sums of |gradient| x scale of every
    mesh's vertices and of the camera position (what they are at scale 1, for the same paths)."""
    s = offset_scene(scale=scale)
    leaves = [m.vertices.requires_grad_() for m in s.meshes] + [s.camera.position.requires_grad_()]
    # 128 spp: the smooth sphere's paths round differently at another scale and its sum of
    # |gradient| is heavy-tailed; at 32 spp it moved by 0.88-1.14 between scales (8 seeds), at
    # 128 by 0.96-1.06.
    image = ep.render(s, spp=128, max_bounces=3, seed=1)
    image.sum().backward()
    return float(image.detach().double().sum()), [float(t.grad.double().abs().sum()) * scale for t in leaves]


@pytest.mark.parametrize("scale", [2e-11, 1e-4, 1e11],
                         ids=["scale 2e-11 (1.2e-10 across, the least extent)", "scale 1e-4",
                              "scale 1e11 (coordinates to 6e11)"])
def test_gradients_do_not_depend_on_the_scenes_scale(scale):
    """The same scene at another scale, up to the coordinate bound: the same image, and each
    gradient scaled by 1 / scale, within the noise of paths that round differently (about 5%
    here). Scaled up, areas, normals, MIS weights, re-solved hits and the secondary edges' plane
    once overflowed float: images with NaN pixels, gradients of NaN (the camera's) or 0 (the
    lamp's, at 1e10)."""
    base_sum, base = scaled_gradients(1.0)
    moved_sum, moved = scaled_gradients(scale)
    assert moved_sum == pytest.approx(base_sum, rel=1e-2)
    for k, (b, m) in enumerate(zip(base, moved)):
        assert b > 0 and m == pytest.approx(b, rel=0.12), f"leaf {k}: {m} against {b}"


@pytest.mark.parametrize("scale", [1e6, 1e10])
def test_a_to_world_camera_far_from_the_origin_looks_along_its_z_column(scale):
    """offset_scene at ``scale`` seen by its camera given as a to_world matrix renders the image
    of its position/look_at camera. look_at was position + z: a unit step lost to rounding at
    the position's magnitude, the direction off by up to a quarter at 6e6 units, and the camera
    refused (look_at equal to position) at 6e10."""
    s = offset_scene(scale=scale)
    matrix = to_world_look_at(*(t.double().tolist() for t in s.camera.frame()))
    framed = offset_scene(scale=scale)
    framed.camera = ep.Camera(to_world=matrix.float(), resolution=s.camera.resolution)
    options = dict(spp=4, max_bounces=1, seed=1)
    want, got = ep.render(s, **options).double(), ep.render(framed, **options).double()
    assert want.sum() > 0
    assert float((got - want).abs().mean()) < 1e-2 * float(want.mean())


def tiny_triangle_gradient(scale, sampling):
    """A triangle lit by a lamp, camera, all x scale: its image sum and its vertices' gradient
    x scale, interior terms only (the same paths at any scale)."""
    def place(rows):
        return (torch.tensor(rows, dtype=torch.float64) * scale).float()
    tri = ep.Mesh(place([[-1, -1, 0], [0, 1, 0], [1, -1, 0]]).requires_grad_(), torch.tensor([[0, 1, 2]]),
                  material=ep.Material(diffuse=torch.tensor([.7, .7, .7])))
    lamp = ep.Mesh(place([[-2, -2, -7], [2, -2, -7], [2, 2, -7], [-2, 2, -7]]), torch.tensor([[0, 1, 2], [0, 2, 3]]),
                   emission=torch.tensor([8., 8., 8.]))
    camera = ep.Camera(position=place([[0.3, 0.2, -5]])[0], look_at=torch.zeros(3), resolution=(16, 16))
    image = ep.render(ep.Scene(camera, [tri, lamp]), spp=4, max_bounces=1, seed=1, sampling=sampling,
                      primary_edges=False, secondary_edges=False)
    image.sum().backward()
    return float(image.detach().double().sum()), tri.vertices.grad.double() * scale


@pytest.mark.parametrize("sampling", ["light", "bsdf", "mis"])
def test_a_tiny_triangles_gradients_are_its_gradients_at_scale_one(sampling):
    """Embree returns barycentrics of 0 on triangles whose edges are below about 5e-10 units:
    the paths of a tiny scene once all left from a corner of the triangle they met, and its
    interior gradients were 1.7 to 3.7 times off (its image, traced apart, was right). Now the
    same as at scale 1, to rounding."""
    base_sum, base = tiny_triangle_gradient(1.0, sampling)
    assert base.abs().sum() > 0.5
    for scale in (1e-10, 3e-11):
        moved_sum, moved = tiny_triangle_gradient(scale, sampling)
        assert moved_sum == pytest.approx(base_sum, rel=1e-5)
        assert torch.allclose(moved, base, rtol=1e-3, atol=1e-4), f"{scale}: {moved} against {base}"
