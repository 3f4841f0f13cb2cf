"""The constrained quadratic of one IRLS iteration (paper 002, sections 3 and 4(b)).

Unknowns are the cell values ``x`` that are not yet decided and the flow variables ``v`` from
every living cell of slice ``t`` to the living cells of slice ``t + 1`` in its neighbourhood
(7 or 27 cells, Figure 2). Decided cells (data, labels, clamped values) are back-substituted;
flows into or out of a zero cell do not exist; with ``still_depth`` a deep interior's flows
to other cells do not exist either and its flows to themselves are constants 1
(:func:`still_interior`).

Energy (weights ``alpha``, ``1 - alpha`` and ``reg``)::

    F   = alpha F_c' + (1 - alpha) F_m + reg F_r
    F_c' = sum_t sum_{space faces (i, j)} w_ij (x_i - x_j)^2          (5)
    F_m  = sum (v_{i->j}^t - v_{j->j+(j-i)}^{t+1})^2                    (4)
    F_r  = sum x^2 + sum v^2

Constraints (incompressibility, (1) and (2))::

    x_c^t = sum_j v_{j->c}^{t-1}     (t > 0)
    x_c^t = sum_j v_{c->j}^{t}       (t < S - 1)

giving the saddle-point system ``[[A, B^T], [B, 0]] [u; lambda] = [f; g]`` of section 5
(``A`` is the Hessian of ``F`` / 2, so ``A u = f`` at the unconstrained optimum).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
from scipy import ndimage

from fourd.methods.flow.sparse import csr_from_entries


def neighbourhood(size: int) -> np.ndarray:
    """Offsets ``[K, 3]`` of the temporally adjacent cells: ``size`` 7 (faces) or 27 (all)."""
    if size == 7:
        return np.array(
            [[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
        )
    if size == 27:
        return np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)])
    raise ValueError(f"neighbourhood must be 7 or 27, got {size}")


class Flows(NamedTuple):
    """The flow variables of the current set of living cells.

    source, target : int64 [V], flat 4D cell indices (target is in the next slice).
    offset : int64 [V], index into the neighbourhood offsets.

    Ordered by offset, then source (:func:`flow_lookup` relies on it).
    """

    source: np.ndarray
    target: np.ndarray
    offset: np.ndarray


def still_interior(value: np.ndarray, depth: int) -> tuple[np.ndarray, np.ndarray]:
    """Where material stays in its cell: ``(leaving, entering)``, bool [S, X, Y, Z].

    A cell fixed inside (``value`` 1) whose neighbours within ``depth`` cells (3x3x3 steps,
    in its slice) are all fixed inside is deep. Material leaves a deep cell that is fixed
    inside in the next slice too only to itself (``leaving``), and enters a deep cell that was
    fixed inside in the previous slice only from itself (``entering``). Inside a solid every
    cell is full whatever the flows between its cells, and the stay flows kept leave every
    constraint feasible; but a deep interior that stays cannot carry a translating solid
    along, so its boundary layers lag (see the flow method's ``Options.still_interior``).
    """
    inside = value == 1
    deep = ndimage.binary_erosion(
        inside, structure=np.ones((1, 3, 3, 3), dtype=bool), iterations=max(depth, 1),
        border_value=0,
    )
    leaving = np.zeros_like(deep)
    leaving[:-1] = deep[:-1] & inside[1:]
    entering = np.zeros_like(deep)
    entering[1:] = deep[1:] & inside[:-1]
    return leaving, entering


def enumerate_flows(
    alive: np.ndarray,
    offsets: np.ndarray,
    still: tuple[np.ndarray, np.ndarray] | None = None,
) -> Flows:
    """All flows between living cells of consecutive slices (``alive`` [S, X, Y, Z] bool),
    but for the flows to another cell out of a ``leaving`` or into an ``entering`` cell of
    ``still = (leaving, entering)`` (:func:`still_interior`; None: all flows)."""
    S, X, Y, Z = alive.shape
    strides = np.array([X * Y * Z, Y * Z, Z, 1], dtype=np.int64)
    sources, targets, kinds = [], [], []
    for k, (dx, dy, dz) in enumerate(offsets):
        xs = slice(max(0, -dx), X - max(0, dx))
        ys = slice(max(0, -dy), Y - max(0, dy))
        zs = slice(max(0, -dz), Z - max(0, dz))
        xt = slice(xs.start + dx, xs.stop + dx)
        yt = slice(ys.start + dy, ys.stop + dy)
        zt = slice(zs.start + dz, zs.stop + dz)
        mask = np.zeros(alive.shape, dtype=bool)
        mask[:-1, xs, ys, zs] = alive[:-1, xs, ys, zs] & alive[1:, xt, yt, zt]
        if still is not None and (dx or dy or dz):
            mask[:-1, xs, ys, zs] &= ~still[0][:-1, xs, ys, zs]
            mask[:-1, xs, ys, zs] &= ~still[1][1:, xt, yt, zt]
        src = np.flatnonzero(mask)
        sources.append(src)
        targets.append(src + strides[0] + dx * strides[1] + dy * strides[2] + dz * strides[3])
        kinds.append(np.full(len(src), k, dtype=np.int64))
    return Flows(np.concatenate(sources), np.concatenate(targets), np.concatenate(kinds))


@numba.njit(cache=True)
def _first_disorder(offset, source):
    for i in range(1, len(source)):
        if offset[i] < offset[i - 1] or (offset[i] == offset[i - 1] and source[i] <= source[i - 1]):
            return i
    return -1


@numba.njit(cache=True, parallel=True)
def _lookup(source, starts, queries, query_offsets, out):
    for q in numba.prange(len(queries)):
        out[q] = -1
        k = query_offsets[q]
        if k < 0 or k >= len(starts) - 1:
            continue
        lo, hi = starts[k], starts[k + 1]
        wanted = queries[q]
        while lo < hi:
            middle = (lo + hi) // 2
            if source[middle] < wanted:
                lo = middle + 1
            else:
                hi = middle
        if lo < starts[k + 1] and source[lo] == wanted:
            out[q] = lo


def flow_lookup(flows: Flows, sources: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Index of the flow ``(source, offset)`` for each query, ``-1`` where there is none.

    ``flows`` must be ordered by offset, then source, as :func:`enumerate_flows` gives them:
    each query is a binary search within its offset's run.
    """
    if len(flows.source) == 0:
        return np.full(len(sources), -1, dtype=np.int64)
    bad = _first_disorder(flows.offset, flows.source)
    if bad >= 0:
        raise ValueError(f"flows are not ordered by offset, then source (at flow {bad})")
    starts = np.searchsorted(flows.offset, np.arange(int(flows.offset[-1]) + 2))
    out = np.empty(len(sources), dtype=np.int64)
    _lookup(flows.source, starts, np.asarray(sources), np.asarray(offsets), out)
    return out


class System(NamedTuple):
    """One saddle-point system ``[[A, B^T], [B, 0]] [u; lambda] = [f; g]``.

    A : csr [n, n], SPD (thanks to the regulariser).
    B : csr [m, n], the incompressibility constraints (rows without unknowns dropped).
    f : [n]; g : [m].
    free : int64 [n_x], flat cell index of each free value (the first ``n_x`` unknowns).
    flows : Flows (the remaining ``n - n_x`` unknowns).
    infeasible : int, constraints of fixed cells that have no flow at all (dropped).
    """

    A: sp.csr_matrix
    B: sp.csr_matrix
    f: np.ndarray
    g: np.ndarray
    free: np.ndarray
    flows: Flows
    infeasible: int


def _gram(first: np.ndarray, second: np.ndarray, weight: np.ndarray, n: int, reg: float):
    """``D^T diag(weight) D + reg I`` [n, n] (CSR) for the operator ``D`` whose row ``k`` is
    ``+1`` at unknown ``first[k]`` and ``-1`` at ``second[k]`` (either ``-1``: no entry).

    Every pair of unknowns shares at most one term (a face, or a flow and its successor), so
    the off-diagonal entries are the terms' ``-weight`` placed directly, without a product.
    """
    diagonal = np.full(n, float(reg))
    for column in (first, second):
        present = column >= 0
        diagonal += np.bincount(column[present], weight[present], minlength=n)
    both = np.flatnonzero((first >= 0) & (second >= 0))
    index = np.int32 if n < np.iinfo(np.int32).max else np.int64
    a, b = first[both].astype(index), second[both].astype(index)
    w = -weight[both]
    del both
    cells = np.arange(n, dtype=index)
    rows = np.concatenate([cells, a, b])
    columns = np.concatenate([cells, b, a])
    del cells, a, b
    return csr_from_entries(rows, columns, np.concatenate([diagonal, w, w]), (n, n))


def build_system(
    value: np.ndarray,
    weights: np.ndarray,
    offsets: np.ndarray,
    *,
    alpha: float,
    reg: float,
    still_depth: int = 0,
) -> System:
    """Assemble the system for the current cell values.

    Parameters
    ----------
    value : float64 [S, X, Y, Z]
        ``nan`` for free cells, else the fixed value (0 outside / dead, 1 inside).
    weights : float64 [3, S, X, Y, Z]
        Continuity weight of the face between a cell and its ``+axis`` neighbour.
    offsets : int [K, 3]
    alpha, reg : float
        Weight of continuity against momentum, and of the regulariser ``F_r``.
    still_depth : int
        Material stays in the cells fixed inside at least this many cells deep
        (:func:`still_interior`; 0: flows everywhere, the paper).
    """
    shape4 = value.shape
    S = shape4[0]
    n_cells = value.size
    flat_value = value.ravel()
    free_mask = np.isnan(flat_value)
    alive = free_mask | (flat_value != 0)
    free = np.flatnonzero(free_mask)
    n_x = len(free)
    xcol = np.full(n_cells, -1, dtype=np.int64)
    xcol[free] = np.arange(n_x)
    still = still_interior(value, still_depth) if still_depth > 0 else None
    flows = enumerate_flows(alive.reshape(shape4), offsets, still)
    # a deep cell's flow to itself is its only way out (or in) and its value is 1, so that
    # flow is 1: a constant, not an unknown
    pinned = np.zeros(len(flows.source), dtype=bool)
    if still is not None:
        stay = ~offsets[flows.offset].any(axis=1)
        pinned = stay & (still[0].ravel()[flows.source] | still[1].ravel()[flows.target])
    del still
    n_v = int((~pinned).sum())
    n = n_x + n_v
    column = np.full(len(flows.source), -1, dtype=np.int64)
    column[~pinned] = n_x + np.arange(n_v)
    fixed_value = np.where(free_mask, 0.0, flat_value)

    f = np.zeros(n)

    # Every term of F but the regulariser is a weighted square of a difference of at most two
    # unknowns: one row of an operator D [terms, n] with +1 / -1 at the unknowns (none at a
    # fixed cell) and weight w, so that A = D^T W D + reg I (:func:`_gram`).
    first, second, term_weight = [], [], []

    # continuity (5): faces with at least one free cell; a fixed neighbour's value goes to f
    strides = np.array([np.prod(shape4[a + 1 :]) for a in range(4)], dtype=np.int64)
    flat = np.arange(n_cells).reshape(shape4)
    for axis in range(3):
        a = np.take(flat, np.arange(shape4[axis + 1] - 1), axis=axis + 1).ravel()
        b = a + strides[axis + 1]
        keep = free_mask[a] | free_mask[b]
        a, b = a[keep], b[keep]
        w = alpha * weights[axis].ravel()[a]
        fa, fb = free_mask[a], free_mask[b]
        first.append(xcol[a])  # -1 where fixed
        second.append(xcol[b])
        term_weight.append(w)
        only_a = fa & ~fb
        f[:n_x] += np.bincount(
            xcol[a[only_a]], w[only_a] * fixed_value[b[only_a]], minlength=n_x
        )
        only_b = fb & ~fa
        f[:n_x] += np.bincount(
            xcol[b[only_b]], w[only_b] * fixed_value[a[only_b]], minlength=n_x
        )

    # momentum (4): (v_a - v_b)^2 for each flow and its successor in the same direction;
    # a missing partner is a zero flow.
    mom = 1.0 - alpha
    if n_v:
        d = offsets[flows.offset]
        shift = strides[0] + d[:, 0] * strides[1] + d[:, 1] * strides[2] + d[:, 2] * strides[3]
        t_src = flows.source // strides[0]
        successor = flow_lookup(flows, flows.target, flows.offset)
        has_next_slice = t_src < S - 2
        pair = np.flatnonzero(has_next_slice & (successor >= 0))
        a, b = column[pair], column[successor[pair]]
        both = (a >= 0) & (b >= 0)
        one = (a >= 0) ^ (b >= 0)
        # a pinned partner (a flow of 1) puts (v - 1)^2: the missing partner's v^2 and f += w
        f += np.bincount(np.maximum(a, b)[one], minlength=n) * mom
        first.append(np.concatenate([a[both], np.maximum(a, b)[one]]))
        second.append(np.concatenate([b[both], np.full(int(one.sum()), -1, dtype=np.int64)]))
        lonely_out = has_next_slice & (successor < 0) & ~pinned
        predecessor = flow_lookup(flows, flows.source - shift, flows.offset)
        lonely_in = (t_src >= 1) & (predecessor < 0) & ~pinned
        single = column[np.concatenate([np.flatnonzero(lonely_out), np.flatnonzero(lonely_in)])]
        first.append(single)
        second.append(np.full(len(single), -1, dtype=np.int64))
        term_weight.append(np.full(len(first[-2]) + len(single), mom))
        del d, shift, t_src, successor, predecessor, pair, a, b, both, one
        del lonely_out, lonely_in, single

    first, second, term_weight = (np.concatenate(t) for t in (first, second, term_weight))
    A = _gram(first, second, term_weight, n, reg)
    del first, second, term_weight

    # incompressibility: out rows (t < S-1) and in rows (t > 0) for every living cell
    alive_cells = np.flatnonzero(alive)
    t_cell = alive_cells // strides[0]
    out_cells = alive_cells[t_cell < S - 1]
    in_cells = alive_cells[t_cell > 0]
    row_of_out = np.full(n_cells, -1, dtype=np.int64)
    row_of_out[out_cells] = np.arange(len(out_cells))
    row_of_in = np.full(n_cells, -1, dtype=np.int64)
    row_of_in[in_cells] = len(out_cells) + np.arange(len(in_cells))
    m_all = len(out_cells) + len(in_cells)
    # B's column of a free cell has -1 in the cell's out and in rows (where they exist), a
    # flow's column +1 in its source's out row and its target's in row; a row without a flow
    # whose cell is fixed is dropped (infeasible when its value is not zero).
    cells = np.concatenate([out_cells, in_cells])
    is_free = free_mask[cells]
    g_all = np.where(is_free, 0.0, fixed_value[cells])
    if pinned.any():
        g_all -= np.bincount(row_of_out[flows.source[pinned]], minlength=m_all)
        g_all -= np.bincount(row_of_in[flows.target[pinned]], minlength=m_all)
        flows = Flows(flows.source[~pinned], flows.target[~pinned], flows.offset[~pinned])
    flow_out, flow_in = row_of_out[flows.source], row_of_in[flows.target]
    has_flow = np.zeros(m_all, dtype=bool)
    has_flow[flow_out] = True
    has_flow[flow_in] = True
    infeasible = int((~has_flow & ~is_free & (g_all != 0)).sum())
    keep = has_flow | is_free
    g = g_all[keep]
    index = np.int32 if max(n, m_all) < np.iinfo(np.int32).max else np.int64
    new_row = np.full(m_all + 1, -1, dtype=index)  # the last one is row -1's
    new_row[np.flatnonzero(keep)] = np.arange(int(keep.sum()), dtype=index)
    del cells, is_free, g_all, has_flow, keep
    rows = np.empty((n, 2), dtype=index)
    rows[:n_x, 0] = new_row[row_of_out[free]]
    rows[:n_x, 1] = new_row[row_of_in[free]]
    rows[n_x:, 0] = new_row[flow_out]
    rows[n_x:, 1] = new_row[flow_in]
    del flow_out, flow_in, row_of_out, row_of_in
    values = np.empty((n, 2))
    values[:n_x] = -1.0
    values[n_x:] = 1.0
    columns = np.repeat(np.arange(n, dtype=index), 2)
    B = csr_from_entries(rows.ravel(), columns, values.ravel(), (len(g), n))
    return System(A, B, f, g, free, flows, infeasible)
