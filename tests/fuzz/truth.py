"""A search for wrong gradients: the fuzzer's API scene (fuzz.py: _api_scene) in random valid
forms (corpus.PLACED_VARIANTS: camera types, pixel filters, material kinds, bounce counts), a
random continuous parameter of it and a random direction in that parameter's space; the
derivative image (forward mode, every term on) against central finite differences, over
several seeds each, projected on three weightings of the image (its sum, random weights in
[-1, 1] per value, the signs of an independent derivative image). A case is off where a projection's two means differ by
more than 4.5 standard errors plus 3% of the finite difference (and a thousandth of its L1
norm): a lead to check with more samples (--replay, with --seeds and --spp).

What it cannot tell from a bug, by design of the estimators (docs/gradients.md): the point
lights' hard shadows have no boundary term (the scene keeps none here), and the edges seen
from the camera after two smooth faces where one is curved (through both sides of a glass
ball) are missing, and so are those seen in a mirror from a later vertex (the outlines seen in
one curved face have their term since it was written; the classification below still counts
them as limited); a case that moves geometry seen in a
smooth material may be off for that reason (reported apart, as "limited"), unless the only
smooth surface is the floor made a flat mirror or flat glass, at one bounce, seen by a pinhole,
thin lens or orthographic camera (the outlines in it and through it have their term).
Heavy-tailed derivatives (glass at grazing angles) make a case look off now and then: more
seeds settle it.

    python tests/fuzz/truth.py --cases 200 --seed 1 [--log FILE]
    python tests/fuzz/truth.py --replay '{"forms": [...], "param": "box.normals", "seed": 5}'
"""

import argparse
import json
import math
import os
import random
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import corpus  # noqa: E402
import fuzz  # noqa: E402

# (object, field, finite-difference step): the continuous values of the API scene.
PARAMS = [("floor", "vertices", 0.01), ("box", "vertices", 0.01), ("lamp", "vertices", 0.01),
          ("box", "normals", 0.01), ("box", "colors", 0.01), ("floor", "uvs", 0.01),
          ("camera", "position", 0.01), ("camera", "look_at", 0.01), ("camera", "up", 0.01),
          ("camera", "fov", 0.2), ("camera", "to_world", 0.005), ("camera", "aperture_radius", 0.005),
          ("camera", "focus_distance", 0.02), ("camera", "ortho_scale", 0.01),
          ("floor_material", "diffuse", 0.01), ("floor_material", "specular", 0.01),
          ("floor_material", "roughness", 0.01), ("floor_material", "normal_map", 0.01),
          ("box_material", "diffuse", 0.01), ("box_material", "roughness", 0.01), ("box_material", "ior", 0.01),
          ("lamp", "emission", 0.05), ("envmap", "values", 0.01), ("envmap", "scale", 0.01)]
STEPS = {(target, field): eps for target, field, eps in PARAMS}
# The forms that make a surface a smooth mirror or glass, and the values that are not geometry
# or the camera: a case with the former that moves the latter may see an outline move in a
# reflection or through glass, whose term is left out by design. Such a case that is off is
# reported as "limited" (in the log, counted, not printed): look at them when nothing else is off.
SMOOTH_FORMS = {("floor_kind", "conductor"), ("floor_kind", "dielectric"), ("box_kind", "conductor")}
# The forms drawn: the placed kind's, and the floor without its normal map (flat: a planar
# mirror or pane, where it is one). A flat mirror or glass floor's outlines have their term
# where the camera is not a fisheye or panorama and paths have one bounce (the camera's
# reflection or refraction only).
FORMS = dict(corpus.PLACED_VARIANTS, floor_shading=[("floor_normal_map", None)])
PLANAR = {("floor_normal_map", None), ("max_bounces", 1)}
PLANAR_FLOORS = {("floor_kind", "conductor"), ("floor_kind", "dielectric")}
NOT_PLANAR_CAMERAS = {("camera_type", "fisheye"), ("camera_type", "panorama")}
NOT_GEOMETRY = {"floor_material.diffuse", "floor_material.specular", "floor_material.roughness",
                "box_material.diffuse", "box_material.roughness", "box_material.ior", "lamp.emission",
                "envmap.values", "envmap.scale", "box.colors"}


def build(ep, forms):
    """The API scene in `forms` (fuzz.api_scene_in_forms), without point lights; its values as
    plain tensors (fov one too). Returns (scene, objects, max_bounces)."""
    import torch
    scene, objects, bounces, _ = fuzz.api_scene_in_forms(ep, forms)
    scene.point_lights = []
    camera = objects["camera"]
    if not isinstance(camera.fov, torch.Tensor):
        camera.fov = torch.tensor(float(camera.fov))
    for obj in objects.values():
        for name, value in vars(obj).items():
            if isinstance(value, torch.Tensor) and value.requires_grad:
                setattr(obj, name, value.detach())
    return scene, objects, bounces


def draw_case(rng):
    groups = sorted(g for g in FORMS if g != "call")
    forms = [list(rng.choice(FORMS[g])) for g in rng.sample(groups, rng.randrange(4))]
    target, field, _ = rng.choice(PARAMS)
    return {"forms": forms, "param": f"{target}.{field}", "seed": rng.randrange(1 << 30)}


def run_case(ep, case, seeds=12, spp=128, fd_spp=512):
    """The case's projections (derivative mean, finite-difference mean, standard error) and the
    names of those off; None where the scene in these forms has no such tensor."""
    import torch
    target, field = case["param"].split(".")
    scene, objects, bounces = build(ep, [tuple(f) for f in case["forms"]])
    param = getattr(objects[target], field, None)
    if not isinstance(param, torch.Tensor):
        return None
    gen = torch.Generator().manual_seed(case["seed"])
    direction = torch.rand(param.shape, generator=gen) * 2 - 1
    if field == "to_world":
        # Stays a camera matrix to first order: the axes turned (a skew-symmetric W times
        # them), the position moved, the bottom row (0, 0, 0, 1).
        w = direction[:3, :3] - direction[:3, :3].T
        direction[:3, :3] = w @ param[:3, :3]
        direction[3] = 0.0
    d = torch.stack([ep.derivative_image(scene, param, direction, spp=spp, seed=k, max_bounces=bounces).double()
                     for k in range(seeds)])
    f = torch.stack([ep.finite_difference_image(scene, param, direction, eps=STEPS[(target, field)], spp=fd_spp,
                                                seed=1000 + k, max_bounces=bounces).double() for k in range(seeds)])
    mean_f = f.mean(0)
    # The signs of an independent derivative image (those of the finite differences' own mean
    # would favour their noise: sign(x) x is |x|).
    signs = torch.sign(ep.derivative_image(scene, param, direction, spp=spp, seed=10_000, max_bounces=bounces).double())
    weights = {"sum": torch.ones_like(mean_f),
               "signed": torch.rand(mean_f.shape, generator=gen, dtype=torch.float64) * 2 - 1,
               "sign": signs}
    floor = 1e-3 * float(mean_f.abs().sum())
    out, off = {}, []
    for name, w in weights.items():
        a, b = (d * w).sum((1, 2, 3)), (f * w).sum((1, 2, 3))
        ma, mb = float(a.mean()), float(b.mean())
        se = math.sqrt(float(a.var() + b.var()) / seeds)
        out[name] = [round(ma, 5), round(mb, 5), round(se, 5)]
        if abs(ma - mb) > 4.5 * se + 0.03 * abs(mb) + floor:
            off.append(name)
    return {"bounces": bounces, "projections": out, "off": off}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0, help="seed of the cases drawn")
    parser.add_argument("--replay", help="one case, as JSON (a line of the log's 'case')")
    parser.add_argument("--seeds", type=int, default=12, help="renders per estimate")
    parser.add_argument("--spp", type=int, default=128, help="the derivative's; the finite difference gets 4x")
    parser.add_argument("--log", help="a JSON line per case")
    args = parser.parse_args(argv)
    import edgepath as ep
    cases = [json.loads(args.replay)] if args.replay else [draw_case(random.Random(args.seed * 100003 + i))
                                                            for i in range(args.cases)]
    log = open(args.log, "a") if args.log else None
    counts = {"ok": 0, "off": 0, "limited": 0, "none": 0, "error": 0}
    for case in cases:
        start = time.time()
        try:
            result = run_case(ep, case, args.seeds, args.spp, 4 * args.spp)
            outcome = "none" if result is None else "off" if result["off"] else "ok"
            forms = {tuple(form) for form in case["forms"]}
            if outcome == "off" and case["param"] not in NOT_GEOMETRY and forms & SMOOTH_FORMS and \
                    not (forms >= PLANAR and forms & PLANAR_FLOORS and not forms & NOT_PLANAR_CAMERAS
                         and ("box_kind", "conductor") not in forms):
                outcome = "limited"
        except Exception as error:  # a valid scene moved along a valid direction: a finding too
            result, outcome = {"error": f"{type(error).__name__}: {error}"}, "error"
        counts[outcome] += 1
        line = {"case": case, "outcome": outcome, "seconds": round(time.time() - start, 2), **(result or {})}
        if log:
            print(json.dumps(line), file=log, flush=True)
        if outcome in ("off", "error") or args.replay:
            print(json.dumps(line), flush=True)
    print(f"{counts['ok']} agree, {counts['off']} off, {counts['limited']} off where a smooth surface may show a "
          f"moving outline, {counts['error']} raised, {counts['none']} without the parameter")
    return 1 if counts["off"] or counts["error"] else 0


if __name__ == "__main__":
    sys.exit(main())
