"""How accurate are the optical-flow anchors (``fourd.appearance.anchors``) on the synthetic
scenes, and how many survive?

Each scene (20 frames, the standard scan with 2% outliers, 128 x 128 images, the first
``PAIRS`` frame pairs) is scanned with an appearance and filmed; every anchor's source is bound
to its material point (the closest point of the true surface in its frame: triangle and
barycentric coordinates) and that point is followed to the next frame; the anchor's error is
the distance of its target from there. Also: how far targets lie off the true surface, and the
motion itself, all as fractions of the truth's bounding-box diagonal.

Run from the repository root::

    .venv/bin/python experiments/anchor_accuracy.py            # the README table
    .venv/bin/python experiments/anchor_accuracy.py --markdown # as Markdown rows
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh

import fourd
from fourd.animation import AnimatedMesh
from fourd.appearance.anchor_tracks import anchors
from fourd.synth.paint import barycentric

PAIRS = 3
CASES = [
    ("rigid-turn", "cloth"),
    ("rigid-turn", "skin"),
    ("bending-arm", "cloth"),
    ("bending-arm", "skin"),
    ("squash-ball", "cloth"),
    ("waving-sheet", "cloth"),
]


def _follow(truth: AnimatedMesh, t: int, points: np.ndarray):
    """Where the material points nearest ``points`` (in frame ``t``) are in frame ``t + 1``."""
    mesh = trimesh.Trimesh(truth.vertices[t], truth.faces, process=False)
    closest, _, triangle = trimesh.proximity.closest_point(mesh, points)
    corners = truth.faces[triangle]
    weights = barycentric(closest, truth.vertices[t][corners])
    return np.einsum("pk,pkj->pj", weights, truth.vertices[t + 1][corners])


def measure(name: str, appearance: str, resolution: int = 128) -> dict:
    full = fourd.synth.scene(name, frames=20)
    truth = AnimatedMesh(full.faces, full.vertices[: PAIRS + 1], rest=full.rest)
    diagonal = full.diagonal()
    scans = fourd.synth.scan(truth, appearance=appearance, video=True, resolution=resolution)
    started = time.perf_counter()
    result = anchors(scans)
    seconds = (time.perf_counter() - started) / len(result)
    errors, off, motion, kept, total = [], [], [], 0, 0
    for pair in result:
        followed = _follow(truth, pair.first, pair.source)
        errors.append(np.linalg.norm(pair.target - followed, axis=1))
        motion.append(np.linalg.norm(followed - pair.source, axis=1))
        after = trimesh.Trimesh(truth.vertices[pair.second], truth.faces, process=False)
        off.append(np.abs(trimesh.proximity.closest_point(after, pair.target)[1]))
        kept += len(pair.source)
        total += len(scans[pair.first])
    error = np.concatenate(errors) / diagonal
    return {
        "scene": name,
        "appearance": appearance,
        "anchors": kept / len(result),
        "share": kept / total,
        "motion": float(np.median(np.concatenate(motion)) / diagonal),
        "median": float(np.median(error)),
        "p90": float(np.percentile(error, 90)),
        "p99": float(np.percentile(error, 99)),
        "off": float(np.median(np.concatenate(off)) / diagonal),
        "seconds": seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--markdown", action="store_true")
    args = parser.parse_args()
    header = "| scene | appearance | anchors / pair (% of points) | motion | error median | p90 | p99 | off surface (median) | s / pair |"
    if args.markdown:
        print(header)
        print("|---|---|---|---|---|---|---|---|---|")
    for name, appearance in CASES:
        r = measure(name, appearance)
        cells = [
            f"`{r['scene']}`", r["appearance"], f"{r['anchors']:.0f} ({100 * r['share']:.0f}%)",
            f"{r['motion']:.4f}", f"{r['median']:.4f}", f"{r['p90']:.4f}", f"{r['p99']:.4f}",
            f"{r['off']:.4f}", f"{r['seconds']:.2f}",
        ]  # fmt: skip
        print("| " + " | ".join(cells) + " |" if args.markdown else "  ".join(cells), flush=True)


if __name__ == "__main__":
    main()
