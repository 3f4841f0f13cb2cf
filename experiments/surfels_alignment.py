"""Question: `surfels`' surfel trajectories on crane lose 0.004 -> 0.013 of the diagonal over
frames 6-9 (mean error of each surfel against the truth point it started on). Is it the
alignment of two adjacent frames (sec. 3.2, the non-rigid ICP that starts every merge), and
which of its settings leaves the fast limbs behind?

    PYTHONPATH=src python experiments/surfels_alignment.py crane [PERCENTILE ...]

For each pair of adjacent frames ``t, t + 1`` of a bench scene (``rt64``: rigid-turn, 3 frames
of 6 degrees scanned at 64 rays), frame ``t``'s seed model (as the pipeline makes it) is
aligned to frame ``t + 1``'s preprocessed points by `align_ranges` at each cutoff percentile;
each surfel's error is its distance to where the truth point nearest it at ``t`` went at
``t + 1`` (surfels within ``eps_sampl`` of the truth only). ``SET=rigid=0.5,...`` sets options
of `surfels`. Seeds are kept under /tmp/surfels-align/.

Answer (2026-12-05, tenth session, at 67aa052; mean over the pairs of the mean / 90th
percentile error, fractions of the diagonal; the paper's 85 against every point that passes
the 45 degree and doublet tests, 100):

    scene                 85                  95                 100
    crane                 0.0061 / 0.0154     0.0047 / 0.0108    0.0037 / 0.0067
    crane-130             0.0106 / 0.0286                        0.0067 / 0.0140
    dfaust-hopping        0.0020 / 0.0033                        0.0019 / 0.0032
    rigid-turn-outliers   0.0010 / 0.0013                        0.0010 / 0.0013
    rt64                  0.0114 / 0.0141                        0.0127 / 0.0156

On crane's fastest pairs (frames 8-10 and 14: the surfels move 0.021-0.027 of the diagonal on
average, 0.055-0.075 at the 90th percentile, 3-4 eps_sampl) the 85th-percentile cutoff left
40-60% of the motion undone (pair 9: 0.0155 / 0.0540), 100 a quarter (0.0067 / 0.0113): the
farthest 15% of the distances are exactly the limbs that moved most, so they are cut and stay
where they were. More steps (24, 48 against 12) changed nothing; a weaker rigidity (0.5, 0.25)
or a stronger data weight (3, 4) gave less than the cutoff did (0.0034-0.0050 at 100). The
outliers are gone after the tensor voting (rigid-turn with 10% outliers: no difference), and the
surface one frame sees and the other does not fails the doublet test. Only the coarse turning
blob (rt64) aligns a little worse without the cutoff: there the farthest points are the
surface the turn brings into view at the border, and a smooth blob's turn is barely fixed by
its shape (both leave 40-50% of the 6 degrees undone). Aligning at 100 and then settling at 85
was worse on both (crane 0.0039, rt64's whole run 0.16 of the motion against 0.15).

Whole runs (`experiments/surfels_completeness.py`, fitted, 20k samples; Chamfer / accuracy /
completeness-95 / correspondence mean / last): crane 0.0047 / 0.0033 / 0.0218 / 0.0108 / 0.0180
-> 0.0046 / 0.0030 / 0.0228 / 0.0092 / 0.0128; crane-130 0.0061 / 0.0053 / 0.0253 / 0.0239 /
0.0266 -> 0.0047 / 0.0035 / 0.0212 / 0.0131 / 0.0162. So `align_percentile` is 100.

Crane-50 (held out, the fastest stretch; 2026-12-05, eleventh session, at 100): over the pairs
0.0076 / 0.0191. Pairs 7-9 move 0.030-0.036 of the diagonal on average and 0.081-0.097 at the
90th percentile (5-6 eps_sampl), and the alignment leaves 60-80% of the fast part undone
(0.0139-0.0185 / 0.051-0.075). These are the frames where three pieces of `surfels`' crane-50
mesh lose their data for good (`experiments/surfels_pieces.py`). Nothing of the alignment's
settings reaches them (pairs 7 / 8 / 9, 90th percentile; the seeds kept, the settings
acting on the alignment only): 48 steps instead of 12 0.0595 / 0.0748 / 0.0511 (the same: the
correspondences settle), `rigid` 0.25 0.0492 / 0.0738 / 0.0519 (over the pairs 0.0062 /
0.0163), `align_data` 4 0.0547 / 0.0750 / 0.0536, the doublet tolerance at 2 or 4 eps_top
0.0567 / 0.0729 / 0.0529. A limb that moves several times its own sampling between two scans
is beyond the nearest-point correspondences of any ICP; what would reach it is a
correspondence that does not come from proximity (appearance, or a rigid search per part).
"""

from __future__ import annotations

import ast
import os
import pickle
import sys

import numpy as np
from scipy.spatial import cKDTree

from fourd import synth
from fourd.bench.suite import HELD_OUT_SCENES, PROTOCOL, ROBUSTNESS_SCENES, STANDARD_SCENES
from fourd.cache import StageCache
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.neighbors import point_spacing
from fourd.methods.surfels import pipeline as sp
from fourd.methods.surfels.align import align_ranges
from fourd.methods.surfels.options import Options


def scans_of(label: str):
    if label == "rt64":
        truth = synth.scene("rigid-turn", frames=3, angle=12.0)
        return truth, synth.scan(truth, resolution=64)
    scene = next(s for s in STANDARD_SCENES + HELD_OUT_SCENES + ROBUSTNESS_SCENES if s.key == label)
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    return truth, synth.scan(truth, resolution=scene.resolution, seed=0, **{**PROTOCOL, **scene.scan})


def where_truth_went(truth, t: int, positions: np.ndarray, sampling: float):
    """The truth point nearest each surfel at frame ``t``, at ``t + 1``; and which surfels lie
    within ``sampling`` of the truth."""
    (here, faces), (there, _) = truth.frame(t), truth.frame(t + 1)
    if len(faces):
        found = closest_points_on_mesh(here, faces, positions)
        target = np.einsum("sk,skd->sd", found.barycentric, there[faces[found.triangle]])
        return target, found.distances < sampling
    distance, nearest = cKDTree(here).query(positions)  # a registered point cloud (dfaust)
    return there[nearest], distance < sampling


def env_settings() -> dict:
    """The options of `surfels` that ``SET=name=value,...`` sets."""
    return dict(
        (key, ast.literal_eval(value))
        for key, value in (item.split("=") for item in os.environ.get("SET", "").split(",") if item)
    )


def seeded(label: str, options: Options):
    """``(truth, frames, sampling, noise, seeds)`` of a bench scene: its preprocessed frames and
    one seed model per frame as the pipeline makes them (the seeds kept under
    /tmp/surfels-align/)."""
    os.makedirs("/tmp/surfels-align", exist_ok=True)
    truth, scans = scans_of(label)
    spacing = point_spacing(scans.frames[0].points)
    sampling, noise = options.sampling * spacing, options.noise or spacing
    frames, _ = sp.prepare_frames(scans.frames, spacing, options, StageCache(options.cache_dir))
    path = f"/tmp/surfels-align/{label}-seeds.pickle"
    if os.path.exists(path):
        with open(path, "rb") as f:
            return truth, frames, sampling, noise, pickle.load(f)
    schedule = sp.assembly_schedule(options, noise, sampling)
    seeds = sp.seed_models(frames, range(len(frames)), sampling, schedule, options)
    with open(path, "wb") as f:
        pickle.dump(seeds, f)
    return truth, frames, sampling, noise, seeds


def main(label: str, percentiles: list[float]) -> None:
    options = Options(cache_dir=f"/tmp/surfels-align/{label}", **env_settings())
    truth, frames, sampling, noise, seeds = seeded(label, options)
    diagonal = truth.diagonal()
    schedule = sp.assembly_schedule(options, noise, sampling)
    for percentile in percentiles:
        errors = []
        for t in range(len(frames) - 1):
            start = seeds[t].state.positions[-1]
            target, near = where_truth_went(truth, t, start, sampling)
            aligned = align_ranges(seeds[t], frames[t + 1].points, frames[t + 1].normals,
                                   schedule.weights, schedule.align, data_weight=schedule.align_data,
                                   percentile=percentile)
            motion = np.linalg.norm(target - start, axis=1)[near] / diagonal
            error = np.linalg.norm(aligned.positions - target, axis=1)[near] / diagonal
            errors.append((error.mean(), np.percentile(error, 90)))
            print(f"{label} {percentile:g}: pair {t}: motion {motion.mean():.4f} / "
                  f"{np.percentile(motion, 90):.4f}, aligned error {error.mean():.4f} / "
                  f"{np.percentile(error, 90):.4f}", flush=True)
        mean = np.mean(errors, axis=0)
        print(f"{label} {percentile:g}: over the pairs {mean[0]:.4f} / {mean[1]:.4f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "crane", [float(p) for p in sys.argv[2:]] or [85.0, 100.0])
