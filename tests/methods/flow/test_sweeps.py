"""The flow solver's parallel sweeps and products (:mod:`fourd.methods.flow.sweeps`)."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import scipy.sparse as sp

from fourd.methods.flow import sweeps
from fourd.methods.flow.amg import (
    amg_hierarchy,
    normal_finest,
    parallel_smoothers,
    v_cycle,
)
from fourd.methods.flow.irls import unknown_slices
from fourd.methods.flow.saddle import solve_saddle
from fourd.methods.flow.system import build_system, neighbourhood


def _flow_system(slices=12, size=10):
    value = np.full((slices, size, size, size), np.nan)
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    for t in range(slices):  # a block moving one cell every other slice
        shift = t // 2
        value[t, 2 + shift % 4 : 5 + shift % 4, 4:6, 4:6] = 1.0
    system = build_system(value, np.ones((3, *value.shape)), neighbourhood(7), alpha=1 / 3,
                          reg=0.0025)
    return system, unknown_slices(system, value.shape)


def _serial_sweep(S: sp.csr_matrix, x, rhs, rows):
    """Plain Gauss-Seidel in the row order ``rows`` (the reference)."""
    S = S.tocsr()
    diagonal = S.diagonal()
    for i in rows:
        start, end = S.indptr[i], S.indptr[i + 1]
        total = S.data[start:end] @ x[S.indices[start:end]] - diagonal[i] * x[i]
        if diagonal[i] != 0:
            x[i] = (rhs[i] - total) / diagonal[i]


def test_schedule_colours_blocks_that_share_no_entry():
    system, groups = _flow_system()
    S = (system.A + system.B.T @ system.B).tocsr()
    reach = sweeps.csr_reach(S, groups)
    assert reach == 1  # the finest level joins slices t and t + 1 only
    assert sweeps.normal_reach(system.A, system.B.T.tocsr(), groups) == reach
    order = sweeps.schedule(groups, reach, blocks=6)
    assert sorted(order.rows.tolist()) == list(range(S.shape[0]))
    assert len(order.block_starts) - 1 == 6  # of 2 slices each
    blocks = len(order.block_starts) - 1
    assert 0 < order.colour_start < blocks
    block_of = np.empty(S.shape[0], np.int64)
    for b in range(blocks):
        block_of[order.rows[order.block_starts[b] : order.block_starts[b + 1]]] = b
    colour_of = (block_of >= order.colour_start).astype(int)
    rows, columns = S.nonzero()
    joined = block_of[rows] != block_of[columns]
    # blocks joined by an entry always have different colours
    assert joined.any() and (colour_of[rows[joined]] != colour_of[columns[joined]]).all()
    # too few slices for two blocks of each colour: no schedule
    assert sweeps.schedule(np.zeros(10, np.int64), 1) is None
    assert sweeps.schedule(groups, 4) is None  # 12 slices: 3 blocks of 4


@pytest.mark.parametrize("threads", [1, 2])
def test_coloured_sweeps_are_gauss_seidel_in_their_order_on_any_core_count(threads):
    system, groups = _flow_system()
    S = (system.A + system.B.T @ system.B).tocsr()
    order = sweeps.schedule(groups, 1)
    assert len(order.block_starts) - 1 == sweeps.BLOCKS
    rng = np.random.default_rng(0)
    rhs = rng.standard_normal(S.shape[0])
    expected = rng.standard_normal(S.shape[0])
    start = expected.copy()
    _serial_sweep(S, expected, rhs, order.rows)
    _serial_sweep(S, expected, rhs, order.rows[::-1])
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        x = start.copy()
        sweeps.csr_sweep(S, x, rhs, order, forward=True)
        sweeps.csr_sweep(S, x, rhs, order, forward=False)
        # the same sweeps through A and B^T, keeping y = B x
        C = system.B.T.tocsr()
        finest = normal_finest(system.A, C, groups)
        assert finest.order is not None
        z, y = start.copy(), system.B @ start
        for forward in (True, False):
            sweeps.normal_sweep(finest.A, C, finest.diagonal, z, y, rhs, finest.order,
                                forward=forward)
    finally:
        numba.set_num_threads(previous)
    assert np.allclose(x, expected, rtol=0, atol=1e-10 * abs(expected).max())
    assert np.allclose(z, expected, rtol=0, atol=1e-10 * abs(expected).max())
    assert np.allclose(y, system.B @ z, rtol=0, atol=1e-10 * abs(y).max())


def test_products_match_scipy():
    rng = np.random.default_rng(1)
    P = sp.random(300, 40, density=0.1, random_state=2, format="csr", dtype=np.float32)
    x = rng.standard_normal(300)
    assert np.allclose(sweeps.transpose_multiply(P, x), P.T @ x, rtol=0, atol=1e-12 * 300)


def test_parallel_v_cycle_is_symmetric_and_the_solve_as_good():
    """With the unknowns' slices the V-cycle sweeps in coloured order on every level it can:
    still a symmetric positive definite preconditioner, and MINRES reaches the residual of
    the serial order."""
    system, groups = _flow_system(slices=16, size=12)
    S = (system.A + system.B.T @ system.B).tocsr()
    ml = amg_hierarchy(S.astype(np.float32), max_coarse=50)
    assert len(ml.levels) >= 3
    parallel_smoothers(ml, groups)
    assert isinstance(ml.levels[1].presmoother, type(ml.levels[1].postsmoother))
    ml.levels[0].A = None
    finest = normal_finest(system.A, system.B.T, groups, system.B)
    rng = np.random.default_rng(3)
    x, y = rng.standard_normal((2, S.shape[0]))
    Mx, My = v_cycle(ml, x, finest), v_cycle(ml, y, finest)
    assert abs(x @ My - y @ Mx) <= 1e-5 * abs(x @ Mx)
    assert x @ Mx > 0
    out = np.empty_like(x)
    assert v_cycle(ml, x, finest, out) is out and np.allclose(out, Mx, rtol=0, atol=1e-12)
    kwargs = dict(inner="amg", rtol=1e-6, maxiter=200, softness=1e-3)
    serial = solve_saddle(system.A, system.B, system.f, system.g, **kwargs)
    parallel = solve_saddle(system.A, system.B, system.f, system.g, groups=groups, **kwargs)
    # measured: 3.5e-6 and 5.1e-6 after 200 steps (1.8e-3 and 2.4e-3 after 60)
    assert parallel.residual <= max(2 * serial.residual, 1e-6)
    difference = np.linalg.norm(parallel.u - serial.u) / np.linalg.norm(serial.u)
    assert difference < 1e-3, difference
