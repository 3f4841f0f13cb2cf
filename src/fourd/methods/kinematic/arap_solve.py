"""The ARAP system of the sliding (section 5.3) split as libigl does: a precompute of what
stays fixed over the whole sliding (:func:`slide_precompute`) and a solver factorised once
per time step (:class:`ConstrainedSolver`, the constraints eliminated by the null-space
method).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fourd.geometry.factors import elimination_order
from fourd.geometry.laplacian import cotangent_weights, weights_laplacian
from fourd.geometry.meshes import median_edge_length


class SlidePrecompute(NamedTuple):
    """What stays fixed over the whole sliding: the template's cotangent weights, Laplacian
    and edge incidence (libigl's ``arap_precomputation``)."""

    rest: np.ndarray
    edge_i: np.ndarray
    edge_j: np.ndarray
    edge_w: np.ndarray
    incidence: sp.csr_matrix
    laplacian: sp.csr_matrix
    rest_edges: np.ndarray
    edge_length: float
    indptr: np.ndarray
    order: np.ndarray
    ordered_laplacian: sp.csr_matrix


def slide_precompute(
    rest_vertices: np.ndarray, faces: np.ndarray, edge_stiffness=None
) -> SlidePrecompute:
    """Cotangent weights (clamped at zero), Laplacian ``L`` and directed edge lists of the
    template.

    ``edge_stiffness`` (optional) is ``(edges [E, 2], values [E])``: per template edge (vertex
    pairs, either order) a factor on its weight, e.g. the bending stiffness learned from a
    first tracking (:func:`fourd.deform.learn_material`); edges not listed keep theirs."""
    rest = np.asarray(rest_vertices, dtype=np.float64)
    Wc = cotangent_weights(rest, faces, clamp_negative=True).tocsr()
    if edge_stiffness is not None:
        Wc = _scaled_weights(Wc, *edge_stiffness)
    Wc.sort_indices()
    W = Wc.tocoo()
    n = len(rest)
    incidence = sp.csr_matrix((np.ones(W.nnz), (W.row, np.arange(W.nnz))), shape=(n, W.nnz))
    laplacian = weights_laplacian(W)
    rest_edges = np.ascontiguousarray(rest[W.row] - rest[W.col])
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    edge_length = median_edge_length(rest, faces) if len(faces) else 1.0
    order = elimination_order(laplacian)
    ordered = laplacian[order][:, order].tocsr()
    ordered.sort_indices()
    return SlidePrecompute(
        rest,
        W.row.astype(np.int64),
        W.col.astype(np.int64),
        W.data.astype(np.float64),
        incidence,
        laplacian,
        rest_edges,
        edge_length,
        Wc.indptr.astype(np.int64),
        order,
        ordered,
    )


def _scaled_weights(weights: sp.csr_matrix, edges: np.ndarray, values: np.ndarray) -> sp.csr_matrix:
    """``weights`` [N, N] with the entries of ``edges`` [E, 2] (both directions) times ``values``."""
    n = weights.shape[0]
    coo = weights.tocoo()
    edges = np.sort(np.asarray(edges, dtype=np.int64).reshape(-1, 2), axis=1)
    keys = edges[:, 0] * n + edges[:, 1]
    order = np.argsort(keys)
    keys, values = keys[order], np.asarray(values, dtype=np.float64)[order]
    entry = np.minimum(coo.row, coo.col).astype(np.int64) * n + np.maximum(coo.row, coo.col)
    position = np.minimum(np.searchsorted(keys, entry), max(len(keys) - 1, 0))
    found = (keys[position] == entry) if len(keys) else np.zeros(len(entry), bool)
    factor = np.where(found, values[position] if len(keys) else 1.0, 1.0)
    return sp.csr_matrix((coo.data * factor, (coo.row, coo.col)), shape=weights.shape)


def _tangent_bases(normals: np.ndarray) -> np.ndarray:
    """Orthonormal [M, 3, 2] bases of the planes orthogonal to unit ``normals`` [M, 3]."""
    helper = np.zeros_like(normals)
    smallest = np.argmin(np.abs(normals), axis=1)
    helper[np.arange(len(normals)), smallest] = 1.0
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    return np.stack([t1, t2], axis=2)


@numba.njit(cache=True)
def _reduced_matrix(indptr, indices, data, dims, bases, mu):
    """CSR of ``K = B^T (L (x) I_3 + diag(mu)) B`` over the reduced unknowns: vertex ``v``
    has ``dims[v]`` unknowns (the first columns of ``bases[v]`` [3, 3], orthonormal), block
    ``(v, w)`` is ``L_vw T_v^T T_w`` (+ ``mu_v I`` on the diagonal). Vertices in the order of
    ``L`` (CSR ``indptr, indices, data`` with sorted indices), so the columns come sorted."""
    n = len(dims)
    start = np.zeros(n + 1, dtype=np.int64)
    for v in range(n):
        start[v + 1] = start[v] + dims[v]
    row_ptr = np.zeros(start[n] + 1, dtype=np.int64)
    for v in range(n):
        width = 0
        for e in range(indptr[v], indptr[v + 1]):
            width += dims[indices[e]]
        for a in range(dims[v]):
            row_ptr[start[v] + a + 1] = width
    for r in range(start[n]):
        row_ptr[r + 1] += row_ptr[r]
    cols = np.empty(row_ptr[-1], dtype=np.int32)
    vals = np.empty(row_ptr[-1])
    for v in range(n):
        for a in range(dims[v]):
            k = row_ptr[start[v] + a]
            for e in range(indptr[v], indptr[v + 1]):
                w = indices[e]
                lw = data[e]
                for b in range(dims[w]):
                    dot = (
                        bases[v, 0, a] * bases[w, 0, b]
                        + bases[v, 1, a] * bases[w, 1, b]
                        + bases[v, 2, a] * bases[w, 2, b]
                    )
                    value = lw * dot
                    if w == v and a == b:
                        value += mu[v]
                    cols[k] = start[w] + b
                    vals[k] = value
                    k += 1
    return row_ptr, cols, vals


class ConstrainedSolver:
    """System (5) for one time step: factorised once, solved per iteration by back-substitution.

    Parameters
    ----------
    pre : SlidePrecompute
    normals : ndarray [N, 3]
        Spatial part of ``grad f`` at the vertices at time ``t``.
    offsets : ndarray [N]
        Right sides ``c_i`` of the constraints ``normals_i . p_i = c_i``.
    constrained : ndarray bool [N]
        False where lambda_i = 0 (5.4).
    regularization : float
    pull : ndarray [N], optional
        An extra weight per vertex (times its Laplacian diagonal) towards the ``reference`` of
        :meth:`solve`: the anchor-guided positions (:mod:`fourd.appearance.guide`).

    The reduced matrix ``B^T (L (x) I_3) B`` is assembled directly in the template's
    elimination order (:func:`elimination_order`) and factorised without pivoting (it is
    symmetric positive definite).
    """

    def __init__(self, pre, normals, offsets, constrained, regularization, pull=None):
        n = len(pre.rest)
        norm = np.linalg.norm(normals, axis=1)
        constrained = constrained & (norm > 1e-12)
        unit = normals / np.maximum(norm, 1e-300)[:, None]
        self.anchor = np.zeros((n, 3))
        self.anchor[constrained] = (offsets[constrained] / norm[constrained])[:, None] * unit[
            constrained
        ]
        # per vertex an orthonormal basis whose first dims columns span its unknowns: the
        # constraint plane (2 columns) or all of space (3)
        self.bases = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        self.bases[constrained, :, :2] = _tangent_bases(unit[constrained])
        self.dims = np.where(constrained, 2, 3)
        diag = pre.laplacian.diagonal()
        self.mu_vertex = regularization * np.where(diag > 0, diag, max(diag.mean(), 1e-12))
        if pull is not None:  # extra pull towards the reference, in units of each vertex's stiffness
            self.mu_vertex = self.mu_vertex + np.asarray(pull, dtype=np.float64) * np.where(
                diag > 0, diag, max(diag.mean(), 1e-12)
            )
        self.mu = np.repeat(self.mu_vertex, 3)
        self.laplacian = pre.laplacian
        self.order = pre.order
        L = pre.ordered_laplacian
        dims = self.dims[self.order]
        row_ptr, cols, vals = _reduced_matrix(
            L.indptr.astype(np.int64),
            L.indices.astype(np.int64),
            L.data,
            dims,
            np.ascontiguousarray(self.bases[self.order]),
            self.mu_vertex[self.order],
        )
        size = len(row_ptr) - 1
        # symmetric: its CSR arrays are its CSC arrays
        K = sp.csc_matrix((vals, cols, row_ptr), shape=(size, size))
        self.factor = spla.splu(
            K, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
        self._unknown = np.arange(3)[None, :] < dims[:, None]  # [N, 3] in elimination order
        self.constrained = constrained
        self._La = pre.laplacian @ self.anchor + self.mu_vertex[:, None] * self.anchor

    @property
    def L3(self) -> sp.csr_matrix:
        """``L (x) I_3 + diag(mu)`` [3N, 3N] (the full system's stiffness; for checks)."""
        return sp.kron(self.laplacian, sp.identity(3), format="csr") + sp.diags(self.mu)

    def solve(self, rhs: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """Positions [N, 3] minimising ``P^T L P - 2 rhs.P`` (+ Tikhonov towards ``reference``)
        under the constraints."""
        r = rhs + self.mu_vertex[:, None] * reference - self._La
        reduced = np.einsum("nab,na->nb", self.bases, r)[self.order][self._unknown]
        u = np.zeros((len(r), 3))
        u[self._unknown] = self.factor.solve(reduced)
        moved = np.empty_like(u)
        moved[self.order] = u
        return self.anchor + np.einsum("nab,nb->na", self.bases, moved)
