"""Question: on the whole crane capture, do the colour fit's observed vertices creep only where
the print's texture pins nothing (far from any sample that pins), or also beside samples that
pin?

Setup: ``experiments/assembly_color_fit.py crane-full-mid``'s input and its cached
geometry-only chain (run that first: it writes ``/tmp/fourd_assembly_color_fit_crane-full-mid_geometry.pkl``),
fitted with the defaults. A fit sample counts as pinning when the Lucas-Kanade at the truth's
own positions weighs it at least exp(-1) in at least half of frames 1, 13, ..., 169 (as
``experiments/assembly_color_bias.py``). First the median error of the observed and the filled-in vertices, chain and fitted, at
frames 25, 75, 125, 174; then the observed vertices binned by their distance to the
nearest such sample (first frame, edges); median error against the truth in edges at frames 25,
100 and 174.

Run: ``.venv/bin/python experiments/assembly_color_creep.py`` (about 4 minutes).

Answer (2026-12-02): observed 89% / 82% / 70% / 72%; chain -> fitted, observed 2.33 -> 0.74,
4.78 -> 1.13, 5.91 -> 1.94, 7.15 -> 3.03 edges; filled in 3.04 -> 2.09, 5.24 -> 3.47, 6.76 ->
5.38, 10.89 -> 6.16. Distance 0-1.5 / 1.5-3 / 3-6 / over 6 edges holds 59% / 19% / 18% / 4% of
the observed vertices; median error at frame 25 0.60 / 0.81 / 1.22 / 2.53 edges, at frame 100
1.32 / 1.88 / 2.44 / 3.35, at frame 174 2.36 / 3.23 / 4.45 / 5.54. Farther from what pins is
worse, but the vertices beside a pinning sample creep too (0.60 -> 2.36), though the
Lucas-Kanade asks half an edge of points in place: see ``benchmarks/METHODS.md``, `assembly`,
"What the colour fit leaves on the whole capture".
"""

from __future__ import annotations

import pickle

import numpy as np
from scipy.spatial import cKDTree

from fourd import synth
from fourd.appearance.photometric import photometric_shift
from fourd.bench.suite import PROTOCOL
from fourd.geometry.grid import one_per_cube
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.normals import vertex_normals
from fourd.geometry.surface_samples import sample_surface
from fourd.methods.assembly import Options
from fourd.methods.assembly.color_fit import SAMPLE_SPACING, _field, fit_colors, frame_colors
from fourd.methods.assembly.method import frame_meshes
from fourd.metrics.scores import bind_to_surface, bound_positions

CHAIN = "/tmp/fourd_assembly_color_fit_crane-full-mid_geometry.pkl"


def main() -> None:
    truth = synth.scene("crane", frames=175, seed=0, start=0, step=1)
    scans = synth.scan(truth, resolution=256, seed=0, appearance="cloth", video=True, video_resolution=256,
                       **PROTOCOL)
    with open(CHAIN, "rb") as file:
        chain = pickle.load(file)
    meshes = frame_meshes(scans, Options())
    colors = frame_colors(scans, meshes)
    fitted = fit_colors(chain.vertices, chain.faces, chain.observed, meshes, colors)
    edge = median_edge_length(fitted[0], chain.faces)
    samples = sample_surface(truth.vertices[0], truth.faces, 20000, np.random.default_rng(0))
    followed = bound_positions(bind_to_surface(fitted[0], truth.vertices[0], truth.faces, samples),
                               truth.vertices, truth.faces)
    sample = np.flatnonzero(chain.observed[0])
    sample = sample[one_per_cube(fitted[0][sample], SAMPLE_SPACING * edge)]
    reference = _field(*meshes[0], colors[0], len(sample)).sample(followed[0][sample])
    frames = list(range(1, 175, 12))
    pinned_frames = np.zeros(len(sample))
    for t in frames:
        x = followed[t]
        result = photometric_shift(x[sample], vertex_normals(x, chain.faces)[sample], reference,
                                   _field(*meshes[t], colors[t], len(sample)), radius=5.0 * edge)
        weight = np.exp(-((result.uncertainty / (0.5 * edge)) ** 2))
        pinned_frames += np.isfinite(result.uncertainty) & (weight >= np.exp(-1.0))
    pinning = sample[pinned_frames / len(frames) >= 0.5]
    distance = cKDTree(fitted[0][pinning]).query(fitted[0])[0] / edge
    error = np.linalg.norm(fitted - followed, axis=2) / edge
    before = np.linalg.norm(chain.vertices - followed, axis=2) / edge
    for t in (25, 75, 125, 174):
        seen = chain.observed[t]
        print(f"frame {t}: {seen.mean():.0%} observed; median error chain -> fitted, observed "
              f"{np.median(before[t, seen]):.2f} -> {np.median(error[t, seen]):.2f} (90th percentile "
              f"{np.percentile(error[t, seen], 90):.1f}), filled in {np.median(before[t, ~seen]):.2f} -> "
              f"{np.median(error[t, ~seen]):.2f} edges", flush=True)
    for t in (25, 100, 174):
        observed = chain.observed[t]
        for low, high in ((0, 1.5), (1.5, 3), (3, 6), (6, np.inf)):
            inside = observed & (distance >= low) & (distance < high)
            print(f"frame {t}, {low}-{high} edges from a pinning sample: {inside.sum() / observed.sum():.0%} of the "
                  f"observed, median error {np.median(error[t, inside]):.2f} edges", flush=True)


if __name__ == "__main__":
    main()
