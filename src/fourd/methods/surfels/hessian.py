"""The Gauss-Newton gradient ``2 J^T r`` and Hessian ``2 J^T J`` of eq. (3) from the data
term's and the priors' Jacobians, with the structure of the priors' part kept between the
assemblies of one optimisation.

The priors' Jacobians have fixed patterns on one topology and layout (:class:`~.term.Pattern`),
and the data term's rows each touch one surfel's position and normal offset in one frame
(:func:`~.match.match_term`), so the data's ``J^T J`` lies within those 5 x 5 blocks whatever
the association. With the blocks' entries (zeros where no datum is) added first, the
Hessian's structure is the same at every state: a :class:`HessianPlan` keeps it, with the
priors' stacked pattern and its transpose, and later assemblies compute values only (no
stacking of index arrays, no transposition, no count of the product's row lengths).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.sparse_products import csr_product, csr_transpose, multiply_add
from fourd.methods.surfels.state import Layout


@dataclass(frozen=True)
class HessianPlan:
    """The structure of one optimisation's Gauss-Newton Hessian (:func:`planned_derivatives`).

    patterns : tuple of Pattern
        The priors' Jacobian patterns it was made for, in stacking order (the same objects).
    stacked : tuple (indices, indptr, shape)
        The CSR structure of the priors' stacked Jacobian [R, k].
    transposed : tuple (indices, indptr, shape)
        That of its transpose [k, R]; ``order`` int [nnz]: the stacked values' index of each
        transposed entry.
    blocks : tuple (indices, indptr, shape)
        That of the data's 5 x 5 blocks on and above the diagonal [k, k] (:func:`data_blocks`).
    row_lengths : int [k] or None
        The Hessian's row lengths; None before the first product.
    """

    patterns: tuple
    stacked: tuple
    transposed: tuple
    order: np.ndarray
    blocks: tuple
    row_lengths: np.ndarray | None = None

    def fits(self, patterns: tuple) -> bool:
        """Whether the priors' Jacobians of ``patterns`` have this plan's structure."""
        return len(patterns) == len(self.patterns) and all(
            a is b for a, b in zip(patterns, self.patterns, strict=True)
        )


def data_blocks(lay: Layout, columns: np.ndarray | None = None) -> sp.csr_matrix:
    """The structure (values 0) of every surfel's 5 x 5 block in every frame, its position
    and normal offset's rows and columns, on and above the diagonal: [n, n] for the layout's
    ``n`` unknowns, or [k, k] for the unknowns ``columns`` (int [k], sorted) only."""
    cells = np.arange(lay.frames * lay.count, dtype=np.int64)
    position = 3 * cells
    normal = lay.normals_start + 2 * cells
    # the block's five unknowns, positions first (the layout puts them before the normals)
    unknowns = np.concatenate(
        [position[:, None] + np.arange(3), normal[:, None] + np.arange(2)], axis=1
    )
    first, second = np.triu_indices(5)
    rows = unknowns[:, first].ravel()
    cols = unknowns[:, second].ravel()
    size = lay.size
    if columns is not None:
        renumber = np.full(lay.size, -1, dtype=np.int64)
        renumber[np.asarray(columns, dtype=np.int64)] = np.arange(len(columns))
        rows, cols = renumber[rows], renumber[cols]
        kept = (rows >= 0) & (cols >= 0)
        rows, cols, size = rows[kept], cols[kept], len(columns)
    blocks = sp.csr_matrix((np.zeros(len(rows)), (rows, cols)), shape=(size, size))
    blocks.sort_indices()
    return blocks


def planned_derivatives(
    data_jacobian: sp.csr_matrix,
    data_residuals: np.ndarray,
    prior_jacobians: list[sp.csr_matrix],
    prior_residuals: np.ndarray,
    patterns: tuple,
    plan: HessianPlan | None,
    lay: Layout,
    columns: np.ndarray | None = None,
) -> tuple[np.ndarray, sp.csr_matrix, HessianPlan]:
    """The gradient ``2 J^T r`` [k] and the Hessian ``2 J^T J`` [k, k] (on and above the
    diagonal) of the data term's ``data_jacobian`` [D, k] and the priors' ``prior_jacobians``
    (each [R_i, k], from ``patterns``, stacked in that order), with their residuals [D] and
    [sum R_i]; and the plan that gives the next assembly its structure. ``plan``: that of an
    earlier assembly (used if it :meth:`~HessianPlan.fits` ``patterns``); else one is made
    for the unknowns ``columns`` (int [k], sorted; None: all) of ``lay``.
    ``prior_jacobians`` is emptied once its values are read (so that a caller that passes
    the last references lets them go before the product)."""
    if plan is None or not plan.fits(patterns):
        blocks = data_blocks(lay, columns)
        stacked = sp.vstack(prior_jacobians, format="csr")
        # the transposition carries each entry's number: its values later come by a gather
        # (32-bit numbers where they fit: a fresh 64-bit array of crane's 27 million took 19 ms)
        number = np.int32 if stacked.nnz < np.iinfo(np.int32).max else np.int64
        numbers = sp.csr_matrix(
            (np.arange(stacked.nnz, dtype=number), stacked.indices, stacked.indptr),
            shape=stacked.shape,
        )
        transposed = csr_transpose(numbers)
        plan = HessianPlan(
            tuple(patterns), _structure(stacked), _structure(transposed), transposed.data,
            _structure(blocks),
        )
        del stacked, numbers, transposed
    data_transposed = csr_transpose(data_jacobian)
    data_hessian = csr_product(data_transposed, data_jacobian, upper=True)
    block_indices, block_indptr, _ = plan.blocks
    block_values = np.zeros(len(block_indices))
    if not _into_blocks(
        data_hessian.indptr, data_hessian.indices, data_hessian.data,
        block_indptr, block_indices, block_values,
    ):
        raise ValueError("a data row leaves its surfel's position and normal offset")
    del data_hessian
    values = np.concatenate([j.data for j in prior_jacobians])
    prior_jacobians.clear()
    stacked = _matrix(plan.stacked, values)
    transposed = _matrix(plan.transposed, _gather(values, plan.order))
    del values
    hessian = csr_product(
        transposed, stacked, add=_matrix(plan.blocks, block_values), upper=True,
        row_lengths=plan.row_lengths,
    )
    hessian.data *= 2.0
    # on all cores, each entry summed in scipy's order
    gradient = np.zeros(transposed.shape[0])
    multiply_add(transposed, prior_residuals, gradient)
    multiply_add(data_transposed, data_residuals, gradient)
    gradient *= 2.0
    if plan.row_lengths is None:
        plan = replace(plan, row_lengths=np.diff(hessian.indptr))
    return gradient, hessian, plan


def _structure(matrix: sp.csr_matrix) -> tuple:
    """A CSR matrix's (indices, indptr, shape), without its values."""
    return matrix.indices, matrix.indptr, matrix.shape


def _matrix(structure: tuple, values: np.ndarray) -> sp.csr_matrix:
    """The CSR matrix of ``structure`` (:func:`_structure`; its arrays shared, never
    written) and ``values`` [nnz]."""
    indices, indptr, shape = structure
    matrix = sp.csr_matrix((values, indices, indptr), shape=shape, copy=False)
    matrix.has_sorted_indices = True
    return matrix


@numba.njit(cache=True, parallel=True, nogil=True)
def _gather(values: np.ndarray, order: np.ndarray) -> np.ndarray:
    """``values[order]`` on all cores (numpy's take runs on one)."""
    out = np.empty(len(order))
    for k in numba.prange(len(order)):
        out[k] = values[order[k]]
    return out


@numba.njit(cache=True, nogil=True)
def _into_blocks(indptr, indices, data, b_indptr, b_indices, b_data) -> bool:
    """Add every entry of a CSR matrix into the CSR ``b`` (``b_indptr``, ``b_indices``,
    values ``b_data``) of the same shape at the same row and column; False (and ``b_data``
    partly written) when ``b`` has no such entry."""
    for row in range(len(indptr) - 1):
        for k in range(indptr[row], indptr[row + 1]):
            column = indices[k]
            found = False
            for s in range(b_indptr[row], b_indptr[row + 1]):
                if b_indices[s] == column:
                    b_data[s] += data[k]
                    found = True
                    break
            if not found:
                return False
    return True
