"""The as-rigid-as-possible local step and energy over a template (Sorkine & Alexa, SGP 2007):
per-vertex best rotations of the cotangent-weighted edge covariances, the right side of the
global step, and the normalised energy. ``pre`` is a
:class:`fourd.methods.kinematic.arap_solve.SlidePrecompute` of the template; the sliding (5.2,
5.3) and the large-motion registration share these."""

from __future__ import annotations

import numba
import numpy as np

from fourd.geometry.rotations import best_rotations


@numba.njit(cache=True, parallel=True)
def _covariances(indptr, edge_j, edge_w, rest_edges, vertices, out):
    for i in numba.prange(len(indptr) - 1):
        # scalar accumulators: a 3x3 array allocated per vertex costs more than the sums
        s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = edge_j[e]
            w = edge_w[e]
            r0, r1, r2 = w * rest_edges[e, 0], w * rest_edges[e, 1], w * rest_edges[e, 2]
            d0 = vertices[i, 0] - vertices[j, 0]
            d1 = vertices[i, 1] - vertices[j, 1]
            d2 = vertices[i, 2] - vertices[j, 2]
            s00 += r0 * d0
            s01 += r0 * d1
            s02 += r0 * d2
            s10 += r1 * d0
            s11 += r1 * d1
            s12 += r1 * d2
            s20 += r2 * d0
            s21 += r2 * d1
            s22 += r2 * d2
        o = out[i]
        o[0, 0], o[0, 1], o[0, 2] = s00, s01, s02
        o[1, 0], o[1, 1], o[1, 2] = s10, s11, s12
        o[2, 0], o[2, 1], o[2, 2] = s20, s21, s22


@numba.njit(cache=True, parallel=True)
def _rhs(indptr, edge_j, edge_w, rest_edges, rotations, out):
    for i in numba.prange(len(indptr) - 1):
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = edge_j[e]
            h = 0.5 * edge_w[e]
            e0 = rest_edges[e, 0]
            e1 = rest_edges[e, 1]
            e2 = rest_edges[e, 2]
            b0 += h * (
                (rotations[i, 0, 0] + rotations[j, 0, 0]) * e0
                + (rotations[i, 0, 1] + rotations[j, 0, 1]) * e1
                + (rotations[i, 0, 2] + rotations[j, 0, 2]) * e2
            )
            b1 += h * (
                (rotations[i, 1, 0] + rotations[j, 1, 0]) * e0
                + (rotations[i, 1, 1] + rotations[j, 1, 1]) * e1
                + (rotations[i, 1, 2] + rotations[j, 1, 2]) * e2
            )
            b2 += h * (
                (rotations[i, 2, 0] + rotations[j, 2, 0]) * e0
                + (rotations[i, 2, 1] + rotations[j, 2, 1]) * e1
                + (rotations[i, 2, 2] + rotations[j, 2, 2]) * e2
            )
        out[i, 0] = b0
        out[i, 1] = b1
        out[i, 2] = b2


def arap_rotations(pre, vertices: np.ndarray) -> np.ndarray:
    """Per-vertex best rotations [N, 3, 3] of the template's cells onto ``vertices`` (5.2)."""
    S = np.empty((len(pre.rest), 3, 3))
    _covariances(
        pre.indptr,
        pre.edge_j,
        pre.edge_w,
        pre.rest_edges,
        np.ascontiguousarray(vertices, dtype=np.float64),
        S,
    )
    return best_rotations(S)


def arap_rhs(pre, rotations: np.ndarray) -> np.ndarray:
    """Right side of (5): ``b_i = sum_j w_ij / 2 (R_i + R_j)(p0_i - p0_j)`` [N, 3]."""
    out = np.empty((len(pre.rest), 3))
    _rhs(pre.indptr, pre.edge_j, pre.edge_w, pre.rest_edges, np.ascontiguousarray(rotations), out)
    return out


def with_rest_shape(pre, positions: np.ndarray):
    """``pre`` with the edges of ``positions`` [N, 3] as its rest edges (the same cotangent
    weights): an ARAP reference remembered from another frame."""
    positions = np.asarray(positions, dtype=np.float64)
    edges = positions[pre.edge_i] - positions[pre.edge_j]
    return pre._replace(rest_edges=np.ascontiguousarray(edges))


def blended_arap_rhs(pre, vertices: np.ndarray, remembered=None, weight: float = 0.0) -> np.ndarray:
    """:func:`arap_rhs` at the best rotations onto ``vertices`` [N, 3] of ``(1 - weight)
    E_ARAP(rest) + weight E_ARAP(remembered)`` (``remembered`` from :func:`with_rest_shape`;
    None: the rest shape alone); [N, 3]."""
    rhs = arap_rhs(pre, arap_rotations(pre, vertices))
    if remembered is None or weight == 0:
        return rhs
    return (1.0 - weight) * rhs + weight * arap_rhs(remembered, arap_rotations(remembered, vertices))


def arap_energy(pre, vertices: np.ndarray) -> float:
    """ARAP energy (1) of ``vertices`` with optimal rotations, divided by the template's
    ``sum w_ij |p0_i - p0_j|^2`` (0 for a rigid motion of the template)."""
    R = arap_rotations(pre, vertices)
    edges = vertices[pre.edge_i] - vertices[pre.edge_j]
    residual = edges - np.einsum("eab,eb->ea", R[pre.edge_i], pre.rest_edges)
    energy = float(pre.edge_w @ np.einsum("ij,ij->i", residual, residual))
    scale = float(pre.edge_w @ np.einsum("ij,ij->i", pre.rest_edges, pre.rest_edges))
    return energy / max(scale, 1e-300)
