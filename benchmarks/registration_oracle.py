"""Which step of ``kinematic``'s tracking loses the correspondence: the large-motion registration
or the sliding after it? An oracle experiment on a scene with an animated-mesh truth.

Run: ``.venv/bin/python benchmarks/registration_oracle.py [SCENE]`` (default ``crane``; any
bench scene with its own scanner, e.g. ``crane-clean``; about two minutes on 2 cores).

It reconstructs the scene with ``kinematic`` three times:

* ``plain``: as the method runs;
* ``oracle seed``: every registration starts from the true positions of the template's
  vertices at that frame (:func:`arap_basin.truth_positions`: the correspondence metric's
  binding at frame 0 with its normal offset, carried by the truth) instead of the method's
  prediction;
* ``oracle registration``: every registration returns those true positions unchanged.

Every other step (prediction, projection, sliding, smoothing) is the method's own. It prints
the correspondence mean / last frame of each run and, for ``oracle seed``, how far each
registration moved the template from the truth it started on (fraction of the diagonal).
If ``oracle registration`` is close to the truth and ``oracle seed`` is not, the sliding keeps a
good state and the registration's own objective leaves it.

This reaches into the method's internals (it replaces ``ArapIcp.seed``,
``ArapIcp.register_frame`` and ``sliding.slide_step`` for the run), so it is a diagnostic
script, not part of the package.
"""

from __future__ import annotations

import argparse

import numpy as np
from arap_basin import truth_positions

from fourd import evaluate, synth
from fourd.evaluate.bench import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.methods import kinematic
from fourd.methods.kinematic import register, sliding


def run(scans, mode: str, true: np.ndarray | None, diagonal: float):
    """``kinematic`` on ``scans`` with the registration replaced per ``mode`` (``plain``,
    ``oracle seed``, ``oracle registration``); ``true`` [T, N, 3] are the template's true
    positions at the input frames. Returns the result and the registrations' moves away from
    the truth."""
    times = np.asarray(scans.times, dtype=float)
    step, seed, register_frame = sliding.slide_step, register.ArapIcp.seed, register.ArapIcp.register_frame
    frame = {"index": 0}
    moves = []

    def tracked_step(pre, field, vertices, time, next_time, **kw):
        frame["index"] = int(np.abs(times - next_time).argmin())
        return step(pre, field, vertices, time, next_time, **kw)

    def oracle_seed(self, predicted, carried, points, before):
        return true[frame["index"]].copy()

    def oracle_register(self, vertices, points, normals, previous=None):
        if mode == "oracle registration":
            return true[frame["index"]].copy(), 0.0
        out = register_frame(self, vertices, points, normals, previous=previous)
        moved = np.linalg.norm(out[0] - true[frame["index"]], axis=1).mean() / diagonal
        moves.append((frame["index"], float(moved)))
        return out

    try:
        if mode != "plain":
            sliding.slide_step = tracked_step
            register.ArapIcp.seed = oracle_seed
            register.ArapIcp.register_frame = oracle_register
        result = kinematic.reconstruct(scans, kinematic.Options())
    finally:
        sliding.slide_step = step
        register.ArapIcp.seed = seed
        register.ArapIcp.register_frame = register_frame
    return result, moves


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="crane")
    args = parser.parse_args()
    scene = {s.key: s for s in STANDARD_SCENES + HELD_OUT_SCENES}[args.scene]
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, **{**PROTOCOL, **scene.scan})
    diagonal = float(np.linalg.norm(np.ptp(np.asarray(truth.vertices).reshape(-1, 3), axis=0)))
    plain, _ = run(scans, "plain", None, diagonal)
    true = truth_positions(
        np.asarray(plain.vertices[0]), np.asarray(truth.vertices), np.asarray(truth.faces)
    )
    for mode in ("plain", "oracle seed", "oracle registration"):
        result, moves = (plain, []) if mode == "plain" else run(scans, mode, true, diagonal)
        report = evaluate(result, truth, samples=20000)
        print(f"{args.scene} {mode}: correspondence mean {report['correspondence_mean']:.4f}, "
              f"last frame {report['correspondence_last']:.4f}", flush=True)
        if moves:
            print("  registrations from the truth, mean distance from it after: "
                  + ", ".join(f"frame {k} {m:.4f}" for k, m in moves))


if __name__ == "__main__":
    main()
