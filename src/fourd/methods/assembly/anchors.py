"""Sparse correspondences between a source and a target mesh: anchors (thesis section 5.4.1).

An anchor is a source vertex and a point on the target surface (a target triangle and
barycentric coordinates in it); in the method they come from optical flow
(:func:`fourd.appearance.anchors`), in tests from the truth.

Whatever their source, the anchor set is cleaned twice before use (5.4.1): anchors whose
point, sent back to the source, does not return near where it started are dropped
(:func:`consistent_anchors`, the thesis' forward-backward check, here for any backward map),
and where anchors crowd, some are dropped so that the rest are roughly uniform
(:func:`spread_anchors`; where they are too sparse, the refinement of 5.4.4 adds more).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree


class Anchors(NamedTuple):
    """Source vertices with a known point on the target.

    source : int64 [A]
        Source vertex of each anchor.
    target_faces : int64 [A]
        Target triangle of each anchor's corresponding point.
    target_barycentric : float64 [A, 3]
        Its barycentric coordinates in that triangle.
    """

    source: np.ndarray
    target_faces: np.ndarray
    target_barycentric: np.ndarray

    def target_corners(self, target_faces: np.ndarray) -> np.ndarray:
        """The target vertices each anchor's point depends on ``[A, 3]``: its triangle's
        corners, -1 where its barycentric coordinate is 0 (a point on an edge or at a vertex
        belongs to every triangle around it)."""
        corners = np.asarray(target_faces, dtype=np.int64)[self.target_faces]
        return np.where(self.target_barycentric > 0, corners, -1)

    def target_points(self, target_vertices: np.ndarray, target_faces: np.ndarray) -> np.ndarray:
        """The anchors' points on the target ``[A, 3]``."""
        corners = np.asarray(target_vertices, dtype=np.float64)[np.asarray(target_faces)[self.target_faces]]
        return np.einsum("ak,akd->ad", self.target_barycentric, corners)

    def subset(self, which: np.ndarray) -> Anchors:
        """The anchors picked by ``which`` (bool mask ``[A]`` or indices)."""
        return Anchors(self.source[which], self.target_faces[which], self.target_barycentric[which])

    @staticmethod
    def join(*parts: Anchors) -> Anchors:
        """The anchors of all ``parts``, in order."""
        return Anchors(*(np.concatenate([getattr(p, name) for p in parts]) for name in Anchors._fields))


def anchors_at_vertices(source: np.ndarray, target: np.ndarray, target_faces: np.ndarray) -> Anchors:
    """Anchors whose target points are target vertices: ``source [A]`` matched to ``target
    [A]`` (each target vertex must belong to a face of ``target_faces [F, 3]``)."""
    source = np.asarray(source, dtype=np.int64).reshape(-1)
    target = np.asarray(target, dtype=np.int64).reshape(-1)
    target_faces = np.asarray(target_faces, dtype=np.int64)
    if source.shape != target.shape:
        raise ValueError(f"{len(source)} source vertices for {len(target)} target vertices")
    face_of = np.full(int(target_faces.max()) + 1, -1, dtype=np.int64)
    corner_of = np.zeros_like(face_of)
    for k in range(3):
        face_of[target_faces[:, k]] = np.arange(len(target_faces))
        corner_of[target_faces[:, k]] = k
    if np.any(target >= len(face_of)) or np.any(face_of[target] < 0):
        raise ValueError("every target anchor vertex must belong to a target face")
    return Anchors(source, face_of[target], np.eye(3)[corner_of[target]])


def returned_points(anchors: Anchors, target_faces: np.ndarray, backward: np.ndarray) -> np.ndarray:
    """Where the anchors' target points land when sent back to the source ``[A, 3]``.

    ``backward [M, 3]`` is the backward map at the target's vertices (each target vertex's
    point on the source: a target-to-source cross-parameterisation, or the backward optical
    flow lifted to 3D), interpolated at each anchor's point by its barycentric coordinates.
    """
    corners = np.asarray(backward, dtype=np.float64)[np.asarray(target_faces)[anchors.target_faces]]
    return np.einsum("ak,akd->ad", anchors.target_barycentric, corners)


def consistent_anchors(anchors: Anchors, source_vertices: np.ndarray, returned: np.ndarray,
                       tolerance: float) -> np.ndarray:
    """The forward-backward check of 5.4.1: anchors whose point, sent forward to the target
    and back (``returned [A, 3]``, e.g. :func:`returned_points`), lands within ``tolerance``
    (input units) of its source vertex, bool ``[A]``. The thesis keeps the flow
    correspondences whose round trip returns within an epsilon (one pixel in the images, then
    an epsilon in 3D); an anchor with no return (NaN) is inconsistent."""
    if not tolerance > 0:
        raise ValueError(f"tolerance must be > 0, got {tolerance!r}")
    start = np.asarray(source_vertices, dtype=np.float64)[anchors.source]
    gap = np.linalg.norm(np.asarray(returned, dtype=np.float64) - start, axis=1)
    return gap <= tolerance


def spread_anchors(
    anchors: Anchors,
    source_vertices: np.ndarray,
    spacing: float,
    *,
    priority: np.ndarray | None = None,
    keep: np.ndarray | None = None,
    seed: int = 0,
) -> np.ndarray:
    """Thin the anchors to a roughly uniform density: a maximal set of anchors no two of which
    lie closer than ``spacing`` on the source (input units; straight-line distance), bool
    ``[A]``.

    Every dropped anchor has a kept one within ``spacing``, so the kept ones cover all the
    dropped ones did, at about one per ``spacing``. Where two anchors conflict the one of
    higher ``priority [A]`` wins (e.g. the more consistent; by default at random, from
    ``seed``); the anchors of ``keep [A]`` (bool) are kept whatever their neighbours, and the
    others give way to them. The selection runs in rounds (a Jones-Plassmann maximal
    independent set): each round keeps every undecided anchor of higher priority than all its
    undecided neighbours and drops their neighbours.
    """
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0, got {spacing!r}")
    count = len(anchors.source)
    rng = np.random.default_rng(seed)
    jitter = rng.random(count)
    if priority is None:
        key = jitter
    else:
        # the rank of the priority, ties broken at random
        key = np.empty(count)
        key[np.lexsort((jitter, np.asarray(priority, dtype=np.float64)))] = np.arange(count)
    points = np.asarray(source_vertices, dtype=np.float64)[anchors.source]
    pairs = cKDTree(points).query_pairs(spacing, output_type="ndarray")
    graph = sp.csr_matrix((np.ones(2 * len(pairs)), (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                          shape=(count, count))
    kept = np.zeros(count, dtype=bool) if keep is None else np.asarray(keep, dtype=bool).copy()
    undecided = ~kept & ~_touching(graph, kept)
    filled = np.diff(graph.indptr) > 0
    while undecided.any():
        current = np.where(undecided, key, -1.0)
        highest = np.full(count, -1.0)
        highest[filled] = np.maximum.reduceat(current[graph.indices], graph.indptr[:-1][filled])
        chosen = undecided & (current > highest)
        kept |= chosen
        undecided &= ~chosen & ~_touching(graph, chosen)
    return kept


def _touching(graph: sp.csr_matrix, members: np.ndarray) -> np.ndarray:
    """Nodes with a neighbour in ``members``."""
    return (graph @ members.astype(np.float64)) > 0
