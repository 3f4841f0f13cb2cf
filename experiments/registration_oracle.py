"""Which step of ``kinematic``'s tracking loses the correspondence: the large-motion registration
or the sliding after it? An oracle experiment on a scene with an animated-mesh truth.

Run: ``.venv/bin/python experiments/registration_oracle.py [SCENE]`` (default ``crane``; any
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

``--stop-explained F`` ends each registration's stiff iterations once at most ``F`` of the
frame's points are unexplained (``RegisterOptions.stop_explained``), in all three runs;
``--slide-iterations N`` sets the sliding's ARAP iterations per step; ``--per-frame`` prints
each frame's error. Measured (correspondence mean / last frame; plain, oracle seed, oracle
registration): crane 0.0073 / 0.0120, 0.0058 / 0.0080, 0.0042 / 0.0060; with
``--stop-explained 0.005`` 0.0091 / 0.0141, 0.0043 / 0.0058, 0.0042 / 0.0060 (from the truth,
the stiff iterations are what leave it; from the method's own seeds they are what correct
the seed); with ``--slide-iterations 1`` 0.0078 / 0.0118, 0.0060 / 0.0082, 0.0027 / 0.0032;
crane-50 0.0235 / 0.0308, 0.0142 / 0.0164, 0.0078 / 0.0094, and with ``--slide-iterations 1``
0.0231 / 0.0314, 0.0150 / 0.0179, 0.0049 / 0.0055 (the sliding's own iterations, too, pull
a right state towards the rest shape's ARAP minimum).

``--energies`` then reruns the plain tracking with every registration also started from the
truth, and prints per registered frame the ARAP energy against the template and the mean
distance from the truth of the method's registration, of the one from the truth, and of the
truth itself. crane: both registrations end at the same energy (0.0013-0.0091, within 0.0005
of each other), the truth's own being 0.0089-0.0524: the prior's minimum is not the truth,
and its energy cannot choose between seeds.

This reaches into the method's internals (it replaces ``ArapIcp.seed``,
``ArapIcp.register_frame`` and ``sliding.slide_step`` for the run), so it is a diagnostic
script, not part of the package.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from arap_basin import truth_positions

from fourd import evaluate, synth
from fourd.bench import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.methods import kinematic
from fourd.methods.kinematic import arap, register, sliding


def run(scans, mode: str, true: np.ndarray | None, diagonal: float,
        options: kinematic.Options | None = None, stop_explained: float = 0.0):
    """``kinematic`` with ``options`` (None: its defaults) on ``scans``, with the registration
    replaced per ``mode`` (``plain``, ``oracle seed``, ``oracle registration``, or
    ``energies``: as ``plain``, each registration also run from the truth) and its
    ``RegisterOptions.stop_explained`` set to ``stop_explained``; ``true`` [T, N, 3] are the
    template's true positions at the input frames. Returns the result and the registrations'
    moves away from the truth (with ``energies``: per registration the frame and, for the
    method's registration, the one from the truth and the truth itself, the ARAP energy
    against the template and the mean distance from the truth)."""
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
        if mode == "energies":
            own = register_frame(self, vertices, points, normals, previous=previous)
            now = true[frame["index"]]
            from_truth = register_frame(self, now.copy(), points, normals, previous=previous)
            moves.append((frame["index"], *(
                (arap.arap_energy(self.pre, x), np.linalg.norm(x - now, axis=1).mean() / diagonal)
                for x in (own[0], from_truth[0], now)
            )))
            return own
        if mode == "oracle registration":
            return true[frame["index"]].copy(), 0.0
        out = register_frame(self, vertices, points, normals, previous=previous)
        moved = np.linalg.norm(out[0] - true[frame["index"]], axis=1).mean() / diagonal
        moves.append((frame["index"], float(moved)))
        return out

    init = register.ArapIcp.__init__

    def stopping_init(self, pre, faces, register_options=None, *args, **kw):
        register_options = register_options or register.RegisterOptions()
        init(self, pre, faces, replace(register_options, stop_explained=stop_explained), *args, **kw)

    try:
        register.ArapIcp.__init__ = stopping_init
        if mode != "plain":
            sliding.slide_step = tracked_step
            register.ArapIcp.register_frame = oracle_register
        if mode not in ("plain", "energies"):
            register.ArapIcp.seed = oracle_seed
        result = kinematic.reconstruct(scans, options or kinematic.Options())
    finally:
        register.ArapIcp.__init__ = init
        sliding.slide_step = step
        register.ArapIcp.seed = seed
        register.ArapIcp.register_frame = register_frame
    return result, moves


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="crane")
    parser.add_argument(
        "--stop-explained", type=float, default=0.0, metavar="F",
        help="end each registration's stiff iterations once at most this fraction of the "
        "frame's points is unexplained (RegisterOptions.stop_explained; 0: all of them)",
    )
    parser.add_argument(
        "--slide-iterations", type=int, default=None, metavar="N",
        help="the sliding's ARAP iterations per step (kinematic's iterations; default its own)",
    )
    parser.add_argument("--per-frame", action="store_true", help="print each frame's error too")
    parser.add_argument(
        "--energies", action="store_true",
        help="then, per registration of the plain run, the ARAP energy and distance from the "
        "truth of its result, of the registration started from the truth, and of the truth",
    )
    args = parser.parse_args()
    options = kinematic.Options()
    if args.slide_iterations is not None:
        options = replace(options, iterations=args.slide_iterations)
    settings = dict(options=options, stop_explained=args.stop_explained)
    scene = {s.key: s for s in STANDARD_SCENES + HELD_OUT_SCENES}[args.scene]
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, **{**PROTOCOL, **scene.scan})
    diagonal = float(np.linalg.norm(np.ptp(np.asarray(truth.vertices).reshape(-1, 3), axis=0)))
    plain, _ = run(scans, "plain", None, diagonal, **settings)
    true = truth_positions(
        np.asarray(plain.vertices[0]), np.asarray(truth.vertices), np.asarray(truth.faces)
    )
    for mode in ("plain", "oracle seed", "oracle registration"):
        result, moves = (
            (plain, []) if mode == "plain" else run(scans, mode, true, diagonal, **settings)
        )
        report = evaluate(result, truth, samples=20000)
        print(f"{args.scene} {mode}: correspondence mean {report['correspondence_mean']:.4f}, "
              f"last frame {report['correspondence_last']:.4f}", flush=True)
        if args.per_frame:
            print("  per frame: " + " ".join(
                f"{e:.4f}" for e in report["per_frame"]["correspondence"]))
        if moves:
            print("  registrations from the truth, mean distance from it after: "
                  + ", ".join(f"frame {k} {m:.4f}" for k, m in moves))
    if args.energies:
        _, rows = run(scans, "energies", true, diagonal, **settings)
        print(f"{args.scene} registrations, ARAP energy against the template / mean distance "
              "from the truth: the method's, started from the truth, the truth")
        for k, *cells in rows:
            print(f"  frame {k}: " + ", ".join(f"{e:.4f} / {d:.4f}" for e, d in cells))


if __name__ == "__main__":
    main()
