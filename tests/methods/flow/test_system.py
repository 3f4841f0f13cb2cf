"""The flow's constrained quadratic (continuity, momentum, regulariser, incompressibility)."""

from __future__ import annotations

import numpy as np
import pytest

from fourd.methods.flow import (
    solve_saddle,
)
from fourd.methods.flow.system import (
    build_system,
    enumerate_flows,
    neighbourhood,
    still_interior,
)


@pytest.mark.parametrize("still_depth", [0, 1])
def test_system_quadratic_is_the_energy(still_depth):
    """``u^T A u - 2 f^T u`` differs from the energy F of the system's docstring (continuity
    with the fixed cells substituted, momentum with missing partners as zero flows, the
    regulariser) by a constant, computed here term by term with Python loops; with a still
    interior, over every flow that is left, the deep cells' flows to themselves held at 1."""
    rng = np.random.default_rng(3)
    if still_depth:
        value = np.full((4, 9, 8, 8), np.nan)
        value[:, 2:7, 2:7, 2:7] = 1.0
        value[1:, 2, 2:7, 2:7] = np.nan  # the block's side moves: flows to a free layer
    else:
        value = np.full((4, 6, 5, 5), np.nan)
        value[:, 2:4, 2:3, 2:4] = 1.0
    value[:, [0, -1], :, :] = value[:, :, [0, -1], :] = value[:, :, :, [0, -1]] = 0.0
    dead = rng.random(value.shape) < 0.1
    value[dead & (np.isnan(value) if still_depth else True)] = 0.0
    weights = rng.random((3, *value.shape))
    alpha, reg = 1 / 3, 0.0025
    offsets = neighbourhood(7)
    system = build_system(value, weights, offsets, alpha=alpha, reg=reg, still_depth=still_depth)
    n_x = len(system.free)
    still = still_interior(value, still_depth) if still_depth else None
    flows = enumerate_flows(value != 0, offsets, still)
    pinned = np.zeros(len(flows.source), dtype=bool)
    if still is not None:
        pinned = ~offsets[flows.offset].any(axis=1) & (
            still[0].ravel()[flows.source] | still[1].ravel()[flows.target]
        )
        assert pinned.sum() >= 27
    assert np.array_equal(flows.source[~pinned], system.flows.source)
    index = {(int(a), int(k)): i for i, (a, k) in enumerate(zip(flows.source, flows.offset, strict=True))}
    S, shape = value.shape[0], value.shape
    strides = np.array([np.prod(shape[a + 1 :]) for a in range(4)])

    def energy(u):
        x = np.where(np.isnan(value), 0.0, value).ravel().copy()
        x[system.free] = u[:n_x]
        v = np.ones(len(flows.source))
        v[~pinned] = u[n_x:]
        total = reg * (u**2).sum()
        cells = x.reshape(shape)
        for axis in range(3):
            for cell in np.ndindex(*shape):
                other = list(cell)
                other[axis + 1] += 1
                if other[axis + 1] >= shape[axis + 1]:
                    continue
                if np.isnan(value[cell]) or np.isnan(value[tuple(other)]):
                    w = alpha * weights[(axis, *cell)]
                    total += w * (cells[cell] - cells[tuple(other)]) ** 2
        for i, (source, target, k) in enumerate(
            zip(flows.source, flows.target, flows.offset, strict=True)
        ):
            t = source // strides[0]
            if t < S - 2:
                after = index.get((int(target), int(k)))
                total += (1 - alpha) * (v[i] - (v[after] if after is not None else 0.0)) ** 2
            shift = strides[0] + offsets[k] @ strides[1:]
            if t >= 1 and (int(source - shift), int(k)) not in index:
                total += (1 - alpha) * v[i] ** 2
        return total

    def quadratic(u):
        return u @ (system.A @ u) - 2 * system.f @ u

    differences = [
        energy(u) - quadratic(u)
        for u in (np.zeros(system.A.shape[0]), *rng.standard_normal((2, system.A.shape[0])))
    ]
    assert len(flows.source) > 100 and n_x > 20
    assert np.allclose(differences, differences[0], rtol=0, atol=1e-9 * abs(energy(
        np.ones(system.A.shape[0]))))
    assert abs(system.A - system.A.T).max() == 0


def _block(moving: bool) -> np.ndarray:
    """Four slices of a 10 x 6 x 6 block fixed inside, moving one cell along +x per slice
    (or still), with its leading and trailing layers and a one-cell shell free."""
    value = np.zeros((4, 20, 14, 14))
    for s in range(4):
        x = s if moving else 0
        value[s, 2 + x : 14 + x, 2:12, 2:12] = np.nan
        value[s, 4 + x : 12 + x, 4:10, 4:10] = 1.0
        value[s, [4 + x, 11 + x], 4:10, 4:10] = np.nan
    return value


def _solved_values(value: np.ndarray, still_depth: int):
    system = build_system(
        value, np.ones((3, *value.shape)), neighbourhood(7), alpha=1 / 3, reg=0.0025,
        still_depth=still_depth,
    )
    solution = solve_saddle(
        system.A, system.B, system.f, system.g, inner="cg-amg", rtol=1e-6, inner_rtol=1e-2, softness=0.0,
        maxiter=500,
    )
    assert solution.converged and system.infeasible == 0
    x = np.where(np.isnan(value), 0.0, value).ravel()
    x[system.free] = solution.u[: len(system.free)]
    return system, x.reshape(value.shape)


def test_a_still_interior_keeps_only_the_stay_flows_of_deep_cells():
    """``still_interior``: deep inside cells keep only the flow to themselves. A block at
    rest comes out as with every flow (measured within 0.005, asserted within 0.01: the
    interior's flows no longer spread under the regulariser); one moving a cell per slice
    keeps its mass, and its free layers lag by up to 0.07 (the deep cells cannot carry it
    along)."""
    for moving, tolerance in ((False, 0.01), (True, 0.1)):
        value = _block(moving)
        every, x_every = _solved_values(value, 0)
        fewer, x_fewer = _solved_values(value, 1)
        assert len(fewer.flows.source) < len(every.flows.source)
        leaving, entering = still_interior(value, 1)
        assert leaving[:-1].sum() > 50 and entering[1:].sum() > 50
        moves = neighbourhood(7)[fewer.flows.offset].any(axis=1)
        assert not (leaving.ravel()[fewer.flows.source] & moves).any()
        assert not (entering.ravel()[fewer.flows.target] & moves).any()
        assert np.abs(x_fewer - x_every).max() < tolerance
        masses = x_fewer.reshape(4, -1).sum(axis=1)
        assert np.ptp(masses) < 1e-6 * masses.mean()
