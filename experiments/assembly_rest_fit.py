"""Question: the assembly's chain of pair maps drifts over a whole capture (each frame's
correspondence is the composition of every pair map before it, and the hard pairs' errors add
up), and its mesh wears (edges shrink and stretch). `kinematic` does not drift over the same
capture: its deformation is measured against the rest shape, so a slide that distorts the
surface costs energy in every later frame. Does a pass after the assembly that slides each
frame's vertices on that frame's own surface towards the shape most as-rigid-as-possible to the
first frame (ARAP-ICP against the rest, started from the previous frame's result moved by the
chain's step) break the chain's drift?

Setup: a bench scene as ``fourd bench`` scans it, ``assembly`` with ``rest_fit=0`` (cached in
the temporary folder, so a rerun only fits and scores), each frame's own mesh as the method
makes it, then :func:`fourd.methods.assembly.rest_fit.fit_rest` at ``ITERATIONS`` rounds and
``WEIGHT`` (the option's defaults unless set). Scored by ``fourd.metrics.evaluate`` (20,000
samples, so the Chamfer is not the bench's), with the last frame's edge lengths against the
first frame's.

Run: ``.venv/bin/python experiments/assembly_rest_fit.py [SCENE]`` (a bench scene's name,
``crane-full-sparse`` by default; environment: ``ITERATIONS``, ``WEIGHT``, or ``SETTINGS`` as
``ROUNDS:WEIGHT[:SETTLED],...``; ``PERCENTILE``, the share of the vertices that ``SETTLED``
is asked of, 90 by default, 50 the median as before 2026-12-04).

Answer: (below, when measured)
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    import fourd.bench.suite as suite
    from fourd.animation import AnimatedMesh
    from fourd.methods import reconstruct
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.method import frame_meshes
    from fourd.methods.assembly.rest_fit import SETTLED, fit_rest
    from fourd.metrics import evaluate

    name = sys.argv[1] if len(sys.argv) > 1 else "crane-full-sparse"
    bench = suite.select_scenes([name], quick=False)[0]
    truth, scans = suite.scan_scene(bench)
    import fourd.methods.assembly.rest_fit as rest_fit

    if "PERCENTILE" in os.environ:  # the share of the vertices a settled round asks of
        rest_fit.SETTLED_PERCENTILE = float(os.environ["PERCENTILE"])
    iterations = int(os.environ.get("ITERATIONS", "16"))
    weight = float(os.environ.get("WEIGHT", "0.03"))
    kept = Path(tempfile.gettempdir()) / f"assembly_rest_fit_{name}.npz"
    if kept.exists():
        stored = np.load(kept)
        vertices, faces, observed = stored["vertices"], stored["faces"], stored["observed"]
    else:
        result = reconstruct(scans, "assembly", rest_fit=0)
        vertices, faces, observed = result.vertices, result.faces, result.observed
        np.savez(kept, vertices=vertices, faces=faces, observed=observed)
    meshes = frame_meshes(scans, Options())
    runs = [("chain", vertices, 0.0)]
    for setting in os.environ.get("SETTINGS", f"{iterations}:{weight}").split(","):
        rounds, pull, *rest = setting.split(":")
        settled = float(rest[0]) if rest else SETTLED
        began = time.perf_counter()
        fitted = fit_rest(
            vertices,
            faces,
            observed,
            meshes,
            iterations=int(rounds),
            weight=float(pull),
            settled=settled,
        )
        seconds = (time.perf_counter() - began) / max(len(vertices) - 1, 1)
        runs.append((f"rest fit ({rounds} x, weight {pull}, settled {settled})", fitted, seconds))
    for label, positions, seconds in runs:
        mesh = AnimatedMesh(faces, positions, scans.times, observed, rest=positions[0])
        m = evaluate(mesh, truth, samples=20000, seed=0)
        curve = m["per_frame"]["correspondence"]
        marks = " ".join(f"{curve[t]:.4f}" for t in range(0, len(curve), max(len(curve) // 7, 1)))
        first = np.linalg.norm(positions[0][faces[:, 0]] - positions[0][faces[:, 1]], axis=1)
        last = np.linalg.norm(positions[-1][faces[:, 0]] - positions[-1][faces[:, 1]], axis=1)
        edges = last / np.maximum(first, 1e-12)
        print(
            f"{name}, {label}: corr {m['correspondence_mean']:.4f} / {m['correspondence_last']:.4f}, "
            f"Chamfer {m['chamfer']:.4f}, compl-95 {m['completeness_95']:.4f}, last frame's edges median "
            f"{np.median(edges):.3f} (10th / 99th {np.percentile(edges, 10):.3f} / "
            f"{np.percentile(edges, 99):.2f}), {seconds:.3f} s/frame; curve {marks}"
        )
    print(f"{len(vertices[0])} vertices")


if __name__ == "__main__":
    main()
