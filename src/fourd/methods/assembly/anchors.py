"""Sparse correspondences between a source and a target mesh: anchors (thesis section 5.4.1).

An anchor is a source vertex and a point on the target surface (a target triangle and
barycentric coordinates in it); in the method they come from optical flow
(:func:`fourd.appearance.anchors`), in tests from the truth.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


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
