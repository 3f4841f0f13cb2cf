"""Blending transformations in Alexa's commutative algebra (thesis ``004_f87f5acf96d50b57.txt``,
Appendix A; Alexa, Linear combination of transformations, SIGGRAPH 2002).

``(+)_a w_a (.) T_a = exp(sum_a w_a log T_a)``. The anchors of material-aware deformation are
rotations with a uniform scale (section 2.3), ``T = s R``, whose logarithm is
``log(s) I + [r]_x`` with ``r`` the rotation vector of ``R`` (angle at most pi): the blend is
the scale ``exp(sum w log s)`` times the rotation of the rotation vector ``sum w r``, in closed
form and batched over triangles. Rotations compose commutatively in this algebra, which is
what lets section 2.6 split a rotation into rotations about x, y and z:
``log(R) = [r_x e_x]_x + [r_y e_y]_x + [r_z e_z]_x``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from fourd.errors import InputError

__all__ = ["Similarity", "blend", "similarity_matrices", "split_similarity"]


class Similarity(NamedTuple):
    """Rotations with a uniform scale, in log form.

    rotvecs : float64 [K, 3]
        Rotation vectors (axis times angle, radians).
    log_scales : float64 [K]
        Natural logarithms of the scales.
    """

    rotvecs: np.ndarray
    log_scales: np.ndarray


def split_similarity(matrices: np.ndarray, *, tolerance: float = 1e-3) -> Similarity:
    """Log form of 3x3 matrices ``s R`` [K, 3, 3] (polar decomposition: ``s`` the cube root of
    the determinant, ``R`` the orthogonal factor). Raises :class:`~fourd.errors.InputError`
    when a matrix is not a rotation with a uniform scale (within ``tolerance``, relative)."""
    matrices = np.asarray(matrices, dtype=np.float64).reshape(-1, 3, 3)
    det = np.linalg.det(matrices)
    if np.any(det <= 0):
        raise InputError("an anchor transformation mirrors or collapses the mesh (determinant <= 0)")
    scales = np.cbrt(det)
    rotations = matrices / scales[:, None, None]
    error = np.abs(np.einsum("kji,kjl->kil", rotations, rotations) - np.eye(3)).max(axis=(1, 2))
    if np.any(error > tolerance):
        raise InputError(
            "anchor transformations must be rotations with a uniform scale "
            f"(|R^T R - I| up to {error.max():.2g})"
        )
    return Similarity(Rotation.from_matrix(rotations).as_rotvec(), np.log(scales))


def similarity_matrices(similarity: Similarity) -> np.ndarray:
    """The 3x3 matrices [K, 3, 3] of a :class:`Similarity`."""
    rotations = Rotation.from_rotvec(np.asarray(similarity.rotvecs, dtype=np.float64)).as_matrix()
    return rotations * np.exp(np.asarray(similarity.log_scales, dtype=np.float64))[:, None, None]


def blend(weights: np.ndarray, anchors: Similarity, axis_weights: np.ndarray | None = None) -> Similarity:
    """Blend anchor transformations per triangle (equation 2.2, or 2.6's anisotropic form).

    Parameters
    ----------
    weights : float64 [F, K]
        Blending weights of each triangle (isotropic), or their mean over the three axes
        (which blends the scales, ``omega~`` of section 2.6).
    anchors : Similarity
        ``K`` anchor transformations.
    axis_weights : float64 [3, F, K], optional
        Per-axis weights (section 2.6): component ``c`` of each anchor's rotation vector is
        blended with ``axis_weights[c]``.

    Returns
    -------
    Similarity
        ``F`` blended transformations.
    """
    weights = np.asarray(weights, dtype=np.float64)
    rotvecs = np.asarray(anchors.rotvecs, dtype=np.float64)
    if axis_weights is None:
        blended = weights @ rotvecs
    else:
        blended = np.stack([axis_weights[c] @ rotvecs[:, c] for c in range(3)], axis=1)
    return Similarity(blended, weights @ np.asarray(anchors.log_scales, dtype=np.float64))
