"""Question: `surfels`' completeness-95 on crane is 0.027 of the diagonal (target 0.009;
`kinematic` 0.012, `assembly` 0.005). Which truth is missing, and why: no surfel there in that
frame (never assembled, or resampled away), surfels there but the mesh clipped at the border
(weight sum under `mesh_clip`), or the surface there but misplaced?

    PYTHONPATH=src python experiments/surfels_completeness.py crane [REFERENCE:CLIP[:FLOOR] ...]

(`CLASSES=1` classes the missing truth of the first variant's mesh; `SET=geodesic=False,...`
sets options of `surfels`; `SEEDS=0.05,0.2` measures frame 0's seed at those tangential data
shares instead: how its surfels bunch; `CLOSE=0.25:1.0,...` also scores the fitted mesh with its
small holes closed, at that area fraction and C1 weight.)

The model is cached under /tmp/surfels-compl/ (`cache_dir`), so a rerun only meshes. For each
frame, truth samples farther than THRESHOLD of the diagonal from the result are "missing";
each is classed by the distance to the nearest surfel of that frame (in `eps_sampl`), the
nearest preprocessed point of that frame (in point spacings: was it seen?), and the surfels'
weight sum there over the meshing's reference (the clipping's measure).

Answer (crane, the bench's 20 frames and scan, 2-core Intel Xeon, 2026-12-05; the model of
951d1e3's code pickled as /tmp/surfels-compl/crane-geodesic=False.pickle): 26-31% of each
frame's truth lay farther than 0.01 of the diagonal from the unfitted mesh. Of it (`CLASSES=1`):
48% had a surfel within eps_sampl but a weight sum under 0.3 of the median (clipped), 26% had
data within 2 spacings but no surfel within eps_sampl (lost), 11% was unseen in its frame, 10%
had surfels there (misplaced), 4% had raw points the preprocessing dropped. Two causes:

- The surfels' weight sums spread from 0.32 to 2.27 of the median (5th-90th percentile): the
  clipping against the median drops the sparser stretches whole. Measured against the surfels
  around each point (`local`, `MeshingOptions.clip_reference`) they stay.
- The seed optimisation bunches the surfels: nearest-surfel distance 0.32 / 0.52 / 0.62
  eps_sampl (5th / 25th / 50th percentile) as sampled, 0.09 / 0.24 / 0.41 after, and 9.1% of
  frame 0's points end farther than 0.75 eps_sampl from any surfel (0.2% before). With eq. (6)
  off: 0%; the Laplacian at 1, 3, 10 times its weight: no change; the tangential share at 0.2:
  2.1%. Built within eps_top in space, the graph joins the two sides of a limb thinner than
  eps_top and eq. (6) pulls them together; without those edges (the paper's geodesic T_S):
  6.1% (13,650 -> 12,695 edges). The rest is eq. (6)'s own pull on curved stretches.

Chamfer / accuracy / completeness-95 / correspondence mean / last, every frame fitted
(`fit_frames`, as the method does), 20k samples; the graph built within eps_top in space
(before), without the edges across a limb (e8f07eb), with them kept for the deformation priors
and left out of the shape priors (2cf7b28, `geodesic`); the meshing's clipping against the
median (before) or the surfels around each point (`local:clip:floor`, now 0.4 and 0.5):

    crane      space     median:0.3      0.0056 / 0.0035 / 0.0277 / 0.0120 / 0.0210
                         local:0.5:0     0.0054 / 0.0036 / 0.0238 / 0.0126 / 0.0220
               dropped   median:0.3      0.0051 / 0.0033 / 0.0253 / 0.0106 / 0.0170
                         local:0.4:0     0.0046 / 0.0037 / 0.0196 / 0.0109 / 0.0172
                         local:0.4:0.5   0.0048 / 0.0035 / 0.0219 / 0.0106 / 0.0168
               shape     median:0.3      0.0051 / 0.0032 / 0.0253 / 0.0105 / 0.0179
                         local:0.4:0.5   0.0047 / 0.0033 / 0.0218 / 0.0108 / 0.0180
    crane-130  space     median:0.3      0.0069 / 0.0050 / 0.0292 / 0.0243 / 0.0285
                         local:0.4:0.5   0.0063 / 0.0054 / 0.0240 / 0.0248 / 0.0295
               dropped   median:0.3      0.0067 / 0.0062 / 0.0265 / 0.0274 / 0.0338
                         local:0.4:0.5   0.0063 / 0.0062 / 0.0224 / 0.0286 / 0.0362
               shape     median:0.3      0.0065 / 0.0046 / 0.0302 / 0.0228 / 0.0243
                         local:0.4:0.5   0.0061 / 0.0053 / 0.0253 / 0.0239 / 0.0266

Dropping the edges across a limb also took its cross-section's rigidity (eq. 9): crane-130's
limbs then followed worse. 0.4 against the local weight puts a uniform plane's border where
0.3 against the median did (the meshing tests' patch); without a floor a few stray surfels make
surface: touching-spheres (the pipeline test's scan) came out as one piece at frame 0, where
half the median keeps it in two (1,831 and 1,248 vertices).

What bunching is left (`SEEDS=0.05,0.1,0.2`, at 2cf7b28): frame 0's seed at the tangential data
share 0.05 (the default) leaves 6.1% of its points farther than 0.75 eps_sampl from any surfel,
at 0.1 2.9%, at 0.2 0.9% (nearest surfel 0.12 / 0.28 / 0.45 -> 0.26 / 0.45 / 0.59 eps_sampl).
On whole runs (tenth session, `SET=tangential=0.2`, fitted, `local:0.4:0.5`) it does not
give the surface back: crane 0.0047 / 0.0033 / 0.0218 / 0.0108 / 0.0180 -> 0.0046 / 0.0032 /
0.0223 / 0.0099 / 0.0174, crane-130 0.0061 / 0.0053 / 0.0253 / 0.0239 / 0.0266 -> 0.0059 /
0.0043 / 0.0264 / 0.0204 / 0.0216; with the alignment's new cutoff (`align_percentile` 100,
`experiments/surfels_alignment.py`) crane 0.0046 / 0.0030 / 0.0228 / 0.0092 / 0.0128 -> 0.0044
/ 0.0029 / 0.0222 / 0.0085 / 0.0118, crane-130 0.0047 / 0.0035 / 0.0212 / 0.0131 / 0.0162 ->
0.0051 / 0.0036 / 0.0231 / 0.0140 / 0.0164. Mixed: the share stays 0.05.

At 2cf7b28's model (`CLASSES=1`, 16-23% of each frame missing): of the missing truth 37% is
clipped, 27% lost, 17% misplaced, 13% unseen, 5% dropped by the preprocessing; the lost truth
is where a limb's surfels fell 1.4-4.3 eps_sampl behind (frames 8 and 17), which is what the
alignment's cutoff did. What no frame fills, the closing fills (`CLOSE=0.25:1.0`: the result's
holes of at most a quarter of their piece's flat area closed by the membrane,
:mod:`fourd.geometry.hole_closing`, C1 weight 1; 0.1 and 0 for the flatter membranes): on the
model with `align_percentile` 100 and the share at 0.2, crane 0.0044 / 0.0029 / 0.0222 / 0.0085 /
0.0118 -> 0.0041 / 0.0036 / 0.0155 / 0.0089 / 0.0121 (0.1), 0.0038 / 0.0035 / **0.0117** /
0.0089 / 0.0122 (1), 0.0042 / 0.0036 / 0.0164 / 0.0090 / 0.0122 (0); crane-130 with
`align_percentile` 100, 0.0047 / 0.0035 / 0.0212 / 0.0131 / 0.0162 -> 0.0048 / 0.0046 / 0.0179
/ 0.0136 / 0.0167 (0.1), 0.0047 / 0.0046 / 0.0167 / 0.0136 / 0.0166 (1), 0.0049 / 0.0046 / 0.0180
/ 0.0137 / 0.0167 (0). The membranes are guesses and are scored (accuracy +0.0006-0.0011,
correspondence +0.0004-0.0005); the C1 one is nearest on both, so `close_holes` 0.25 with
`close_smoothness` 1 is the default.
"""

from __future__ import annotations

import ast
import dataclasses
import os
import pickle
import sys

import numpy as np
from normal_fit import figures, scans_of
from scipy.spatial import cKDTree

from fourd.cache import StageCache
from fourd.geometry.hole_closing import close_small_holes
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.surface_fit import fit_along_normals
from fourd.geometry.surface_samples import sample_surface
from fourd.methods.surfels import pipeline as sp
from fourd.methods.surfels.assembly import assemble, optimize_model
from fourd.methods.surfels.meshing import MeshingOptions, _reference_weights, _window_pairs
from fourd.methods.surfels.options import Options, energy_weights

THRESHOLD = 0.01
SAMPLES = 20000


def seeded(scans, options):
    """The pipeline's steps up to the seeds: (cache, frames, merge keys, spacing, eps_sampl,
    noise, schedule, seed models)."""
    cache = StageCache(options.cache_dir)
    spacing = point_spacing(scans.frames[0].points)
    sampling = options.sampling * spacing
    noise = options.noise or spacing
    frames, keys = sp.prepare_frames(scans.frames, spacing, options, cache)
    schedule = sp.assembly_schedule(options, noise, sampling)
    seeds = sp.seed_models(frames, range(len(frames)), sampling, schedule, options)
    keys = sp.merge_keys(keys, options, cache)
    return cache, frames, keys, spacing, sampling, noise, schedule, seeds


def model_of(scans, options):
    cache, frames, keys, spacing, sampling, noise, schedule, seeds = seeded(scans, options)
    model, _ = assemble(
        seeds, frames, schedule, cache=cache, keys=keys, optimise_last=options.last_merge_optimised
    )
    model = optimize_model(
        model,
        frames,
        energy_weights(options, noise, sampling, final=True),
        sp.solver_options(options, options.final_iterations),
        schedule.match,
        urshape="rest",
    )
    return model, frames, spacing, sampling


TRACED = (0, 8, 17)


def cached_model(path, scans, options):
    """``model_of(scans, options)``, pickled at ``path`` and read from there when it exists."""
    if os.path.exists(path):
        with open(path, "rb") as f:
            return pickle.load(f)
    result = model_of(scans, options)
    with open(path, "wb") as f:
        pickle.dump(result, f)
    return result


def trace(t, truth, model, lost, sampling, diagonal):
    """Where frame ``t``'s lost truth (data, no surfel) was in frame 0, and whether the
    surfels there in frame 0 followed it."""
    if not len(lost):
        return
    tv, _ = truth.frame(t)
    v0, _ = truth.frame(0)
    vertex = cKDTree(tv).query(lost)[1]
    d0, s = cKDTree(model.state.positions[0]).query(v0[vertex])
    off = np.linalg.norm(model.state.positions[t][s] - tv[vertex], axis=1)
    covered = d0 < sampling
    print(f"  frame {t}: {len(lost)} lost; at frame 0 a surfel within eps_sampl for "
          f"{covered.mean():.2f} of them; those surfels are {np.median(off[covered]) / sampling:.2f} "
          f"eps_sampl (median, 90th {np.percentile(off[covered], 90) / sampling if covered.any() else 0:.2f}) "
          f"from where the truth went")
    groups = cKDTree(lost).query_pairs(2 * sampling, output_type="ndarray")
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n = len(lost)
    graph = coo_matrix((np.ones(len(groups)), (groups[:, 0], groups[:, 1])), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    sizes = np.bincount(labels)
    for g in np.argsort(-sizes)[:5]:
        members = labels == g
        print(f"    cluster of {sizes[g]} at {lost[members].mean(0).round(3).tolist()} "
              f"extent {np.ptp(lost[members], axis=0).round(3).tolist()}; frame 0 covered "
              f"{covered[members].mean():.2f}, offset median {np.median(off[members]) / sampling:.2f} eps_sampl")


def main(label: str, clips) -> None:
    truth, scans = scans_of(label)
    settings = dict(
        (key, ast.literal_eval(value))
        for key, value in (item.split("=") for item in os.environ.get("SET", "").split(",") if item)
    )
    suffix = "".join(f"-{key}={value}" for key, value in sorted(settings.items()))
    options = Options(cache_dir=f"/tmp/surfels-compl/{label}", **settings)
    path = f"/tmp/surfels-compl/{label}{suffix}.pickle"
    model, frames, spacing, sampling = cached_model(path, scans, options)
    diagonal = truth.diagonal()
    print(f"{label}: {model.state.count} surfels, eps_sampl {sampling:.4g}, spacing {spacing:.4g}, "
          f"diagonal {diagonal:.4g}; observed per frame {model.observed.mean():.3f}")
    meshes = {}
    for variant in clips:
        reference, clip, *floor = variant.split(":")
        mo = MeshingOptions(sigma=options.mesh_sigma, cell=options.mesh_cell, clip=float(clip),
                            clip_reference=reference, clip_floor=float(floor[0]) if floor else 0.5)
        mesh = sp.surfel_mesh(model.state, sampling, observed=model.observed, urshape=model.urshape,
                              times=np.asarray(scans.times, dtype=np.float64), options=mo)
        meshes[variant] = mesh
        print(f"{variant}: {mesh.vertices.shape[1]} vertices, observed {mesh.observed.mean():.3f}; "
              "unfitted", figures(mesh, truth), flush=True)
        fit = fit_along_normals(mesh.vertices, mesh.faces, [f.points for f in frames],
                                radius=options.fit_radius * spacing, reach=options.fit_reach * spacing)
        fitted = dataclasses.replace(mesh, vertices=fit.vertices)
        print(f"{variant}: fitted", figures(fitted, truth), flush=True)
        for closing in filter(None, os.environ.get("CLOSE", "").split(",")):
            fraction, smoothness = (float(x) for x in closing.split(":"))
            faces, vertices, observed = close_small_holes(fitted.faces, fitted.vertices, fitted.observed,
                                                          fraction, smoothness)
            closed_mesh = dataclasses.replace(fitted, faces=faces, vertices=vertices, observed=observed,
                                              rest=None)
            print(f"{variant}: fitted, closed {closing}", figures(closed_mesh, truth), flush=True)
    if os.environ.get("CLASSES") != "1":
        return
    mesh = meshes[clips[0]]
    mo = MeshingOptions()
    sigma = mo.sigma * sampling
    support = mo.support * sigma
    classes = np.zeros(5)
    heights = []
    for t in range(truth.frame_count):
        tv, tf = truth.frame(t)
        ts = sample_surface(tv, tf, SAMPLES, np.random.default_rng(t)).points
        rv, rf = mesh.frame(t)
        rs = sample_surface(rv, rf, SAMPLES * 3, np.random.default_rng(100 + t)).points
        comp = cKDTree(rs).query(ts)[0] / diagonal
        missing = ts[comp > THRESHOLD]
        positions, normals = model.state.positions[t], model.state.normals[t]
        tree = cKDTree(positions)
        surfel_d = tree.query(missing)[0] / sampling
        data_d = cKDTree(frames[t].points).query(missing)[0] / spacing
        raw_d = cKDTree(scans.frames[t].points).query(missing)[0] / spacing
        rows, cols, w = _window_pairs(missing, positions, normals, sigma, support, mo.agreement, tree)
        total = np.bincount(rows, w, minlength=len(missing))
        weight = total / _reference_weights(rows, cols, w, total, positions, normals, sigma,
                                            support, mo, tree)
        seen = data_d < 2
        near = surfel_d < 1
        c = [
            np.sum(near & (weight < mo.clip)),  # surfels there, clipped
            np.sum(near & (weight >= mo.clip)),  # surfels there, supported: misplaced surface
            np.sum(~near & seen),  # seen in this frame, no surfel: lost
            np.sum(~near & ~seen & (raw_d < 2)),  # raw points there, dropped by preprocessing
            np.sum(~near & ~seen & (raw_d >= 2)),  # unseen in this frame, not filled
        ]
        classes += c
        heights.append(missing)
        if t in TRACED:
            trace(t, truth, model, missing[~near & seen], sampling, diagonal)
        print(f"frame {t}: missing {len(missing) / SAMPLES:.3f}; clipped {c[0]} misplaced {c[1]} "
              f"lost {c[2]} dropped {c[3]} unseen {c[4]}; surfel distance median "
              f"{np.median(surfel_d) if len(missing) else 0:.2f}", flush=True)
    print("totals (clipped, misplaced, lost, preprocessing-dropped, unseen):",
          (classes / classes.sum()).round(3))
    allm = np.concatenate(heights)
    lo, hi = truth.frame(0)[0].min(0), truth.frame(0)[0].max(0)
    rel = (allm - lo) / (hi - lo)
    print("missing, relative position quantiles (x, y, z) 10/50/90:",
          np.percentile(rel, [10, 50, 90], axis=0).round(2).tolist())


def bunching(surfels, points, sampling):
    """The ``surfels`` [n, 3] against one frame's ``points`` [m, 3]: (share of the points
    farther than 0.75 eps_sampl from any surfel, nearest-surfel distance's 5th / 25th / 50th
    percentiles in eps_sampl)."""
    tree = cKDTree(surfels)
    uncovered = np.mean(tree.query(points)[0] > 0.75 * sampling)
    nearest = tree.query(surfels, k=2)[0][:, 1] / sampling
    return uncovered, np.percentile(nearest, [5, 25, 50])


def seed_bunching(label: str, tangentials) -> None:
    """Frame 0's seed at each tangential data share: nearest-surfel distances (5th / 25th /
    50th percentile, in eps_sampl) and the share of its points farther than 0.75 eps_sampl
    from any surfel."""
    _, scans = scans_of(label)
    options = Options()
    spacing = point_spacing(scans.frames[0].points)
    sampling = options.sampling * spacing
    frames, _ = sp.prepare_frames(scans.frames[:1], spacing, options, StageCache(None))
    for tangential in tangentials:
        options = Options(tangential=tangential)
        schedule = sp.assembly_schedule(options, options.noise or spacing, sampling)
        seed = sp.seed_models(frames, [0], sampling, schedule, options)[0]
        uncovered, nearest = bunching(seed.state.positions[0], frames[0].points, sampling)
        print(f"tangential {tangential}: nearest surfel {nearest.round(2)} "
              f"eps_sampl, points farther than 0.75 eps_sampl {uncovered:.3f}", flush=True)


if __name__ == "__main__":
    if os.environ.get("SEEDS"):
        seed_bunching(sys.argv[1], [float(v) for v in os.environ["SEEDS"].split(",")])
    else:
        main(sys.argv[1], sys.argv[2:] or ["median:0.3"])
