"""The core scene kept across renders (``Scene._core_cache``): whatever changes between calls,
the image and the gradients equal those of a scene built afresh, bit for bit (on two threads:
the gradients' sums are made in the tiles' order whatever the thread count), and only what
changed is rebuilt (``build_counts``).
Once its vertices have moved, the kept scene's edge hierarchy is its refittable form (with the
nearly flat edges as empty leaves), refit at each move: the gradients that edge samples reach
then equal those of a twin with the same history, and of a scene built afresh in that form.
"""

import pytest
import torch

import edgepath as ep

SPP = 2
RES = (20, 24)


def make_scene():
    """A box on a floor under a square lamp, with an environment map; the parameters a test
    may differentiate are leaves that require grad."""
    box_v, box_i = ep.shapes.box(center=(0.0, 0.5, 0.0), half=(0.5, 0.5, 0.5))
    floor_v, floor_i = ep.shapes.quad([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]])
    lamp_v, lamp_i = ep.shapes.quad([[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]])
    camera = ep.Camera(position=torch.tensor([2.0, 2.5, -4.0], requires_grad=True),
                       look_at=torch.tensor([0.0, 0.5, 0.0]), fov=40.0, resolution=RES)
    box = ep.Mesh(box_v.clone().requires_grad_(), box_i,
                  material=ep.Material(diffuse=torch.tensor([0.6, 0.4, 0.3], requires_grad=True),
                                       specular=0.2,
                                       roughness=torch.tensor([0.4], requires_grad=True)))
    floor = ep.Mesh(floor_v, floor_i, material=ep.Material(diffuse=0.5))
    lamp = ep.Mesh(lamp_v, lamp_i, emission=torch.tensor([6.0, 6.0, 5.0], requires_grad=True))
    envmap = ep.EnvironmentMap(values=torch.full((4, 8, 3), 0.2).requires_grad_())
    return ep.Scene(camera=camera, meshes=[box, floor, lamp], envmap=envmap)


def leaves(scene):
    out = [scene.camera.position] + ([scene.envmap.values] if scene.envmap is not None else [])
    for mesh in scene.meshes:
        out += [mesh.vertices, mesh.emission]
        if mesh.material is not None:
            out += [mesh.material.diffuse, mesh.material.roughness]
    return [t for t in out if isinstance(t, torch.Tensor) and t.requires_grad]


def image_and_gradients(scene):
    image = ep.render(scene, spp=SPP, num_threads=2, seed=3, backward_seed=5)
    weight = torch.linspace(-1.0, 2.0, image.numel()).reshape(image.shape)
    params = leaves(scene)
    return image.detach(), torch.autograd.grad((image * weight).sum(), params)


def fresh(scene):
    """The same tensors in a new Scene object: no kept core scene."""
    return ep.Scene(camera=scene.camera, meshes=list(scene.meshes), envmap=scene.envmap)


# The kept scene's twin: a second kept scene that sees the same tensors and goes through the
# same calls (so its edge hierarchy is built and refit at the same points).
_twins = {}
# The vertices each kept scene was first rendered with, and whether they have moved since.
_first_vertices = {}
_moved = {}
# Whether the kept scene's edge hierarchy was refit since it was last built.
_refit = {}
# The scenes these are kept for, held alive: a scene freed after its test could otherwise give
# its id to a later test's scene, which would inherit its twin and history.
_alive = {}


def geometric(scene):
    """Which of leaves(scene) move the shading points and edges: the camera position and the
    vertices."""
    moving = [scene.camera.position] + [m.vertices for m in scene.meshes]
    return [any(t is m for m in moving) for t in leaves(scene)]


def assert_same_as_fresh(scene):
    """The image and the gradients equal those of a fresh scene, bit for bit. Once the kept
    scene's vertices have moved, its edge list keeps the nearly flat edges (empty leaves of its
    edge hierarchy, so that moves refit the tree): the gradients of the camera and the vertices,
    which the secondary edge samples reach, then equal those of a scene built afresh in that
    form (moving_form: built elsewhere, then moved here), not of a plain fresh scene. And where
    the kept hierarchy was refit since it was built (only vertices moved), a refit tree keeps
    the splits of the positions it was built at, so it samples those edges with other (still
    valid) probabilities than a fresh build: those gradients equal the twin's (the same history)
    instead. The other gradients do not see those samples (their random numbers are apart) and
    always equal the fresh scene's. (The refit tree itself is checked against a fresh build in
    tests/cpp/test_hierarchy.cpp and test_a_refit_edge_hierarchy_equals_a_fresh_one_that_splits_alike
    below.)"""
    assert _alive.setdefault(id(scene), scene) is scene
    twin = _twins.setdefault(id(scene), fresh(scene))
    twin.camera, twin.meshes, twin.envmap = scene.camera, list(scene.meshes), scene.envmap
    vertices = [m.vertices.detach().clone() for m in scene.meshes]
    first = _first_vertices.setdefault(id(scene), vertices)
    if len(first) != len(vertices) or any(not torch.equal(a, b) for a, b in zip(first, vertices)):
        _moved[id(scene)] = True
    before = scene.edge_hierarchy_counts()
    image, grads = image_and_gradients(scene)
    after = scene.edge_hierarchy_counts()
    if after["builds"] > before["builds"]:
        _refit[id(scene)] = False
    elif after["refits"] > before["refits"]:
        _refit[id(scene)] = True
    image_twin, grads_twin = image_and_gradients(twin)
    image_fresh, grads_fresh = image_and_gradients(fresh(scene))
    moved, refit = _moved.get(id(scene), False), _refit.get(id(scene), False)
    if moved:
        image_form, grads_form = image_and_gradients(moving_form(scene, [v * 0.5 for v in vertices]))
        assert torch.equal(image, image_form)
    assert torch.equal(image, image_fresh)
    assert torch.equal(image, image_twin)
    assert len(grads) == len(grads_fresh) == len(grads_twin)
    for k, (g, h, t, moves) in enumerate(zip(grads, grads_fresh, grads_twin, geometric(scene))):
        assert torch.equal(g, t)
        if not moves:
            assert torch.equal(g, h)
        elif not moved:
            assert torch.equal(g, h)
        elif not refit:
            assert torch.equal(g, grads_form[k])


def counts_after(scene, change):
    before = scene.build_counts()
    change()
    assert_same_as_fresh(scene)
    after = scene.build_counts()
    return {k: after[k] - before[k] for k in after}


def test_gradients_are_bit_reproducible_on_one_thread():
    """The gradient buffers land at other addresses each call; the sums must not care. Many
    parameters (a sphere's vertices, a textured environment map) overflow the gradient sink's
    cache, so which of them collide decides the order of the float additions."""
    scene = make_scene()
    v, i = ep.shapes.sphere(center=(1.2, 0.6, 0.8), radius=0.5, rings=12, segments=24)[:2]
    scene.meshes.append(ep.Mesh(v.requires_grad_(), i))
    scene.envmap.values = torch.rand(16, 32, 3, generator=torch.Generator().manual_seed(0)).requires_grad_()
    results = []
    for allocations in (0, 37, 1001):
        keep = [torch.zeros(n + 1) for n in range(allocations)]  # other addresses for the buffers
        results.append(image_and_gradients(fresh(scene))[1])
        del keep
    for grads in results[1:]:
        for g, h in zip(grads, results[0]):
            assert torch.equal(g, h)


def test_each_kind_of_change_gives_the_fresh_scene_and_rebuilds_only_what_it_must():
    scene = make_scene()
    box, floor, lamp = scene.meshes
    assert scene.build_counts() == {"builds": 0, "refits": 0, "reuses": 0}
    assert_same_as_fresh(scene)
    # Forward and backward: the image's BVH built, then the scene reused by the backward pass,
    # which builds the exact BVH (Scene.build_counts counts each BVH's builds and refits).
    assert scene.build_counts() == {"builds": 2, "refits": 0, "reuses": 1}
    nothing_rebuilt = {"builds": 0, "refits": 0, "reuses": 2}

    def material_colour():
        with torch.no_grad():
            box.material.diffuse.mul_(0.8)

    def roughness():
        box.material.roughness = torch.tensor([0.25], requires_grad=True)

    def light():
        with torch.no_grad():
            lamp.emission.add_(1.0)

    def camera():
        with torch.no_grad():
            scene.camera.position.add_(torch.tensor([0.1, -0.1, 0.05]))

    def envmap():
        with torch.no_grad():
            scene.envmap.values[1, 2] = 1.5

    hierarchy = scene.edge_hierarchy_counts()
    assert hierarchy == {"builds": 1, "refits": 0, "reuses": 0}
    for change in (material_colour, roughness, light, camera, envmap):
        assert counts_after(scene, change) == nothing_rebuilt, change.__name__
    # Nor is the edge hierarchy: one reuse per gradient pass.
    assert scene.edge_hierarchy_counts() == {"builds": 1, "refits": 0, "reuses": 5}

    def move_vertices():
        with torch.no_grad():
            box.vertices[:, 1] += 0.05 * box.vertices[:, 0]

    # The box's vertices require grad (Mesh "moves"): the scene was built in the form of a scene
    # whose vertices move (BVHs that can be refitted, the image's and the exact one, and the
    # edge hierarchy over the edge list that keeps the nearly flat edges, the box's face
    # diagonals), so every move refits them all, the first one too.
    hierarchy = scene.edge_hierarchy_counts()
    assert counts_after(scene, move_vertices) == {"builds": 0, "refits": 2, "reuses": 1}
    assert counts_after(scene, move_vertices) == {"builds": 0, "refits": 2, "reuses": 1}
    after = scene.edge_hierarchy_counts()
    assert {k: after[k] - hierarchy[k] for k in after} == {"builds": 0, "refits": 2, "reuses": 0}

    def new_vertices_same_shape():
        box.vertices = (box.vertices.detach() * 1.01).requires_grad_()

    hierarchy = scene.edge_hierarchy_counts()
    assert counts_after(scene, new_vertices_same_shape) == {"builds": 0, "refits": 2, "reuses": 1}
    after = scene.edge_hierarchy_counts()
    assert {k: after[k] - hierarchy[k] for k in after} == {"builds": 0, "refits": 1, "reuses": 0}

    def topology():  # the same shape, other triangles: two faces' winding flipped
        indices = box.indices.clone()
        indices[:2] = indices[:2].flip(1)
        box.indices = indices

    assert counts_after(scene, topology) == {"builds": 2, "refits": 0, "reuses": 1}

    def indices_in_place():
        with torch.no_grad():
            box.indices[2:4] = box.indices[2:4].flip(1).clone()

    assert counts_after(scene, indices_in_place) == {"builds": 2, "refits": 0, "reuses": 1}

    def add_mesh():
        v, i = ep.shapes.box(center=(-1.2, 0.3, 0.5), half=(0.2, 0.3, 0.2))
        scene.meshes.append(ep.Mesh(v.requires_grad_(), i, material=ep.Material(diffuse=0.3)))

    assert counts_after(scene, add_mesh) == {"builds": 2, "refits": 0, "reuses": 1}

    def remove_envmap():
        scene.envmap = None

    assert counts_after(scene, remove_envmap) == nothing_rebuilt


def moving_form(scene, before):
    """A new Scene with the tensors of ``scene``, its core scene first built with the vertices
    ``before`` (one tensor per mesh) and then moved to the scene's own: built afresh, at the
    scene's positions, in the form of a scene whose vertices move (a BVH built for refitting;
    an edge list that keeps the nearly flat edges, the edge hierarchy built over it)."""
    import copy
    meshes = []
    for mesh, vertices in zip(scene.meshes, before):
        moved = copy.copy(mesh)
        moved.vertices = vertices
        meshes.append(moved)
    out = ep.Scene(camera=scene.camera, meshes=meshes, envmap=scene.envmap)
    with torch.no_grad():
        ep.render(out, spp=1, num_threads=1)
    out.meshes = list(scene.meshes)
    return out


def assert_equal_results(a, b):
    image_a, grads_a = a
    image_b, grads_b = b
    assert torch.equal(image_a, image_b)
    assert len(grads_a) == len(grads_b)
    for g, h in zip(grads_a, grads_b):
        assert torch.equal(g, h)


def views_image_and_gradients(scene, views):
    images = ep.render(scene, cameras=views, spp=SPP, num_threads=2, seed=3, backward_seed=5)
    weight = torch.linspace(-1.0, 2.0, images.numel()).reshape(images.shape)
    params = [t for t in leaves(scene) if t is not scene.camera.position] + [c.position for c in views]
    return images.detach(), torch.autograd.grad((images * weight).sum(), params)


def test_a_refit_edge_hierarchy_equals_a_fresh_one_that_splits_alike():
    """Every vertex scaled by two: the median splits of a fresh build compare the same numbers
    times two and split alike, so the kept hierarchy, refit, must be the fresh one bit for bit,
    and so must every gradient, for one view and for many views in one call. Vertices that
    require grad build the form of a scene whose vertices move from the first call (nearly flat
    edges kept, as empty leaves); every move refits that tree, the first one too, compared with a
    scene built afresh in that form at the same positions. A one-sided material made two-sided (which changes which creases the
    hierarchy skips from behind), and a mesh made an emitter, are taken up without a rebuild,
    the same way."""
    scene = make_scene()
    assert_same_as_fresh(scene)

    def scale_vertices():
        before = [mesh.vertices.detach() for mesh in scene.meshes]
        for mesh in scene.meshes:
            mesh.vertices = (mesh.vertices.detach() * 2.0).requires_grad_(mesh.vertices.requires_grad)
        return before

    def refit_step(results):
        before = scale_vertices()
        counts = scene.edge_hierarchy_counts()
        kept = results(scene)
        after = scene.edge_hierarchy_counts()
        assert {k: after[k] - counts[k] for k in after} == {"builds": 0, "refits": 1, "reuses": 0}
        built = moving_form(scene, before)
        assert_equal_results(kept, results(built))
        assert built.edge_hierarchy_counts()["builds"] == 1
        return before

    refit_step(image_and_gradients)  # the first move
    refit_step(image_and_gradients)
    views = [ep.Camera(position=torch.tensor(p, requires_grad=True), look_at=torch.tensor([0.0, 1.0, 0.0]),
                       fov=40.0, resolution=RES) for p in ([4.0, 5.0, -8.0], [-6.0, 4.0, -5.0])]
    # Many views in one call: the views share the refit tree (one refit, then reuses).
    counts = scene.edge_hierarchy_counts()
    before = scale_vertices()
    kept = views_image_and_gradients(scene, views)
    after = scene.edge_hierarchy_counts()
    assert {k: after[k] - counts[k] for k in after} == {"builds": 0, "refits": 1, "reuses": 1}
    assert_equal_results(kept, views_image_and_gradients(moving_form(scene, before), views))
    assert all(float(g.abs().max()) > 0 for g in kept[1][-2:])

    def same_as_fresh_without_a_build():
        builds = scene.edge_hierarchy_counts()["builds"]
        kept = image_and_gradients(scene)
        assert scene.edge_hierarchy_counts()["builds"] == builds
        assert_equal_results(kept, image_and_gradients(moving_form(scene, before)))

    scene.meshes[0].material.two_sided = True
    same_as_fresh_without_a_build()
    # The box made an emitter (its creases then count at a last bounce): the same.
    scene.meshes[0].emission = torch.tensor([0.5, 0.5, 0.5])
    same_as_fresh_without_a_build()


def test_moves_that_turn_an_edge_flat_and_back_refit_the_edge_hierarchy():
    """A floor of two triangles whose far corner is lifted by 1e-4 of its size (a fold: the
    diagonal is an edge) or by 1e-7 (one plane up to rounding: a scene built afresh drops the
    diagonal), a box on it under a lamp. A scene kept across vertex steps keeps the diagonal
    (flat when the faces are one plane: an empty leaf of its edge hierarchy), so its edge list is
    the same at every step and each step refits the hierarchy, as it refits the BVH; before, a
    step that turned the diagonal flat or back changed the edge list (here, back and forth
    between two lists, it took the other of the two trees the scene keeps, not refit to the
    new positions; test_a_finely_tessellated_sphere_scaled_by_rounding_refits: rebuilt). The
    refit hierarchy gives
    what a scene built afresh in the same form at those positions gives, bit for bit (the lift
    is too small to change a split), and so does a twin with the same history."""
    box_v, box_i = ep.shapes.box(center=(0.3, 0.5, 0.2), half=(0.4, 0.5, 0.4))
    lamp_v, lamp_i = ep.shapes.quad([[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]])
    floor_i = torch.tensor([[0, 2, 1], [1, 2, 3]], dtype=torch.int32)

    def floor_vertices(lift):
        return torch.tensor([[-2.0, 0.0, -2.0], [2.0, 0.0, -2.0], [-2.0, 0.0, 2.0], [2.0, 4.0 * lift, 2.0]],
                            requires_grad=True)

    camera = ep.Camera(position=torch.tensor([1.0, 3.0, -5.0]), look_at=torch.tensor([0.0, 0.3, 0.0]),
                       fov=45.0, resolution=RES)
    floor = ep.Mesh(floor_vertices(1e-4), floor_i, material=ep.Material(diffuse=0.6))
    meshes = [floor, ep.Mesh(box_v, box_i, material=ep.Material(diffuse=0.4)),
              ep.Mesh(lamp_v, lamp_i, emission=torch.tensor([6.0, 6.0, 5.0]))]
    scene, twin = ep.Scene(camera, meshes), ep.Scene(camera, list(meshes))

    def results(s):
        image = ep.render(s, spp=SPP, num_threads=2, seed=3, backward_seed=5)
        weight = torch.linspace(-1.0, 2.0, image.numel()).reshape(image.shape)
        return image.detach(), torch.autograd.grad((image * weight).sum(), [floor.vertices])

    results(scene), results(twin)  # at rest: built
    floor.vertices = floor_vertices(1e-7)
    results(scene), results(twin)  # the first move: the moving form, built
    builds, hierarchy = scene.build_counts(), scene.edge_hierarchy_counts()
    for lift in (1e-4, 1e-7, 1e-4, 1e-7):
        before = [m.vertices.detach() for m in scene.meshes]
        floor.vertices = floor_vertices(lift)
        kept = results(scene)
        assert float(kept[1][0].abs().max()) > 0
        assert_equal_results(kept, results(twin))
        assert_equal_results(kept, results(moving_form(scene, before)))
    after = scene.edge_hierarchy_counts()
    assert {k: after[k] - hierarchy[k] for k in after} == {"builds": 0, "refits": 4, "reuses": 0}
    after = scene.build_counts()
    assert {k: after[k] - builds[k] for k in after} == {"builds": 0, "refits": 8, "reuses": 4}


def flat_pairs(vertices, indices):
    """Per pair of faces sharing an edge (welded by position, in a fixed order), whether the
    core takes them for one plane: within 1e-5 rad, in double precision from the float corners
    (scene/edges.cpp, nearly_coplanar)."""
    v = vertices.detach()
    _, weld = torch.unique(v, dim=0, return_inverse=True)
    idx = indices.long()
    t = v.double()[idx]
    n = torch.linalg.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    a, b = weld[idx], weld[idx].roll(-1, dims=1)
    lo, hi = torch.minimum(a, b).reshape(-1), torch.maximum(a, b).reshape(-1)
    face = torch.arange(idx.shape[0]).repeat_interleave(3)
    ok = (lo != hi) & (n.norm(dim=1) > 0).repeat_interleave(3)
    key, face = (lo * (int(weld.max()) + 1) + hi)[ok], face[ok]
    key, order = torch.sort(key, stable=True)
    face = face[order]
    pair = key[1:] == key[:-1]
    f0, f1 = face[:-1][pair], face[1:][pair]
    c = (n[f0] * n[f1]).sum(dim=1)
    return (c > 0) & (torch.linalg.cross(n[f0], n[f1]).norm(dim=1) <= 1e-5 * c)


def test_a_finely_tessellated_sphere_scaled_by_rounding_refits():
    """bench/persist.py's vertex step on a smaller sphere (112 rings, 25k triangles): scaled in
    place by 1 + 1e-4 and 1 - 1e-4 in turn, its planar quads' diagonals cross the coplanar bound
    by rounding (checked: the faces' pairs taken for one plane change between steps), which
    rebuilt the edge hierarchy at those steps; the kept scene's edge list now keeps them (flat),
    so every step after the first move refits the hierarchy and both BVHs (the image's and the
    exact one)."""
    v, i = ep.shapes.sphere(radius=1.0, rings=112, segments=112)[:2]
    floor_v, floor_i = ep.shapes.quad([[-4, -1, -4], [-4, -1, 4], [4, -1, 4], [4, -1, -4]])
    lamp_v, lamp_i = ep.shapes.quad([[-1, 4, -1], [1, 4, -1], [1, 4, 1], [-1, 4, 1]])
    sphere = ep.Mesh(v.clone().requires_grad_(), i, material=ep.Material(diffuse=0.5))
    meshes = [sphere, ep.Mesh(floor_v, floor_i), ep.Mesh(lamp_v, lamp_i, emission=torch.tensor([8.0, 8.0, 7.0]))]
    pixel = ep.Camera(position=torch.tensor([0.0, 1.5, 3.5]), look_at=torch.zeros(3), fov=45.0,
                      resolution=(64, 64), crop_window=(32, 32, 1, 1))
    scene = ep.Scene(pixel, meshes)

    def step(k):
        with torch.no_grad():
            sphere.vertices.mul_(1.0 + 1e-4 * (-1) ** k)
        (g,) = torch.autograd.grad(ep.render(scene, spp=1).sum(), [sphere.vertices])
        return flat_pairs(sphere.vertices, i)

    step(0)  # built
    flats = [step(1)]  # the first move: built in the moving form
    builds, hierarchy = scene.build_counts(), scene.edge_hierarchy_counts()
    for k in range(2, 8):
        flats.append(step(k))
    changed = sum(int((a != b).sum()) for a, b in zip(flats, flats[1:]))
    assert changed > 0, "the steps should turn some diagonals flat or back"
    after = scene.edge_hierarchy_counts()
    assert {key: after[key] - hierarchy[key] for key in after} == {"builds": 0, "refits": 6, "reuses": 0}
    after = scene.build_counts()
    assert {key: after[key] - builds[key] for key in after} == {"builds": 0, "refits": 12, "reuses": 6}


def test_never_stale():
    """Edits the kept scene cannot see by shape or identity: in place under no_grad, a new
    tensor of the same shape and dtype, an int64 index tensor converted anew, uvs that change
    only the edge list (a uv seam), a degenerate triangle appearing."""
    scene = make_scene()
    box = scene.meshes[0]
    assert_same_as_fresh(scene)

    def vertex_in_place():
        with torch.no_grad():
            box.vertices[0, 0] += 0.2

    def swap_vertices_for_equal_copy_then_edit():
        box.vertices = box.vertices.detach().clone().requires_grad_()
        with torch.no_grad():
            box.vertices[3] *= 0.9

    def int64_indices():
        box.indices = box.indices.to(torch.int64).flip(0)

    def uvs():
        box.uvs = torch.rand(box.vertices.shape[0], 2, generator=torch.Generator().manual_seed(1))

    def uvs_in_place():
        with torch.no_grad():
            box.uvs[0] = torch.tensor([0.9, 0.1])

    def degenerate_triangle():
        with torch.no_grad():
            i0, i1, _ = box.indices[5].tolist()
            box.vertices[i1] = box.vertices[i0]

    for change in (vertex_in_place, swap_vertices_for_equal_copy_then_edit, int64_indices, uvs,
                   uvs_in_place):
        change()
        assert_same_as_fresh(scene)
    change = degenerate_triangle
    change()
    with pytest.warns(RuntimeWarning, match="degenerate"):
        assert_same_as_fresh(scene)


def test_a_failed_update_does_not_leave_a_broken_scene():
    scene = make_scene()
    assert_same_as_fresh(scene)
    good = scene.meshes[0].vertices.detach().clone()
    with torch.no_grad():
        scene.meshes[0].vertices[0, 0] = float("nan")
    with pytest.raises(ValueError, match=r"meshes\[0\]\.vertices"):
        ep.render(scene, spp=1)
    with torch.no_grad():
        scene.meshes[0].vertices.copy_(good)
    assert_same_as_fresh(scene)


def test_a_scene_rendered_from_threads_at_once():
    """A call that finds the kept scene busy builds one of its own: no waiting, same images."""
    from concurrent.futures import ThreadPoolExecutor
    scene = make_scene()

    def image(_):  # no gradient wanted, as for the expected image (torch's grad mode is per thread)
        with torch.no_grad():
            return ep.render(scene, spp=SPP, num_threads=1)

    with torch.no_grad():
        expected = ep.render(fresh(scene), spp=SPP, num_threads=1)
    with ThreadPoolExecutor(4) as pool:
        images = list(pool.map(image, range(8)))
    for image in images:
        assert torch.equal(image, expected)
    counts = scene.build_counts()
    assert counts["builds"] >= 1 and counts["builds"] + counts["reuses"] <= 8


def test_copies_do_not_share_the_kept_scene():
    import copy
    scene = make_scene()
    with torch.no_grad():
        ep.render(scene, spp=1)
    twin = copy.deepcopy(scene)
    assert twin.build_counts() == {"builds": 0, "refits": 0, "reuses": 0}
    with torch.no_grad():
        assert torch.equal(ep.render(twin, spp=1), ep.render(scene, spp=1))
