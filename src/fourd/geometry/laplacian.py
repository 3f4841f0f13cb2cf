"""Discrete Laplacians of triangle meshes: cotangent weights, cotangent Laplacian, lumped mass
matrix, uniform (umbrella) Laplacian and explicit Laplacian smoothing.

All functions are free functions over ``(vertices [N, 3], faces [F, 3])`` returning
``scipy.sparse`` matrices in CSR form.

Sign convention: the Laplacians returned here are *positive semi-definite*,
``(L x)_i = sum_j w_ij (x_i - x_j)``, so that ``x^T L x = sum_edges w_ij |x_i - x_j|^2``.

References
----------
Pinkall, Polthier: Computing discrete minimal surfaces and their conjugates, Experimental
Mathematics 2(1), 1993 (cotangent weights).
Meyer, Desbrun, Schroeder, Barr: Discrete differential-geometry operators for triangulated
2-manifolds, VisMath 2002 (mass matrix).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def _check(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must have shape [N, 3], got {list(vertices.shape)}")
    if faces.size == 0:
        faces = faces.reshape(0, 3)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape [F, 3], got {list(faces.shape)}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError("faces index vertices out of range")
    return vertices, faces


def cotangent_weights(
    vertices: np.ndarray, faces: np.ndarray, *, clamp_negative: bool = False
) -> sp.csr_matrix:
    """Symmetric edge weights ``w_ij = (cot a_ij + cot b_ij) / 2``.

    Parameters
    ----------
    vertices : ndarray float [N, 3]
    faces : ndarray int [F, 3]
    clamp_negative : bool
        Replace negative edge weights (opposite angles summing to more than pi) by zero, which
        keeps the Laplacian positive semi-definite and an M-matrix.

    Returns
    -------
    W : csr_matrix [N, N], zero diagonal, ``W[i, j] = w_ij`` for every mesh edge.
    """
    vertices, faces = _check(vertices, faces)
    n = len(vertices)
    if len(faces) == 0:
        return sp.csr_matrix((n, n))
    rows, cols, values = [], [], []
    for k in range(3):
        i, j, o = faces[:, (k + 1) % 3], faces[:, (k + 2) % 3], faces[:, k]
        a = vertices[i] - vertices[o]
        b = vertices[j] - vertices[o]
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        dot = np.einsum("ij,ij->i", a, b)
        scale = np.einsum("ij,ij->i", a, a) + np.einsum("ij,ij->i", b, b)
        cot = dot / np.maximum(cross, 1e-12 * np.maximum(scale, 1e-300))
        rows += [i, j]
        cols += [j, i]
        values += [0.5 * cot, 0.5 * cot]
    W = sp.csr_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )
    W.sum_duplicates()
    if clamp_negative:
        W.data = np.maximum(W.data, 0.0)
    W.setdiag(0.0)
    W.eliminate_zeros()
    return W


def weights_laplacian(W: sp.spmatrix) -> sp.csr_matrix:
    """``L = diag(W 1) - W`` for a symmetric weight matrix ``W`` (positive semi-definite for
    non-negative weights)."""
    W = sp.csr_matrix(W)
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()


def cotangent_laplacian(
    vertices: np.ndarray, faces: np.ndarray, *, clamp_negative: bool = False
) -> sp.csr_matrix:
    """Cotangent Laplacian ``L`` [N, N] (positive semi-definite convention).

    ``x^T L x = sum_{edges ij} w_ij |x_i - x_j|^2`` with cotangent weights ``w_ij``; for a
    linear function on a flat mesh, ``L x`` vanishes at interior vertices.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    >>> F = np.array([[0, 1, 2], [1, 3, 2]])
    >>> L = cotangent_laplacian(V, F)
    >>> bool(np.allclose(L @ np.ones(4), 0))
    True
    """
    return weights_laplacian(cotangent_weights(vertices, faces, clamp_negative=clamp_negative))


def uniform_laplacian(vertex_count: int, faces: np.ndarray) -> sp.csr_matrix:
    """Graph (umbrella) Laplacian with unit edge weights, positive semi-definite convention."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    i = faces[:, [0, 1, 2]].ravel()
    j = faces[:, [1, 2, 0]].ravel()
    A = sp.csr_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(vertex_count,) * 2)
    A.data[:] = 1.0
    return weights_laplacian(A)


def mass_matrix(vertices: np.ndarray, faces: np.ndarray) -> sp.dia_matrix:
    """Lumped (barycentric) mass matrix: a third of the incident triangle areas per vertex."""
    from fourd.geometry.meshes import face_areas

    vertices, faces = _check(vertices, faces)
    area = face_areas(vertices, faces)
    mass = np.bincount(faces.ravel(), weights=np.repeat(area / 3.0, 3), minlength=len(vertices))
    return sp.diags(mass)


def laplacian_smooth(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    iterations: int = 10,
    step: float = 0.5,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Explicit umbrella smoothing: ``x <- x + step * (mean of neighbours - x)``, repeated.

    ``weights`` [N] in [0, 1] (optional) scale each vertex's step: 0 keeps a vertex where it
    is. Vertices with no incident face stay where they are. Returns new vertices [N, 3].
    """
    vertices, faces = _check(vertices, faces)
    if iterations <= 0 or len(faces) == 0:
        return vertices.copy()
    L = uniform_laplacian(len(vertices), faces)
    degree = L.diagonal()
    inverse = np.where(degree > 0, 1.0 / np.maximum(degree, 1e-300), 0.0)
    if weights is not None:
        inverse = inverse * np.asarray(weights, dtype=np.float64)
    x = vertices.copy()
    for _ in range(iterations):
        x = x - step * inverse[:, None] * (L @ x)
    return x
