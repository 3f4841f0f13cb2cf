"""Question: `surfels` on horse-gallop (48 frames) gives Chamfer 0.0283 and correspondence
0.053 / 0.098 (`kinematic` 0.0028, 0.0087 / 0.0042), and its plot shows spikes reaching far
out of the scene by the last frame. What flies off, and what should the mesh do with it?

    PYTHONPATH=src:experiments python experiments/surfels_lost_pieces.py horse-gallop [MIN_PIECE ...]

Builds the model as the pipeline does (kept as /tmp/surfels-lost/LABEL-model.pickle, the
merges cached), then: the pieces of the graph T_S, the surfels that leave the truth's box by
more than 5% of the diagonal in some frame (their piece's size, when they last had data, how far
they end); then the mesh as the method makes it (meshed, fitted, closed) with the pieces of
fewer than MIN_PIECE surfels that lack data in some frame left out (`unsupported_pieces`),
scored on 20k samples (Chamfer / accuracy / completeness-95 / correspondence mean / last).

Answer (2026-12-05, eleventh session, at 7d8dfcc; 1,893 surfels): the graph is
shattered, 403 surfels alone and 18 more pieces of 2-24 against one of 1,375 (the stretch filter
of the stitching cuts the fast legs' edges). 88 surfels leave the box: 78 alone in the graph, 10
in pieces of 3-4, each last observed 4-40 frames before the end and then moving on at its last
velocity (the acceleration prior of eq. 10 is all that acts on a piece with no neighbours and
no data), up to 4.9 diagonals away by frame 47. Leaving the small pieces without data in some
frame out of the mesh:

    MIN_PIECE      dropped
    0 (before)     0      0.0291 / 0.0501 / 0.0290 / 0.0531 / 0.0984
    2              400    0.0110 / 0.0105 / 0.0514 / 0.0225 / 0.0275
    4              420    0.0111 / 0.0102 / 0.0552 / 0.0217 / 0.0261
    8 (default)    449    0.0107 / 0.0084 / 0.0660 / 0.0187 / 0.0222
    16             469    (catches the same 88)

Moving them instead, in the frames without data, by the mean motion of the 4 nearest supported
surfels since their nearest frame with data (tried, not kept) keeps completeness-95 (0.0297) but
leaves them misplaced: 0.0164 / 0.0251 / 0.0297 / 0.0428 / 0.0596. Missing surface is closed or
seen as a hole; misplaced surface is wrong geometry. At 8 crane is unchanged (nothing dropped),
crane-50 0.0062 / 0.0063 / 0.0226 / 0.0282 / 0.0419 -> 0.0059 / 0.0057 / 0.0230 / 0.0273 /
0.0412 (27 dropped), crane-130 level (3 dropped). What is left on horse-gallop is the shattered
graph itself: the legs lose their data and their surface (completeness-95 0.066).
"""

from __future__ import annotations

import dataclasses
import os
import sys

import numpy as np
from normal_fit import figures, scans_of
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from surfels_completeness import cached_model

from fourd.geometry.surface_fit import fit_along_normals
from fourd.methods.surfels import pipeline as sp
from fourd.methods.surfels.meshing import surfel_mesh
from fourd.methods.surfels.model import unsupported_pieces, without_surfels
from fourd.methods.surfels.options import Options

FOLDER = "/tmp/surfels-lost"


def main(label: str, min_pieces: list[int]) -> None:
    os.makedirs(FOLDER, exist_ok=True)
    truth, scans = scans_of(label)
    options = Options(cache_dir=f"{FOLDER}/cache-{label}")
    path = f"{FOLDER}/{label}-model.pickle"
    model, frames, spacing, sampling = cached_model(path, scans, options)
    diagonal, count = truth.diagonal(), model.state.count
    edges = model.topology.edges
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(count, count))
    _, label_of = connected_components(graph, directed=False)
    size = np.bincount(label_of)
    print(f"{label}: {count} surfels; pieces of the graph {sorted(size[size > 1])[::-1][:20]}, "
          f"{int((size == 1).sum())} alone")
    positions = model.state.positions
    low, high = truth.vertices.reshape(-1, 3).min(0), truth.vertices.reshape(-1, 3).max(0)
    outside = ((positions < low - 0.05 * diagonal) | (positions > high + 0.05 * diagonal)).any(2)
    flown = np.flatnonzero(outside.any(axis=0))
    print(f"{len(flown)} surfels leave the truth's box; sizes of their pieces",
          np.bincount(size[label_of[flown]]).tolist())
    for s in flown:
        seen = np.flatnonzero(model.observed[:, s])
        beyond = np.maximum(positions[-1, s] - high, 0) + np.maximum(low - positions[-1, s], 0)
        print(f"  surfel {s}: piece of {size[label_of[s]]}, last data at frame "
              f"{seen.max() if len(seen) else -1}, ends {np.linalg.norm(beyond) / diagonal:.3f} "
              "diagonals beyond the box")
    for min_piece in min_pieces:
        lost = unsupported_pieces(model, min_piece)
        kept = without_surfels(model, lost) if lost.any() else model
        mesh = surfel_mesh(kept.state, sampling, reference=0, observed=kept.observed,
                           urshape=kept.urshape, times=np.asarray(scans.times, dtype=float),
                           options=sp.meshing_options(options))
        fit = fit_along_normals(mesh.vertices, mesh.faces, [f.points for f in frames],
                                radius=options.fit_radius * spacing,
                                reach=options.fit_reach * spacing)
        mesh = sp.closed_mesh(dataclasses.replace(mesh, vertices=fit.vertices), options)
        print(f"min_piece {min_piece}: {int(lost.sum())} dropped, caught "
              f"{int(lost[flown].sum())} of {len(flown)}; {figures(mesh, truth)}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "horse-gallop",
         [int(a) for a in sys.argv[2:]] or [0, 2, 4, 8])
