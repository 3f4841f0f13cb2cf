"""Anchor-guided positions: where the video's optical flow says a mesh's vertices went.

Geometry alone does not say where along a surface the skin or the cloth went, which is where
correspondences drift. The anchor tracks of the appearance (:func:`fourd.appearance.anchors`:
optical flow lifted to 3D and pruned, thesis ``004_f87f5acf96d50b57.txt`` section 5.4.1) do: a
vertex with anchors near it in the previous frame is guided to where they went
(:func:`anchor_guide`). ``kinematic``'s sliding starts each step there and pulls towards it
(paper ``000_00387fefe94cc850.txt``, section 5); ``garment``'s template fit does the same.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["Guide", "anchor_guide"]


class Guide(NamedTuple):
    """Guided start positions of one sliding step.

    vertices : int64 [G]
        The vertices with anchors near them.
    positions : float64 [G, 3]
        Where the anchors say they went.
    weight : float64 [G]
        How much to trust that, in [0, 1] (anchor support and confidence).
    """

    vertices: np.ndarray
    positions: np.ndarray
    weight: np.ndarray


def anchor_guide(
    reference: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
    confidence: np.ndarray,
    *,
    radius: float,
    support: float = 3.0,
) -> Guide:
    """Per vertex of ``reference`` [N, 3] (the tracked positions in the anchors' first frame),
    the Gaussian-weighted mean displacement ``target - source`` of the anchors [M, 3] within
    ``2 radius`` (weights ``confidence * exp(-d^2 / radius^2)``); a vertex whose summed weight
    reaches ``support`` gets weight 1 (less in proportion below it).

    Examples
    --------
    >>> grid = np.stack(np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11), [0.0]), -1).reshape(-1, 3)
    >>> guide = anchor_guide(grid, grid, grid + [0.1, 0, 0], np.ones(len(grid)), radius=0.1)
    >>> bool(np.allclose(guide.positions - grid[guide.vertices], [0.1, 0, 0]))
    True
    """
    reference = np.asarray(reference, dtype=np.float64)
    if len(source) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return Guide(empty, np.zeros((0, 3)), np.zeros(0))
    source = np.asarray(source, dtype=np.float64)
    pairs = cKDTree(reference).sparse_distance_matrix(
        cKDTree(source), 2.0 * radius, output_type="coo_matrix"
    )
    rows, cols = pairs.row.astype(np.int64), pairs.col.astype(np.int64)
    w = np.asarray(confidence, dtype=np.float64)[cols] * np.exp(-(pairs.data**2) / radius**2)
    total = np.bincount(rows, w, minlength=len(reference))
    displacement = np.stack(
        [np.bincount(rows, w * (target[cols, c] - source[cols, c]), minlength=len(reference)) for c in range(3)],
        axis=1,
    )
    guided = np.flatnonzero(total > 1e-12)
    moved = reference[guided] + displacement[guided] / total[guided, None]
    return Guide(guided, moved, np.minimum(total[guided] / support, 1.0))
