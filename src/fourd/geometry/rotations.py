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
import scipy.sparse as sp

from fourd.geometry.eigen3 import FOUND, smallest_eigenpair


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
def _polar_newton(x00, x01, x02, x10, x11, x12, x20, x21, x22):
    """Orthogonal polar factor of the 3x3 matrix ``X`` (given row by row) with positive
    determinant by the scaled Newton iteration ``X <- (g X + X^-T / g) / 2`` (Higham 1986).
    Returns ``(converged, Y00, Y01, ..., Y22)``. Scalars throughout: small arrays allocated
    per matrix in the parallel loop cost about four times the arithmetic."""
    change = 0.0
    for _ in range(30):
        # cofactors: X^-T = cof / det
        c00 = x11 * x22 - x12 * x21
        c01 = x12 * x20 - x10 * x22
        c02 = x10 * x21 - x11 * x20
        det = x00 * c00 + x01 * c01 + x02 * c02
        if not (det > 1e-300):
            return False, x00, x01, x02, x10, x11, x12, x20, x21, x22
        c10 = x02 * x21 - x01 * x22
        c11 = x00 * x22 - x02 * x20
        c12 = x01 * x20 - x00 * x21
        c20 = x01 * x12 - x02 * x11
        c21 = x02 * x10 - x00 * x12
        c22 = x00 * x11 - x01 * x10
        nx = (x00 * x00 + x01 * x01 + x02 * x02 + x10 * x10 + x11 * x11 + x12 * x12
              + x20 * x20 + x21 * x21 + x22 * x22)
        ni = (c00 * c00 + c01 * c01 + c02 * c02 + c10 * c10 + c11 * c11 + c12 * c12
              + c20 * c20 + c21 * c21 + c22 * c22)
        # scaling g = (||X^-1||_F / ||X||_F)^(1/2)
        g = np.sqrt(np.sqrt(ni) / det / np.sqrt(nx))
        a = 0.5 * g
        b = 0.5 / (det * g)
        n00, n01, n02 = a * x00 + b * c00, a * x01 + b * c01, a * x02 + b * c02
        n10, n11, n12 = a * x10 + b * c10, a * x11 + b * c11, a * x12 + b * c12
        n20, n21, n22 = a * x20 + b * c20, a * x21 + b * c21, a * x22 + b * c22
        change = (
            (n00 - x00) ** 2 + (n01 - x01) ** 2 + (n02 - x02) ** 2
            + (n10 - x10) ** 2 + (n11 - x11) ** 2 + (n12 - x12) ** 2
            + (n20 - x20) ** 2 + (n21 - x21) ** 2 + (n22 - x22) ** 2
        )
        x00, x01, x02, x10, x11, x12, x20, x21, x22 = n00, n01, n02, n10, n11, n12, n20, n21, n22
        # Newton converges quadratically: after a step of 1e-8 the iterate is within about
        # 1e-16, so the step that would only confirm it is saved
        if change < 1e-16:
            return True, x00, x01, x02, x10, x11, x12, x20, x21, x22
    return change < 1e-12, x00, x01, x02, x10, x11, x12, x20, x21, x22


@numba.njit(cache=True)
def _rotation_by_eigenvectors(S, out):
    """Best rotation ``V U^T`` for ``S^T = V Sigma U^T`` from the eigenvectors of
    ``S S^T = U Sigma^2 U^T`` in closed form, without allocation: ``u_3`` (smallest
    eigenvalue) from the rows of ``S S^T - lambda_3 I``, ``u_1, u_2`` by a 2x2 rotation in the
    plane normal to it, ``v_i = S^T u_i / sigma_i`` for the two largest, and
    ``v_3 = det(U) v_1 x v_2`` (no reflection). Made for the nearly rank-2 covariances of
    surface vertices, where the Newton iteration is slow or the determinant is not positive;
    False when two singular values are (nearly) equal to the smallest one (rank 1, or no
    distinct smallest eigenvalue)."""
    a00 = S[0, 0] * S[0, 0] + S[0, 1] * S[0, 1] + S[0, 2] * S[0, 2]
    a11 = S[1, 0] * S[1, 0] + S[1, 1] * S[1, 1] + S[1, 2] * S[1, 2]
    a22 = S[2, 0] * S[2, 0] + S[2, 1] * S[2, 1] + S[2, 2] * S[2, 2]
    a01 = S[0, 0] * S[1, 0] + S[0, 1] * S[1, 1] + S[0, 2] * S[1, 2]
    a02 = S[0, 0] * S[2, 0] + S[0, 1] * S[2, 1] + S[0, 2] * S[2, 2]
    a12 = S[1, 0] * S[2, 0] + S[1, 1] * S[2, 1] + S[1, 2] * S[2, 2]
    _, u30, u31, u32, status = smallest_eigenpair(a00, a01, a02, a11, a12, a22, 1e-20)
    if status != FOUND:
        return False
    # an orthonormal basis (e, f) of the plane normal to u3
    if abs(u30) <= abs(u31) and abs(u30) <= abs(u32):
        e0, e1, e2 = 0.0, u32, -u31
    elif abs(u31) <= abs(u32):
        e0, e1, e2 = -u32, 0.0, u30
    else:
        e0, e1, e2 = u31, -u30, 0.0
    inv = 1.0 / np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    e0, e1, e2 = e0 * inv, e1 * inv, e2 * inv
    f0 = u31 * e2 - u32 * e1
    f1 = u32 * e0 - u30 * e2
    f2 = u30 * e1 - u31 * e0
    # A restricted to the plane, diagonalised by the angle theta
    ae0 = a00 * e0 + a01 * e1 + a02 * e2
    ae1 = a01 * e0 + a11 * e1 + a12 * e2
    ae2 = a02 * e0 + a12 * e1 + a22 * e2
    af0 = a00 * f0 + a01 * f1 + a02 * f2
    af1 = a01 * f0 + a11 * f1 + a12 * f2
    af2 = a02 * f0 + a12 * f1 + a22 * f2
    bee = e0 * ae0 + e1 * ae1 + e2 * ae2
    bff = f0 * af0 + f1 * af1 + f2 * af2
    bef = e0 * af0 + e1 * af1 + e2 * af2
    theta = 0.5 * np.arctan2(2.0 * bef, bee - bff)
    ct, st = np.cos(theta), np.sin(theta)
    u10, u11, u12 = ct * e0 + st * f0, ct * e1 + st * f1, ct * e2 + st * f2
    u20, u21, u22 = -st * e0 + ct * f0, -st * e1 + ct * f1, -st * e2 + ct * f2
    # v_i = S^T u_i / sigma_i, the second made orthogonal to the first
    w0 = S[0, 0] * u10 + S[1, 0] * u11 + S[2, 0] * u12
    w1 = S[0, 1] * u10 + S[1, 1] * u11 + S[2, 1] * u12
    w2 = S[0, 2] * u10 + S[1, 2] * u11 + S[2, 2] * u12
    n1 = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if not n1 > 1e-150:
        return False
    v10, v11, v12 = w0 / n1, w1 / n1, w2 / n1
    w0 = S[0, 0] * u20 + S[1, 0] * u21 + S[2, 0] * u22
    w1 = S[0, 1] * u20 + S[1, 1] * u21 + S[2, 1] * u22
    w2 = S[0, 2] * u20 + S[1, 2] * u21 + S[2, 2] * u22
    dot = v10 * w0 + v11 * w1 + v12 * w2
    w0, w1, w2 = w0 - dot * v10, w1 - dot * v11, w2 - dot * v12
    n2 = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if not n2 > 1e-6 * n1:
        return False
    v20, v21, v22 = w0 / n2, w1 / n2, w2 / n2
    sign = 1.0
    if (u11 * u22 - u12 * u21) * u30 + (u12 * u20 - u10 * u22) * u31 + (
        u10 * u21 - u11 * u20
    ) * u32 < 0:
        sign = -1.0
    v30 = sign * (v11 * v22 - v12 * v21)
    v31 = sign * (v12 * v20 - v10 * v22)
    v32 = sign * (v10 * v21 - v11 * v20)
    out[0, 0] = v10 * u10 + v20 * u20 + v30 * u30
    out[0, 1] = v10 * u11 + v20 * u21 + v30 * u31
    out[0, 2] = v10 * u12 + v20 * u22 + v30 * u32
    out[1, 0] = v11 * u10 + v21 * u20 + v31 * u30
    out[1, 1] = v11 * u11 + v21 * u21 + v31 * u31
    out[1, 2] = v11 * u12 + v21 * u22 + v31 * u32
    out[2, 0] = v12 * u10 + v22 * u20 + v32 * u30
    out[2, 1] = v12 * u11 + v22 * u21 + v32 * u31
    out[2, 2] = v12 * u12 + v22 * u22 + v32 * u32
    return True


@numba.njit(cache=True, parallel=True)
def _best_rotations(S, R):
    for i in numba.prange(len(S)):
        s = S[i]
        # X = S^T
        x00, x01, x02 = s[0, 0], s[1, 0], s[2, 0]
        x10, x11, x12 = s[0, 1], s[1, 1], s[2, 1]
        x20, x21, x22 = s[0, 2], s[1, 2], s[2, 2]
        det = x00 * (x11 * x22 - x12 * x21) - x01 * (x10 * x22 - x12 * x20) + x02 * (
            x10 * x21 - x11 * x20
        )
        nx = (x00 * x00 + x01 * x01 + x02 * x02 + x10 * x10 + x11 * x11 + x12 * x12
              + x20 * x20 + x21 * x21 + x22 * x22)
        if det > 1e-12 * (nx**1.5 + 1e-300):
            ok, y00, y01, y02, y10, y11, y12, y20, y21, y22 = _polar_newton(
                x00, x01, x02, x10, x11, x12, x20, x21, x22
            )
            if ok:
                r = R[i]
                r[0, 0], r[0, 1], r[0, 2] = y00, y01, y02
                r[1, 0], r[1, 1], r[1, 2] = y10, y11, y12
                r[2, 0], r[2, 1], r[2, 2] = y20, y21, y22
                continue
        if _rotation_by_eigenvectors(S[i], R[i]):
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


def one_ring_rotations(weights: sp.spmatrix, rest: np.ndarray, deformed: np.ndarray,
                       rows: np.ndarray | None = None) -> np.ndarray:
    """Each vertex's rotation best aligning its one-ring's edges at rest with the deformed ones,
    the local step of as-rigid-as-possible modelling (Sorkine and Alexa 2007, eq. 5-6):
    ``R_i`` maximises ``sum_j w_ij (d_j - d_i) . R_i (r_j - r_i)``.

    Parameters
    ----------
    weights : sparse [N, N]
        Non-negative edge weights ``w_ij`` (the one-rings: the non-zeros of row ``i``).
    rest, deformed : array [N, 3]
    rows : int array [K], optional
        Only these vertices' rotations (all by default).

    Returns
    -------
    ndarray float [N, 3, 3] (or [K, 3, 3])
        Proper rotations with ``R_i (r_j - r_i) ~ d_j - d_i``; the identity where a vertex
        has no weighted edge.
    """
    rest = np.ascontiguousarray(rest, dtype=np.float64)
    deformed = np.ascontiguousarray(deformed, dtype=np.float64)
    edges = weights if sp.issparse(weights) and weights.format == "csr" else sp.csr_matrix(weights)
    rows = np.arange(edges.shape[0]) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
    covariance = _one_ring_covariances(edges.indptr, edges.indices, np.asarray(edges.data, dtype=np.float64),
                                       rest, deformed, rows)
    rotations = best_rotations(covariance)
    rotations[np.diff(edges.indptr)[rows] == 0] = np.eye(3)
    return rotations


def arap_right_hand_side(weights: sp.spmatrix, rest: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """The right-hand side of as-rigid-as-possible modelling's global step (Sorkine and Alexa
    2007, eq. 9): ``b_i = sum_j w_ij / 2 (R_i + R_j) (r_i - r_j)``, ``[N, 3]``.

    Parameters
    ----------
    weights : sparse [N, N]
        The edge weights ``w_ij`` of :func:`one_ring_rotations`.
    rest : array [N, 3]
    rotations : array [N, 3, 3]
        Each vertex's rotation (:func:`one_ring_rotations`).
    """
    edges = weights if sp.issparse(weights) and weights.format == "csr" else sp.csr_matrix(weights)
    return _arap_right_hand_side(edges.indptr, edges.indices, np.asarray(edges.data, dtype=np.float64),
                                 np.ascontiguousarray(rest, dtype=np.float64),
                                 np.ascontiguousarray(rotations, dtype=np.float64))


@numba.njit(cache=True, nogil=True)
def _arap_right_hand_side(indptr, indices, weights, rest, rotations):
    """``sum_j w_ij / 2 (R_i + R_j) (r_i - r_j)`` per row ``i`` of the CSR weights ``[N, 3]``."""
    count = len(indptr) - 1
    right = np.zeros((count, 3))
    for i in range(count):
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            d0, d1, d2 = rest[i, 0] - rest[j, 0], rest[i, 1] - rest[j, 1], rest[i, 2] - rest[j, 2]
            for a in range(3):
                # summed as numpy's einsum sums it (first and last term, then the middle), so
                # the result is the vectorised form's to the last bit: the assembly's choices of
                # patches downstream turn on it
                rotated = (((rotations[i, a, 0] + rotations[j, a, 0]) * d0
                            + (rotations[i, a, 2] + rotations[j, a, 2]) * d2)
                           + (rotations[i, a, 1] + rotations[j, a, 1]) * d1)
                right[i, a] += (0.5 * rotated) * weights[e]
    return right


@numba.njit(cache=True, nogil=True)
def _one_ring_covariances(indptr, indices, weights, rest, deformed, rows):
    """``sum_j w_ij (r_j - r_i) (d_j - d_i)^T`` for each row ``i`` in ``rows [K]`` of the CSR
    weights, ``[K, 3, 3]``."""
    covariance = np.zeros((len(rows), 3, 3))
    for k in range(len(rows)):
        i = rows[k]
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            w = weights[e]
            for a in range(3):
                before = w * (rest[j, a] - rest[i, a])
                for b in range(3):
                    covariance[k, a, b] += before * (deformed[j, b] - deformed[i, b])
    return covariance


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
