"""Adversarial scenes: change what an image classifier sees by changing the scene.

First a small convolutional classifier (plain torch, trained here, no downloaded weights) learns
to tell a sphere, a box and a cylinder apart from edgepath renders under random rotation,
viewpoint and lighting. Then, starting from a box it classifies correctly, gradient descent
through the classifier and the renderer moves the camera, the lamp and the box's vertices
(a small displacement each) to raise the probability of "sphere", until the top class changes.
Writes the training samples, the scene before and after, and the class probabilities against
iteration.

    python examples/adversarial.py [--iterations 100] [--size 32] [--train-per-class 150] [--output-dir DIR]
"""

import math

import torch

import edgepath as ep
from edgepath import shapes
from _common import output_dir, parser, plot, rotation, row, run, save_images, weld

CLASSES = ("sphere", "box", "cylinder")
BASE_V, BASE_I = weld(*shapes.sphere(radius=1.0, rings=12, segments=24)[:2])


def class_vertices(name: str) -> torch.Tensor:
    """The same welded sphere mesh pushed onto a sphere, a cube or a cylinder (size about 1.6)."""
    v = BASE_V
    if name == "box":
        v = v / v.abs().max(dim=1, keepdim=True).values
        v = v * 0.75
    elif name == "cylinder":
        radial = v[:, [0, 2]].norm(dim=1, keepdim=True)
        v = v / torch.maximum(radial, v[:, 1:2].abs()) * 0.8
    else:
        v = v * 0.85
    return v


def camera_at(azimuth: torch.Tensor, elevation: torch.Tensor, size: int) -> ep.Camera:
    """A camera 3.5 units from the origin at the given angles (radians), looking at it."""
    position = 3.5 * torch.stack([torch.cos(elevation) * torch.sin(azimuth), torch.sin(elevation),
                                  torch.cos(elevation) * torch.cos(azimuth)])
    return ep.Camera(position=position, look_at=torch.zeros(3), fov=40.0, resolution=(size, size))


def lamp_mesh(centre: torch.Tensor) -> ep.Mesh:
    """A square lamp at ``centre`` (a tensor, differentiable), facing down."""
    h = 0.5
    offsets = torch.tensor([[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]])
    return ep.Mesh(offsets + centre, torch.tensor([[0, 1, 2], [0, 2, 3]]), emission=torch.full((3,), 12.0))


def make_scene(vertices, axis_angle, colour, azimuth, elevation, light, size) -> ep.Scene:
    obj = ep.Mesh(vertices @ rotation(axis_angle).T, BASE_I, material=ep.Material(diffuse=colour))
    return ep.Scene(camera_at(azimuth, elevation, size), [obj, lamp_mesh(light)],
                    ep.EnvironmentMap(torch.full((1, 1, 3), 0.3)))


def random_scene_args(generator: torch.Generator):
    """A random rotation, grey-to-coloured albedo, viewpoint and lamp position."""
    r = lambda *shape: torch.rand(*shape, generator=generator)  # noqa: E731
    axis = torch.nn.functional.normalize(torch.randn(3, generator=generator), dim=0)
    axis_angle = axis * r(()) * math.pi
    colour = 0.3 + 0.5 * r(3)
    azimuth, elevation = r(()) * 2 * math.pi, 0.1 + r(()) * 0.6
    light = torch.stack([r(()) * 4 - 2, 2.5 + r(()), r(()) * 4 - 2])
    return axis_angle, colour, azimuth, elevation, light


class Classifier(torch.nn.Module):
    """Each image standardised (zero mean, unit variance), three conv layers, global average
    pooling, a linear layer."""

    def __init__(self, classes: int):
        super().__init__()
        self.features = torch.nn.Sequential(
            torch.nn.Conv2d(3, 16, 3, padding=1), torch.nn.ReLU(), torch.nn.MaxPool2d(2),
            torch.nn.Conv2d(16, 32, 3, padding=1), torch.nn.ReLU(), torch.nn.MaxPool2d(2),
            torch.nn.Conv2d(32, 64, 3, padding=1), torch.nn.ReLU())
        self.head = torch.nn.Linear(64, classes)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Logits of (N, H, W, 3) linear images."""
        x = images.permute(0, 3, 1, 2)
        x = x / (1.0 + x)  # tone-map: bounded inputs
        mean = x.mean(dim=(1, 2, 3), keepdim=True)
        x = (x - mean) / (x - mean).square().mean(dim=(1, 2, 3), keepdim=True).add(1e-6).sqrt()
        return self.head(self.features(x).mean(dim=(2, 3)))


def make_dataset(per_class: int, size: int, spp: int, seed: int):
    generator = torch.Generator().manual_seed(seed)
    images, labels = [], []
    for label, name in enumerate(CLASSES):
        vertices = class_vertices(name)
        for k in range(per_class):
            scene = make_scene(vertices, *random_scene_args(generator), size)
            images.append(ep.render(scene, spp=spp, seed=seed + 1000 * label + k))
            labels.append(label)
    return torch.stack(images), torch.tensor(labels)


def train(model, images, labels, epochs: int, seed: int, quiet: bool):
    torch.manual_seed(seed)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    for epoch in range(epochs):
        order = torch.randperm(len(labels))
        total = 0.0
        for start in range(0, len(order), 32):
            batch = order[start:start + 32]
            # Augmentation: random horizontal flips.
            x = images[batch]
            flip = torch.rand(len(batch)) < 0.5
            x = torch.where(flip[:, None, None, None], x.flip(2), x)
            loss = torch.nn.functional.cross_entropy(model(x), labels[batch])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += loss.item() * len(batch)
        if not quiet and (epoch % 5 == 0 or epoch == epochs - 1):
            print(f"  epoch {epoch:3d}  training loss {total / len(labels):.4f}")
    model.eval()


def main(argv=None):
    p = parser(__doc__.splitlines()[0], iterations=100, size=32, spp=8)
    p.add_argument("--train-per-class", type=int, default=150, help="training renders per class")
    p.add_argument("--epochs", type=int, default=40, help="training epochs")
    p.add_argument("--target-class", default="sphere", choices=CLASSES, help="the class to reach")
    args = p.parse_args(argv)
    out = output_dir(args, "adversarial")
    size = args.size

    # 1. Train the classifier; measure its accuracy on fresh renders.
    images, labels = make_dataset(args.train_per_class, size, args.spp, args.seed)
    test_images, test_labels = make_dataset(max(10, args.train_per_class // 5), size, args.spp,
                                            args.seed + 777)
    model = Classifier(len(CLASSES))
    train(model, images, labels, args.epochs, args.seed, args.quiet)
    for parameter in model.parameters():
        parameter.requires_grad_(False)
    with torch.no_grad():
        accuracy = float((model(test_images).argmax(1) == test_labels).float().mean())
    print(f"classifier: accuracy {accuracy:.2f} on {len(test_labels)} fresh renders")
    save_images(out, {"training_samples": row([images[labels == c][k] for c in range(len(CLASSES))
                                               for k in range(4)])})

    # 2. A box scene the classifier gets right, with the largest box probability.
    source, target = CLASSES.index("box"), CLASSES.index(args.target_class)
    generator = torch.Generator().manual_seed(args.seed + 4242)
    candidates = [random_scene_args(generator) for _ in range(12)]
    with torch.no_grad():
        probs = [torch.softmax(model(ep.render(make_scene(class_vertices("box"), *c, size), spp=32)[None]), 1)[0]
                 for c in candidates]
    best = max(range(len(candidates)), key=lambda k: float(probs[k][source]))
    axis_angle, colour, azimuth0, elevation0, light0 = candidates[best]

    # 3. Optimise the camera angles, the lamp position and the vertex displacements.
    azimuth = azimuth0.clone().requires_grad_()
    elevation = elevation0.clone().requires_grad_()
    light = light0.clone().requires_grad_()
    displacement = torch.zeros_like(BASE_V, requires_grad=True)
    base = class_vertices("box")
    optimizer = torch.optim.Adam([{"params": [azimuth, elevation], "lr": 0.03},
                                  {"params": [light], "lr": 0.1},
                                  {"params": [displacement], "lr": 0.01}])
    history = {name: [] for name in CLASSES}
    losses, flipped_at = [], None
    for step in range(args.iterations):
        optimizer.zero_grad()
        scene = make_scene(base + displacement, axis_angle, colour, azimuth, elevation.clamp(0.05, 1.4),
                           light, size)
        image = ep.render(scene, spp=args.spp, seed=args.seed + step)
        logits = model(image[None])
        # Raise the target class; keep the displacements small (at most ~0.1 on average).
        loss = (torch.nn.functional.cross_entropy(logits, torch.tensor([target]))
                + 10.0 * displacement.square().sum(1).mean())
        loss.backward()
        optimizer.step()
        with torch.no_grad():
            probabilities = torch.softmax(logits, 1)[0]
        for c, name in enumerate(CLASSES):
            history[name].append(float(probabilities[c]))
        losses.append(loss.item())
        if flipped_at is None and int(probabilities.argmax()) == target:
            flipped_at = step
        if not args.quiet and (step % max(1, args.iterations // 10) == 0 or step == args.iterations - 1):
            print(f"  step {step:4d}  " + ", ".join(f"p({n}) {history[n][-1]:.3f}" for n in CLASSES))

    with torch.no_grad():
        before = ep.render(make_scene(base, axis_angle, colour, azimuth0, elevation0, light0, size), spp=64)
        after = ep.render(make_scene(base + displacement, axis_angle, colour, azimuth,
                                     elevation.clamp(0.05, 1.4), light, size), spp=64)
        final = torch.softmax(model(after[None]), 1)[0]
        initial = torch.softmax(model(before[None]), 1)[0]
    save_images(out, {"before": before, "after": after, "before_after": row([before, after])})
    plot(f"{out}/probabilities.png", {f"p({n})": history[n] for n in CLASSES}, "probability",
         f"classifier's output while the scene is optimised towards '{args.target_class}'", log=False)
    print(f"adversarial: p({args.target_class}) {float(initial[target]):.3f} -> {float(final[target]):.3f}, "
          f"p(box) {float(initial[source]):.3f} -> {float(final[source]):.3f}; top class "
          f"{CLASSES[int(initial.argmax())]} -> {CLASSES[int(final.argmax())]}"
          + (f" (first at step {flipped_at})" if flipped_at is not None else "")
          + f"; mean vertex displacement {float(displacement.detach().norm(dim=1).mean()):.3f}; "
          f"pictures in {out}")
    return {"loss": losses, "probabilities": history, "accuracy": accuracy,
            "initial": initial, "final": final, "target": target, "flipped_at": flipped_at}


if __name__ == "__main__":
    run(main)
