"""Material-aware deformation (fourd.deform): the issue's speed targets and the learned horse.

Run: ``.venv/bin/python benchmarks/bm_deform.py``. Prints

* on crane's first frame (``../shared/data/crane.npz``: 10,002 vertices, 20,000 triangles), with
  six anchor triangles at the extremities: the precomputation (median of 3) and one pose from
  anchor rotations (median of 50; targets 1 s and 20 ms on 2 cores), and one pose from a dragged
  vertex (the binary rotation search);
* on horse-gallop (48 frames), the time to learn the material from its frames, and the learned
  bending stiffness along each leg (geodesic distance from the body: 0 at the body, 1 at the
  hoof; the 10th percentile per tenth of the leg, where the few flexible edges show);
  the picture goes to ``benchmarks/plots/horse-stiffness.png`` (red: flexible);
* the issue's joint target: the median learned bending stiffness of the edges at the leg
  joints against that of the edges along the cannon bones between them (:func:`joints`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from fourd.deform import Deformer, learn_material, rotation_about
from fourd.geometry.meshes import face_adjacency

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _median_seconds(work, repeats):
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return float(np.median(times))


def _extremal_faces(vertices, faces):
    centres = vertices[faces].mean(axis=1)
    return np.unique([int(np.argmin(centres[:, k])) for k in range(3)] + [int(np.argmax(centres[:, k])) for k in range(3)])


def speed() -> None:
    data = np.load(DATA / "crane.npz")
    vertices, faces = data["vertices"][0].astype(float), data["faces"].astype(np.int64)
    anchors = _extremal_faces(vertices, faces)
    build = lambda: Deformer(vertices, faces, anchors=anchors)  # noqa: E731
    build()  # compile the kernels once
    precompute = _median_seconds(build, 3)
    deformer = build()
    rng = np.random.default_rng(0)
    transforms = np.stack([rotation_about(rng.normal(size=3), rng.uniform(0, 1)) for _ in anchors])
    transforms[0] = np.eye(3)
    deformer.pose(transforms)
    pose = _median_seconds(lambda: deformer.pose(transforms), 50)
    print(f"crane frame 0: {len(vertices)} vertices, {len(faces)} triangles, {len(anchors)} anchors")
    print(f"  precomputation {precompute:.3f} s (target 1 s), pose {1000 * pose:.1f} ms (target 20 ms)")
    tip = int(faces[anchors[-1], 0])
    dragger = Deformer(vertices, faces, anchors=anchors[:1], fixed=faces[anchors[0]], handles=[tip])
    target = vertices[tip] + 0.1 * np.ptp(vertices, axis=0).max() * np.array([1.0, 0.0, 0.0])
    drag = _median_seconds(lambda: dragger.pose(positions=[target]), 5)
    print(f"  pose from one dragged vertex (binary search): {1000 * drag:.0f} ms")


def horse() -> None:
    data = np.load(DATA / "horse-gallop.npz")
    frames, faces = data["vertices"].astype(float), data["faces"].astype(np.int64)
    rest = frames[0]
    started = time.perf_counter()
    material = learn_material(rest, frames[1:], faces)
    print(f"horse-gallop: learned from {len(frames) - 1} poses in {time.perf_counter() - started:.2f} s")
    _, edges = face_adjacency(faces)
    pairs = np.unique(np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    lengths = np.linalg.norm(rest[pairs[:, 0]] - rest[pairs[:, 1]], axis=1)
    below = rest[:, 1] < 0.55  # the legs, below the belly (Y up; the horse is 1.36 tall)
    keep = below[pairs[:, 0]] & below[pairs[:, 1]]
    graph = sp.coo_matrix((lengths[keep], (pairs[keep, 0], pairs[keep, 1])), shape=(len(rest),) * 2).tocsr()
    _, labels = connected_components(graph, directed=False)
    sizes = np.bincount(labels[below])
    for leg in np.argsort(sizes)[::-1][:4]:
        members = np.flatnonzero((labels == leg) & below)
        top = members[rest[members, 1] > rest[members, 1].max() - 0.03]
        distance = dijkstra(graph, indices=top, min_only=True)
        along = np.full(len(rest), np.nan)
        reached = members[np.isfinite(distance[members])]
        along[reached] = distance[reached] / distance[reached].max()
        edge_along = along[edges].mean(axis=1)
        profile = [np.quantile(material.bending[(edge_along >= a) & (edge_along < a + 0.1)], 0.1)
                   for a in np.arange(0.0, 1.0, 0.1)]
        x, z = rest[members, 0].mean(), rest[members, 2].mean()
        print(f"  leg at x={x:+.2f} z={z:+.2f}: " + " ".join(f"{p:.2f}" for p in profile))
    _picture(rest, faces, material)


#: The leg joints of horse-gallop's first frame, labelled by eye on a plain grey render (no
#: stiffness shown) of that frame: ``fit_camera`` of its bounds, azimuth 90, elevation 10, 1400 x
#: 1000 pixels; per leg (upper joint: knee or hock; lower: fetlock) the pixel of the joint's
#: outline. Each becomes the mean of the 16 vertices that project nearest to it, less those
#: farther than 0.12 behind the nearest of them (another leg).
JOINT_PIXELS = {
    "front leg, reaching forward": [(355, 625), (300, 680)],
    "front leg, upright": [(565, 610), (585, 700)],
    "hind leg, upright": [(858, 605), (862, 728)],
    "hind leg, lifted": [(905, 550), (950, 672)],
}
#: Edges within this distance of a labelled joint are joint edges (the horse is 1.36 tall).
JOINT_RADIUS = 0.05


def joints(jitter: float = 0.0, seed: int = 0) -> tuple[float, float]:
    """Median learned bending stiffness of the joint edges and of the bone edges (the middle
    40% of the segment from each leg's upper to its lower joint, within 0.08 of it), printed
    with lower quantiles and the chance that a joint edge bends more easily than a bone edge.
    ``jitter``: pixels of random error added to every label (the figures' sensitivity)."""
    from fourd.viz.camera import fit_camera

    data = np.load(DATA / "horse-gallop.npz")
    frames, faces = data["vertices"].astype(float), data["faces"].astype(np.int64)
    rest = frames[0]
    camera = fit_camera(np.array([rest.min(axis=0), rest.max(axis=0)]), azimuth=90, elevation=10)
    pixels, depth = camera.project(rest, 1400, 1000)
    rng = np.random.default_rng(seed)
    legs = {}
    for leg, labels in JOINT_PIXELS.items():
        centres = []
        for label in labels:
            label = np.asarray(label, dtype=float) + rng.uniform(-jitter, jitter, 2)
            near = np.argsort(np.linalg.norm(pixels - label, axis=1))[:16]
            front = near[depth[near] < depth[near].min() + 0.12]
            centres.append(rest[front].mean(axis=0))
        legs[leg] = np.array(centres)
    material = learn_material(rest, frames[1:], faces)
    _, edges = face_adjacency(faces)
    middle = rest[edges].mean(axis=1)
    labelled = np.concatenate(list(legs.values()))
    joint = np.linalg.norm(middle[:, None] - labelled[None], axis=2).min(axis=1) < JOINT_RADIUS
    bone = np.zeros(len(middle), dtype=bool)
    for upper, lower in legs.values():
        length = np.linalg.norm(lower - upper)
        along = (middle - upper) @ (lower - upper) / length**2
        across = np.linalg.norm(middle - upper - np.outer(along, lower - upper), axis=1)
        bone |= (along > 0.3) & (along < 0.7) & (across < 0.08)
    at_joints, on_bones = material.bending[joint], material.bending[bone]
    softer = float((at_joints[:, None] < on_bones[None, :]).mean())
    print(f"horse-gallop joints (labels jittered by up to {jitter:.0f} px): {joint.sum()} joint edges, "
          f"{bone.sum()} bone edges")
    for name, values in (("joints", at_joints), ("bones", on_bones)):
        print(f"  {name:6s} median {np.median(values):.3f}, 10th percentile {np.quantile(values, 0.1):.3f}, "
              f"below 1.0: {np.mean(values < 1.0):.0%}")
    print(f"  a joint edge less stiff than a bone edge: {softer:.0%} of pairs")
    return float(np.median(at_joints)), float(np.median(on_bones))


def _picture(rest, faces, material) -> None:
    from PIL import Image

    from fourd.viz.camera import fit_camera
    from fourd.viz.raster import render
    from fourd.viz.viewer import vertex_flexibility

    flexible = vertex_flexibility(faces, material, len(rest))
    flexible = np.sqrt(np.clip(flexible / max(np.quantile(flexible, 0.98), 1e-12), 0, 1))
    colors = np.stack([np.full_like(flexible, 0.9), 0.9 * (1 - flexible), 0.9 * (1 - flexible)], axis=1)
    camera = fit_camera(np.array([rest.min(axis=0), rest.max(axis=0)]), azimuth=90, elevation=10)
    image = render(camera=camera, width=700, height=500, vertices=rest, faces=faces,
                   vertex_colors=colors, texture="none")
    path = Path(__file__).resolve().parent / "plots" / "horse-stiffness.png"
    Image.fromarray(image).save(path)
    print(f"  picture: {path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path}")


def example() -> None:
    """The README's picture: horse-gallop's first frame, one leg swung back by rotating its hoof
    triangle 0.9 rad about x while the body, head, tail and another hoof hold, with a uniform
    material (middle) and the material learned from the gallop (right)."""
    from PIL import Image

    from fourd.deform import uniform_material
    from fourd.viz.camera import fit_camera
    from fourd.viz.raster import render

    data = np.load(DATA / "horse-gallop.npz")
    frames, faces = data["vertices"].astype(float), data["faces"].astype(np.int64)
    rest = frames[0]
    centres = rest[faces].mean(axis=1)
    nearest = lambda point: int(np.argmin(np.linalg.norm(centres - point, axis=1)))  # noqa: E731
    # body, the swung hoof, head, tail tip, another hoof (positions in the first frame)
    anchors = [nearest(p) for p in ([0, 1.0, -0.26], [-0.11, 0.02, 0.1], [0, 1.3, 0.6],
                                     [0, 0.75, -1.3], [0.1, 0.02, -0.66])]
    transforms = np.stack([np.eye(3), rotation_about([1, 0, 0], 0.9)] + [np.eye(3)] * 3)
    camera = fit_camera(np.array([rest.min(axis=0) - 0.2, rest.max(axis=0) + 0.2]), azimuth=90, elevation=10)
    tiles = [render(camera=camera, width=420, height=360, vertices=rest, faces=faces, texture="none")]
    for material in (uniform_material(faces), learn_material(rest, frames[1:], faces)):
        posed = Deformer(rest, faces, material, anchors=anchors).pose(transforms)
        tiles.append(render(camera=camera, width=420, height=360, vertices=posed, faces=faces, texture="none"))
    path = Path(__file__).resolve().parent / "plots" / "deform-example.png"
    Image.fromarray(np.concatenate(tiles, axis=1)).save(path)
    print(f"example: {path}")


if __name__ == "__main__":
    speed()
    horse()
    joints()
    for seed in range(3):
        joints(jitter=15.0, seed=seed)
    example()
