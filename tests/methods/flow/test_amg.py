"""AMG hierarchies and the V-cycle of the flow's inner solve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from fourd.methods.flow import (
    solve_saddle,
)
from fourd.methods.flow.amg import (
    amg_hierarchy,
    normal_finest,
    v_cycle,
)
from fourd.methods.flow.sparse import (
    drop_weak_entries,
)
from fourd.methods.flow.system import (
    build_system,
    neighbourhood,
)


def test_dropping_weak_coarse_entries_lumps_them_and_keeps_the_matrix_definite():
    """Non-Galerkin coarse matrices: each dropped entry goes to its row's diagonal, so the
    result dominates the original (smallest eigenvalue not lower), and the V-cycle built
    with them still preconditions MINRES to the residual of the Galerkin one."""
    rng = np.random.default_rng(5)
    factor = sp.random(150, 150, density=0.05, random_state=6, format="csr")
    matrix = (factor @ factor.T + 0.1 * sp.identity(150)).tocsr()
    dropped = drop_weak_entries(matrix, 0.1)
    dense, diagonal = matrix.toarray(), matrix.diagonal()
    weak = (np.abs(dense) < 0.1 * np.sqrt(np.outer(diagonal, diagonal))) & (dense != 0)
    weak &= ~np.eye(150, dtype=bool)
    expected = np.where(weak, 0.0, dense)
    expected[np.diag_indices(150)] += np.abs(np.where(weak, dense, 0.0)).sum(axis=1)
    assert weak.any() and dropped.nnz == matrix.nnz - weak.sum()
    assert np.abs(dropped.toarray() - expected).max() < 1e-12
    assert np.linalg.eigvalsh(expected).min() >= np.linalg.eigvalsh(dense).min() - 1e-12
    with pytest.raises(ValueError, match="no diagonal"):
        drop_weak_entries(sp.csr_matrix(np.array([[0.0, 1.0], [1.0, 2.0]])), 0.1)
    value = np.full((3, 12, 12, 12), np.nan)
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    value[:, 5:7, 5:7, 5:7] = 1.0
    system = build_system(
        value, 0.5 + rng.random((3, *value.shape)), neighbourhood(7), alpha=1 / 3, reg=0.0025
    )
    settings = dict(inner="amg", rtol=1e-3, softness=1e-3, maxiter=40)
    galerkin = solve_saddle(system.A, system.B, system.f, system.g, **settings)
    sparser = solve_saddle(system.A, system.B, system.f, system.g, coarse_drop=0.05, **settings)
    assert sparser.residual <= 2 * galerkin.residual and sparser.residual < 1e-2


def test_amg_hierarchy_is_pyamgs_and_a_symmetric_v_cycle():
    """The V-cycle hierarchy equals pyamg's Ruge-Stueben one (direct interpolation) up to
    rounding, and its V-cycle is a symmetric operator (MINRES needs an SPD preconditioner)."""
    import pyamg

    value = np.full((3, 12, 12, 12), np.nan)
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    value[:, 5:7, 5:7, 5:7] = 1.0
    system = build_system(value, np.ones((3, *value.shape)), neighbourhood(7), alpha=1 / 3,
                          reg=0.0025)
    S = (system.A + system.B.T @ system.B).tocsr()
    mine = amg_hierarchy(S, max_coarse=50)
    theirs = pyamg.ruge_stuben_solver(S, max_coarse=50, interpolation="direct")
    assert len(mine.levels) == len(theirs.levels) >= 3
    for ours, reference in zip(mine.levels, theirs.levels, strict=True):
        assert ours.A.shape == reference.A.shape
        assert abs(ours.A - reference.A).max() <= 1e-9 * abs(reference.A).max()
    cycle = mine.aspreconditioner(cycle="V")
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal((2, S.shape[0]))
    assert np.allclose(v_cycle(mine, x), cycle.matvec(x), rtol=0, atol=1e-12 * abs(x).max())
    assert abs(x @ cycle.matvec(y) - y @ cycle.matvec(x)) <= 1e-9 * abs(x @ cycle.matvec(x))
    assert x @ cycle.matvec(x) > 0
    # the finest level swept through A and B^T (without S) takes the same steps
    finest = normal_finest(system.A, system.B.T)
    assert np.allclose(finest.diagonal, S.diagonal(), rtol=1e-12)
    expected = cycle.matvec(x)
    mine.levels[0].A = None
    assert np.allclose(v_cycle(mine, x, finest), expected, rtol=0, atol=1e-10 * abs(x).max())
