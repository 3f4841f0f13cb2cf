"""Question: a limb that moves several `eps_sampl` between two scans is beyond the nearest-point
correspondences of `surfels`' alignment (`experiments/surfels_alignment.py`, crane-50 pairs
7-9). Does a rigid search per part, after the whole-body rigid start and before the non-rigid
ICP, reach it?

    PYTHONPATH=src:experiments python experiments/surfels_part_search.py crane-50 [PART ...]

PART is `part_size` in eps_sampl (0: no part search, the paper's alignment). For each pair of
adjacent frames (``PAIRS=7,8,9`` picks some), frame t's seed model (cached as by
`surfels_alignment.py`) is aligned to frame t + 1's points by `align_ranges` with the schedule's
part search (`fourd.methods.surfels.part_search`; ``SET=part_reach=4,...`` sets options). Error
as in `surfels_alignment.py`: mean / 90th percentile distance of each surfel to where the truth
went, fractions of the diagonal; and the seconds of the alignment.

Answer (2026-12-06, twelfth session, at 21e2f27; mean / 90th percentile over the pairs):

    scene                 0 (no search)       4 (default)         6
    crane                 0.0037 / 0.0067     0.0035 / 0.0060     0.0035 / 0.0059
    crane-50              0.0076 / 0.0191     0.0062 / 0.0120     0.0066 / 0.0135
    crane-130             0.0067 / 0.0140     0.0060 / 0.0102     0.0062 / 0.0104
    horse-gallop          0.0071 / 0.0165     0.0062 / 0.0118     0.0073 / 0.0149
    touching-spheres      0.0032 / 0.0067     0.0033 / 0.0071     0.0035 / 0.0074

Crane-50's fastest pairs 7 / 8 / 9 (90th percentile) 0.0595 / 0.0748 / 0.0511 -> 0.0172 / 0.0393 /
0.0284. dfaust-hopping (0.0019 / 0.0032) and rigid-turn-outliers (0.0010 / 0.0013) are unchanged
(first version: nothing moved). The first version scored the parts against every data point, and
a part of one touching sphere took the other's surface (the pipeline test's spheres came out
glued); scoring against the data no surfel explains at the start fixed it and helped crane-50
and horse-gallop (0.0141 -> 0.0120, at size 4). Seeds one per cube of `part_size` instead of at
least `part_size` apart put seeds side by side across the cubes' faces (a small limb fell into
several parts); they needed size 6 for what the spread seeds give at 4. On touching-spheres pairs
4, 15, 18 gain (0.0131 -> 0.0057 at 18) and 1, 16 lose (0.0095 -> 0.0179): a cap of a smooth
ball matches the ball turned anywhere.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np
from surfels_alignment import env_settings, seeded, where_truth_went

from fourd.methods.surfels import pipeline as sp
from fourd.methods.surfels.align import align_ranges
from fourd.methods.surfels.options import Options


def main(label, sizes):
    settings = env_settings()
    options = Options(cache_dir=f"/tmp/surfels-align/{label}", part_size=0.0)
    truth, frames, sampling, noise, seeds = seeded(label, options)
    diagonal = truth.diagonal()
    pairs = [int(x) for x in os.environ.get("PAIRS", "").split(",") if x] or range(len(frames) - 1)
    for size in sizes:
        schedule = sp.assembly_schedule(Options(part_size=size, **settings), noise, sampling)
        errors, seconds = [], 0.0
        for t in pairs:
            start = seeds[t].state.positions[-1]
            target, near = where_truth_went(truth, t, start, sampling)
            began = time.perf_counter()
            aligned = align_ranges(seeds[t], frames[t + 1].points, frames[t + 1].normals,
                                   schedule.weights, schedule.align, data_weight=schedule.align_data,
                                   percentile=schedule.align_percentile, parts=schedule.parts)
            seconds += time.perf_counter() - began
            motion = np.linalg.norm(target - start, axis=1)[near] / diagonal
            error = np.linalg.norm(aligned.positions - target, axis=1)[near] / diagonal
            errors.append((error.mean(), np.percentile(error, 90)))
            print(f"{label} part {size:g}: pair {t}: motion {motion.mean():.4f} / "
                  f"{np.percentile(motion, 90):.4f}, aligned {error.mean():.4f} / "
                  f"{np.percentile(error, 90):.4f}", flush=True)
        mean = np.mean(errors, axis=0)
        print(f"{label} part {size:g}: over the pairs {mean[0]:.4f} / {mean[1]:.4f}, "
              f"{seconds / len(errors):.2f} s a pair", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "crane-50", [float(s) for s in sys.argv[2:]] or [0.0, 6.0])
