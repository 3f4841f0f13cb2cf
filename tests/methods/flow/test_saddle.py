"""The flow's saddle solve: MINRES with the block-diagonal preconditioner."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from flow_scenes import (
    _saddle_matrix,
)
from scipy.sparse.linalg import spsolve

from fourd.methods.flow import (
    solve_saddle,
)
from fourd.methods.flow.amg import (
    restrict_interpolations,
)
from fourd.methods.flow.irls import _previous_unknowns
from fourd.methods.flow.saddle import _saddle_apply
from fourd.methods.flow.system import (
    build_system,
    neighbourhood,
)


def test_minres_block_preconditioner_converges():
    """A small flow system: MINRES with diag(A + B^T B, I) converges in < 100 iterations and
    the true residual of the full saddle-point system is small."""
    value = np.full((3, 10, 10, 10), np.nan)
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    value[:, 4:6, 4:6, 4:6] = 1.0
    value[1, 2, 2, 2] = 1.0
    weights = np.ones((3, *value.shape))
    system = build_system(value, weights, neighbourhood(7), alpha=1 / 3, reg=0.0025)
    assert system.A.shape[0] > 1000 and system.B.shape[0] > 500
    solution = solve_saddle(
        system.A, system.B, system.f, system.g, inner="cg-amg", rtol=1e-5, softness=0.0
    )
    assert solution.converged
    assert solution.iterations < 100
    K = _saddle_matrix(system.A, system.B)
    b = np.concatenate([system.f, system.g])
    z = np.concatenate([solution.u, solution.multipliers])
    assert np.linalg.norm(b - K @ z) / np.linalg.norm(b) <= 1e-5
    # constraints hold: material in = material out
    assert np.linalg.norm(system.B @ solution.u - system.g) <= 1e-3 * np.linalg.norm(system.g)


def test_minres_reusing_an_earlier_interpolation_solves_the_smaller_system():
    """IRLS decides cells between solves; the next V-cycle keeps the previous interpolation,
    restricted to the unknowns still free. MINRES (the method's inexact settings) then
    reaches the residual of a new AMG set-up, and the cell values of a direct solve."""
    value = np.full((3, 12, 12, 12), np.nan)
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    value[:, 5:7, 5:7, 5:7] = 1.0
    weights = np.ones((3, *value.shape))
    settings = {"inner": "amg", "rtol": 1e-3, "softness": 1e-3, "maxiter": 100}
    first = build_system(value, weights, neighbourhood(7), alpha=1 / 3, reg=0.0025)
    earlier = solve_saddle(first.A, first.B, first.f, first.g, **settings)
    assert len(earlier.interpolations) >= 1
    value[:, 1:3, :, :] = 0.0  # decided: outside
    value[:, 4:8, 4:8, 4:8] = 1.0  # decided: inside
    second = build_system(value, weights, neighbourhood(7), alpha=1 / 3, reg=0.0025)
    rows = _previous_unknowns(second, first.free, first.flows)
    assert rows is not None and len(rows) == second.A.shape[0] < first.A.shape[0]
    fresh = solve_saddle(second.A, second.B, second.f, second.g, **settings)
    restricted = restrict_interpolations(earlier.interpolations, rows)
    assert restricted[0].shape[0] == len(rows)
    for finer, coarser in zip(restricted[:-1], restricted[1:], strict=True):
        assert finer.shape[1] == coarser.shape[0]
    reused = solve_saddle(
        second.A, second.B, second.f, second.g, reuse=restricted, **settings
    )
    assert reused.residual <= 1.5 * fresh.residual and reused.residual < 5e-3
    K = _saddle_matrix(second.A, second.B, 1e-3).tocsc()
    exact = spsolve(K, np.concatenate([second.f, second.g]))
    cells = len(second.free)
    for solution in (fresh, reused):
        assert np.abs(solution.u[:cells] - exact[:cells]).max() < 0.03
    # with the earlier coarse matrices too (restricted, no Galerkin products): still an SPD
    # preconditioner, and on a system this close to the earlier one as good
    interpolations, coarse = restrict_interpolations(
        earlier.interpolations, rows, earlier.coarse_matrices
    )
    assert len(coarse) == len(interpolations)
    # consuming the earlier hierarchy (IRLS's way: lists emptied, coarse matrices compacted
    # in place) gives the same operators
    earlier_lists = [P.copy() for P in earlier.interpolations], [
        matrix.copy() for matrix in earlier.coarse_matrices
    ]
    consumed = restrict_interpolations(earlier_lists[0], rows, earlier_lists[1], consume=True)
    assert all(entry is None for entry in earlier_lists[0][: len(interpolations)])
    for kept, again in zip((*interpolations, *coarse), (*consumed[0], *consumed[1]), strict=True):
        assert abs(kept - again).max() == 0
    for P, matrix in zip(interpolations, coarse, strict=True):
        assert matrix.shape == (P.shape[1], P.shape[1])
        assert abs(matrix - matrix.T).max() <= 1e-6 * abs(matrix).max()
    frozen = solve_saddle(
        second.A, second.B, second.f, second.g, reuse=interpolations, reuse_coarse=coarse,
        **settings,
    )
    assert frozen.residual <= 1.5 * fresh.residual and frozen.residual < 5e-3
    assert np.abs(frozen.u[:cells] - exact[:cells]).max() < 0.03
    # a system with an unknown the earlier one did not have cannot reuse it
    assert _previous_unknowns(first, second.free, second.flows) is None


def test_saddle_solve_releases_its_hierarchy_without_the_garbage_collector(monkeypatch):
    """The V-cycle's AMG hierarchy (about a gigabyte at resolution 64) is freed as soon as
    the solve returns, not whenever the cyclic garbage collector next runs."""
    import gc
    import weakref

    import fourd.methods.flow.saddle as saddle  # solve_saddle looks amg_hierarchy up there

    value = np.full((3, 12, 12, 12), np.nan)
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    value[:, 5:7, 5:7, 5:7] = 1.0
    system = build_system(value, np.ones((3, *value.shape)), neighbourhood(7), alpha=1 / 3,
                          reg=0.0025)
    built = []
    original = saddle.amg_hierarchy

    def recording(*args, **kwargs):
        ml = original(*args, **kwargs)
        built.append(weakref.ref(ml))
        return ml

    monkeypatch.setattr(saddle, "amg_hierarchy", recording)
    gc.disable()
    try:
        solution = solve_saddle(system.A, system.B, system.f, system.g, inner="amg", maxiter=20)
        assert len(built) == 1 and solution.iterations > 0
        assert built[0]() is None
    finally:
        gc.enable()


def test_saddle_apply_matches_the_assembled_matrix():
    a = sp.random(40, 30, density=0.1, random_state=0, format="csr")
    A = (a.T @ a + sp.identity(30)).tocsr()
    B = sp.random(12, 30, density=0.2, random_state=2, format="csr")
    z = np.random.default_rng(0).normal(size=42)
    for softness in (0.0, 1e-3):
        expected = _saddle_matrix(A, B, softness) @ z
        out = np.full(42, np.nan)
        assert _saddle_apply(A, B, B.T, softness, z, out) is out
        assert np.allclose(out, expected, atol=1e-12)


@pytest.mark.parametrize("inner", ["cg-amg", "amg"])  # "amg": a one-level hierarchy here
def test_saddle_solver_on_known_answer(inner):
    A = sp.diags([2.0, 2.0, 2.0, 2.0]).tocsr()
    B = sp.csr_matrix(np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]]))
    s = solve_saddle(A, B, np.zeros(4), np.array([2.0, 4.0]), inner=inner, rtol=1e-8)
    assert np.allclose(s.u, [1, 1, 2, 2], atol=1e-6)
