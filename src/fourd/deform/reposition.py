"""Vertex positions that follow per-triangle transformations (thesis ``004_f87f5acf96d50b57.txt``,
section 2.4.3, equations 2.3-2.4; section 2.5 for positional constraints).

``min sum_i psi_i |V~_i V_i^-1 - T_i|_F^2`` over the new vertex positions and the new fourth
points ``v4`` of the triangles (Sumner and Popović 2004 keep them as unknowns too): a sparse
linear least-squares problem ``|Psi (A x - t)|^2`` (each fourth point appears only in its own
triangle's rows, so it is eliminated from the normal equations exactly: static condensation)
whose matrix depends only on the rest mesh,
the shearing stiffness and which vertices are constrained. Its normal equations are factorised
once (:class:`Repositioning`) and each new set of transformations costs a right-hand side and
two triangular solves. Fixed vertices (a region of influence's boundary, or the one vertex that
removes the free translation) are eliminated; dragged vertices (positional constraints, 2.5)
are soft rows of weight ``handle_weight``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fourd.deform.frames import local_frames
from fourd.errors import InputError
from fourd.geometry.factors import (
    TriangularFactors,
    elimination_order,
    solve_ordered,
    unpermuted_factors,
)

__all__ = ["Repositioning"]


class Repositioning:
    """The factorised least-squares problem of equation 2.4 for one rest mesh.

    Parameters
    ----------
    rest : float64 [N, 3]
    faces : int [F, 3]
    shearing : float64 [F]
        Shearing stiffness per face (``psi``).
    fixed : int [M]
        Vertices held at given positions (eliminated).
    handles : int [H]
        Vertices pulled towards given positions (soft rows).
    handle_weight : float
        Weight of a handle's row against a face's (relative to the mean shearing stiffness and
        the squared mean edge length, so it does not depend on the mesh's units).
    """

    def __init__(self, rest, faces, shearing, fixed=(), handles=(), handle_weight: float = 100.0):
        rest = np.asarray(rest, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        self.vertex_count, self.face_count = len(rest), len(faces)
        self.fixed = np.asarray(fixed, dtype=np.int64).ravel()
        self.handles = np.asarray(handles, dtype=np.int64).ravel()
        if len(self.fixed) == 0 and len(self.handles) == 0:
            raise InputError("fix or drag at least one vertex: positions are free to translate otherwise")
        inverse = np.linalg.inv(local_frames(rest, faces))  # [F, 3, 3]
        n, f = self.vertex_count, self.face_count
        rows = (3 * np.arange(f)[:, None] + np.arange(3)[None, :])  # [F, 3]: row of (face, j)
        # (V~ V^-1)[:, j] = sum_c (v4 - v_c) inverse[c, j]
        cols = np.concatenate([np.repeat(faces[:, :, None], 3, axis=2),
                               np.broadcast_to((n + np.arange(f))[:, None, None], (f, 1, 3))], axis=1)
        values = np.concatenate([-inverse, inverse.sum(axis=1, keepdims=True)], axis=1)  # [F, 4, 3]
        row_index = np.broadcast_to(rows[:, None, :], (f, 4, 3))
        weight = np.sqrt(np.asarray(shearing, dtype=np.float64))
        values = values * weight[:, None, None]
        self.matrix = sp.csr_matrix(
            (values.ravel(), (row_index.ravel(), cols.ravel())), shape=(3 * f, n + f)
        )
        self.row_weight = np.repeat(weight, 3)
        normal = (self.matrix.T @ self.matrix).tocsr()
        # each fourth point appears only in its own triangle's rows: eliminate them (static
        # condensation), leaving a system over the vertices with the mesh's own sparsity
        self.to_fourth = normal[:n, n:]
        self.fourth_inverse = 1.0 / normal[n:, n:].diagonal()
        condensed = (normal[:n, :n] - self.to_fourth @ sp.diags(self.fourth_inverse) @ self.to_fourth.T).tocsr()
        unknown = np.ones(n, dtype=bool)
        unknown[self.fixed] = False
        self.unknown = np.flatnonzero(unknown)
        self.coupling = condensed[self.unknown][:, self.fixed]
        system = condensed[self.unknown][:, self.unknown]
        edges = rest[faces[:, [1, 2, 0]]] - rest[faces]
        scale = float(np.mean(np.asarray(shearing))) / max(float(np.mean(np.linalg.norm(edges, axis=2))) ** 2, 1e-300)
        self.handle_weight = handle_weight * scale
        position = np.full(n, -1)
        position[self.unknown] = np.arange(len(self.unknown))
        self.handle_rows = position[self.handles]
        if np.any(self.handle_rows < 0):
            raise InputError("a vertex cannot be both fixed and dragged")
        if len(self.handles):
            system = system + sp.csr_matrix(
                (np.full(len(self.handles), self.handle_weight), (self.handle_rows, self.handle_rows)),
                shape=system.shape,
            )
        # nested-dissection order, then no pivoting (the matrix is symmetric positive definite)
        # and back-substitution of the three coordinates at once (fourd.geometry.factors)
        self.order = elimination_order(system)
        ordered = system.tocsr()[self.order][:, self.order].tocsc()
        lu = spla.splu(ordered, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        self.factor = unpermuted_factors(lu) or lu

    def solve(self, transforms, fixed_positions=None, handle_positions=None) -> np.ndarray:
        """Vertex positions [N, 3] for per-triangle transformations ``transforms`` [F, 3, 3],
        the fixed vertices at ``fixed_positions`` [M, 3] and the handles pulled towards
        ``handle_positions`` [H, 3]."""
        transforms = np.asarray(transforms, dtype=np.float64)
        target = (transforms.transpose(0, 2, 1).reshape(-1, 3)) * self.row_weight[:, None]
        rhs = self.matrix.T @ target
        n = self.vertex_count
        rhs = rhs[:n] - self.to_fourth @ (rhs[n:] * self.fourth_inverse[:, None])
        x = np.zeros((n, 3))
        if len(self.fixed):
            x[self.fixed] = np.asarray(fixed_positions, dtype=np.float64).reshape(-1, 3)
            rhs_u = rhs[self.unknown] - self.coupling @ x[self.fixed]
        else:
            rhs_u = rhs[self.unknown]
        if len(self.handles):
            rhs_u[self.handle_rows] += self.handle_weight * np.asarray(handle_positions, dtype=np.float64).reshape(-1, 3)
        rhs_u = np.asarray(rhs_u)
        if isinstance(self.factor, TriangularFactors):
            x[self.unknown] = solve_ordered(self.factor, rhs_u, self.order)
        else:
            solved = np.empty_like(rhs_u)
            solved[self.order] = self.factor.solve(np.ascontiguousarray(rhs_u[self.order]))
            x[self.unknown] = solved
        return x
