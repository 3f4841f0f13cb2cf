"""Local frames of triangles and their deformation gradients (thesis ``004_f87f5acf96d50b57.txt``,
section 2.4.2, after Sumner and Popović, Deformation transfer for triangle meshes, SIGGRAPH
2004, section 3).

A triangle ``(v1, v2, v3)`` does not span 3D, so a fourth point is added along its normal,
``v4 = v1 + (v2 - v1) x (v3 - v1) / sqrt(|(v2 - v1) x (v3 - v1)|)`` (a length of the order of
the edges), and the frame is ``V = (v4 - v1, v4 - v2, v4 - v3)`` (columns). The deformation
gradient of a deformed triangle is ``A = V~ V^-1``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["deformation_gradients", "fourth_points", "local_frames"]


def fourth_points(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The point off each triangle along its normal, ``v4`` [F, 3]."""
    v1, v2, v3 = (vertices[faces[:, k]] for k in range(3))
    normal = np.cross(v2 - v1, v3 - v1)
    length = np.sqrt(np.maximum(np.linalg.norm(normal, axis=1), 1e-300))
    return v1 + normal / length[:, None]


def local_frames(vertices: np.ndarray, faces: np.ndarray, fourth: np.ndarray | None = None) -> np.ndarray:
    """Frames ``V = (v4 - v1, v4 - v2, v4 - v3)`` [F, 3, 3] (the vectors as columns)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    v4 = fourth_points(vertices, faces) if fourth is None else fourth
    return np.stack([v4 - vertices[faces[:, k]] for k in range(3)], axis=2)


def deformation_gradients(rest: np.ndarray, posed: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``A = V~ V^-1`` [..., F, 3, 3] of ``posed`` [..., N, 3] against ``rest`` [N, 3].

    Examples
    --------
    >>> rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    >>> turn = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)
    >>> bool(np.allclose(deformation_gradients(rest, 2 * rest @ turn.T, np.array([[0, 1, 2]])), 2 * turn))
    True
    """
    faces = np.asarray(faces, dtype=np.int64)
    inverse = np.linalg.inv(local_frames(rest, faces))
    posed = np.asarray(posed, dtype=np.float64)
    if posed.ndim == 2:
        return local_frames(posed, faces) @ inverse
    return np.stack([local_frames(p, faces) @ inverse for p in posed])
