"""Best-fitting rotations, batched: the local step of as-rigid-as-possible deformation and the
orthogonal Procrustes problem.

References
----------
Sorkine, Alexa: As-rigid-as-possible surface modeling, SGP 2007 (eq. 4-6).
Umeyama: Least-squares estimation of transformation parameters between two point patterns,
IEEE PAMI 13(4), 1991.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


def best_rotations(covariances: np.ndarray) -> np.ndarray:
    """Rotations maximising ``trace(R S)`` for each covariance ``S = sum w (p0)(p)^T``.

    With ``S = U Sigma V^T`` the answer is ``R = V U^T``, with the sign of the column of ``U``
    belonging to the smallest singular value flipped when ``det(V U^T) < 0`` (no reflections).

    Parameters
    ----------
    covariances : ndarray float [N, 3, 3] (or [3, 3])

    Returns
    -------
    ndarray float [N, 3, 3] proper rotations (det = +1), same leading shape as the input.

    Examples
    --------
    >>> import numpy as np
    >>> R = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])
    >>> P = np.random.default_rng(0).normal(size=(10, 3))
    >>> S = P.T @ (P @ R.T)          # sum_k p_k (R p_k)^T
    >>> bool(np.allclose(best_rotations(S), R))
    True
    """
    S = np.asarray(covariances, dtype=np.float64)
    single = S.ndim == 2
    S = np.ascontiguousarray(S.reshape(-1, 3, 3))
    R = np.empty_like(S)
    if len(S):
        _best_rotations(S, R)
    return R[0] if single else R


@numba.njit(cache=True, inline="always")
def _det3(X):
    return (
        X[0, 0] * (X[1, 1] * X[2, 2] - X[1, 2] * X[2, 1])
        - X[0, 1] * (X[1, 0] * X[2, 2] - X[1, 2] * X[2, 0])
        + X[0, 2] * (X[1, 0] * X[2, 1] - X[1, 1] * X[2, 0])
    )


@numba.njit(cache=True)
def _polar_newton(X, out):
    """Orthogonal polar factor of a 3x3 matrix with positive determinant by the scaled Newton
    iteration ``X <- (g X + X^-T / g) / 2`` (Higham 1986); False if it did not converge."""
    Y = X.copy()
    cof = np.empty((3, 3))
    for _ in range(30):
        det = _det3(Y)
        if not (det > 1e-300):
            return False
        cof[0, 0] = Y[1, 1] * Y[2, 2] - Y[1, 2] * Y[2, 1]
        cof[0, 1] = Y[1, 2] * Y[2, 0] - Y[1, 0] * Y[2, 2]
        cof[0, 2] = Y[1, 0] * Y[2, 1] - Y[1, 1] * Y[2, 0]
        cof[1, 0] = Y[0, 2] * Y[2, 1] - Y[0, 1] * Y[2, 2]
        cof[1, 1] = Y[0, 0] * Y[2, 2] - Y[0, 2] * Y[2, 0]
        cof[1, 2] = Y[0, 1] * Y[2, 0] - Y[0, 0] * Y[2, 1]
        cof[2, 0] = Y[0, 1] * Y[1, 2] - Y[0, 2] * Y[1, 1]
        cof[2, 1] = Y[0, 2] * Y[1, 0] - Y[0, 0] * Y[1, 2]
        cof[2, 2] = Y[0, 0] * Y[1, 1] - Y[0, 1] * Y[1, 0]
        # X^-T = cof / det; scaling g = (||X^-1||_F / ||X||_F)^(1/2)
        nx = 0.0
        ni = 0.0
        for a in range(3):
            for b in range(3):
                nx += Y[a, b] * Y[a, b]
                ni += cof[a, b] * cof[a, b]
        g = np.sqrt(np.sqrt(ni) / det / np.sqrt(nx))
        change = 0.0
        for a in range(3):
            for b in range(3):
                new = 0.5 * (g * Y[a, b] + cof[a, b] / (det * g))
                change += (new - Y[a, b]) ** 2
                Y[a, b] = new
        if change < 1e-24:
            out[:, :] = Y
            return True
    out[:, :] = Y
    return change < 1e-12


@numba.njit(cache=True, parallel=True)
def _best_rotations(S, R):
    for i in numba.prange(len(S)):
        X = S[i].T.copy()
        if _det3(X) > 1e-12 * (np.sum(X * X) ** 1.5 + 1e-300):
            if _polar_newton(X, R[i]):
                continue
        U, _, Vt = np.linalg.svd(S[i])
        Ri = Vt.T @ U.T
        det = (
            Ri[0, 0] * (Ri[1, 1] * Ri[2, 2] - Ri[1, 2] * Ri[2, 1])
            - Ri[0, 1] * (Ri[1, 0] * Ri[2, 2] - Ri[1, 2] * Ri[2, 0])
            + Ri[0, 2] * (Ri[1, 0] * Ri[2, 1] - Ri[1, 1] * Ri[2, 0])
        )
        if det < 0:
            U2 = U.copy()
            U2[:, 2] *= -1.0
            Ri = Vt.T @ U2.T
        R[i] = Ri


class RigidTransform(NamedTuple):
    """``y ~ scale * rotation @ x + translation``; ``rms`` is the weighted residual."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    rms: float


def procrustes(
    source: np.ndarray,
    target: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    with_scale: bool = False,
) -> RigidTransform:
    """Least-squares rigid (or similarity) transform mapping ``source`` [P, 3] onto ``target``.

    Raises ``ValueError`` for mismatched shapes or fewer than three points.
    """
    X = np.asarray(source, dtype=np.float64)
    Y = np.asarray(target, dtype=np.float64)
    if X.shape != Y.shape or X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"source and target must both be [P, 3], got {X.shape} and {Y.shape}")
    if len(X) < 3:
        raise ValueError("need at least three points")
    w = np.ones(len(X)) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    mx, my = w @ X, w @ Y
    Xc, Yc = X - mx, Y - my
    S = (Xc * w[:, None]).T @ Yc
    R = best_rotations(S)
    scale = 1.0
    if with_scale:
        variance = float(w @ np.einsum("ij,ij->i", Xc, Xc))
        scale = float(np.trace(R @ S)) / max(variance, 1e-300)
    t = my - scale * R @ mx
    residual = Y - (scale * X @ R.T + t)
    rms = float(np.sqrt(w @ np.einsum("ij,ij->i", residual, residual)))
    return RigidTransform(R, t, scale, rms)
