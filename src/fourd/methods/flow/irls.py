"""Iteratively reweighted least squares with bootstrapping and clamping (paper 002, section 4(b)).

Every iteration assembles the constrained quadratic of :mod:`.system` for the cells still
free, solves it with :func:`.saddle.solve_saddle`, then

* clamps: free cells whose value came out within ``clamp`` of 0 or 1 become hard constraints
  (back-substituted from then on);
* back-substitutes flows: a zero cell has no flows; a cell left without incoming or outgoing
  flow is zero (:func:`.grid.speed_prune` applied with the one-cells kept);
* reweights continuity faces: ``w = |x_i - x_j|^(p - 2)`` with ``|dx|`` bounded below by
  ``floor`` (the paper's bound ``0.001^(0.8-2)`` from above on ``w``) and scaled into
  ``(0, scale]``;

and stops once ``stop_fraction`` of the cells of the hull are decided (90-95% in the paper).
If an iteration decides almost nothing new, the clamping band is widened by half (a safeguard
the paper does not need to mention: it guarantees the loop ends).
"""

from __future__ import annotations

import json
import logging
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from fourd.cache import Chain, report_resumed
from fourd.methods.flow.amg import restrict_interpolations
from fourd.methods.flow.grid import speed_prune
from fourd.methods.flow.saddle import release_free_heap, solve_saddle
from fourd.methods.flow.system import Flows, build_system, flow_lookup

log = logging.getLogger("fourd.methods.flow.irls")


class IRLSResult(NamedTuple):
    """Result of :func:`run_irls`.

    x : float64 [S, X, Y, Z], the characteristic function (decided cells exactly 0/1, the rest
        their last solved value, dead cells 0).
    decided : bool [S, X, Y, Z].
    iterations : int.
    history : list of dict per iteration (decided fraction, total mass per slice, MINRES
        iterations and residual, unknowns, constraints, seconds).
    """

    x: np.ndarray
    decided: np.ndarray
    iterations: int
    history: list


def irls_weights(
    x: np.ndarray, *, exponent: float, floor: float, scale: float, out: np.ndarray | None = None
) -> np.ndarray:
    """Continuity weights ``[3, S, X, Y, Z]`` for the faces towards ``+axis`` from values ``x``
    (written into ``out`` if given).

    ``w = scale * (max(|dx|, floor) / floor)^(exponent - 2)`` lies in ``(0, scale]``.
    """
    weights = np.empty((3, *x.shape)) if out is None else out
    for axis in range(3):
        dx = np.zeros(x.shape)
        a = [slice(None)] * 4
        b = [slice(None)] * 4
        a[axis + 1] = slice(0, -1)
        b[axis + 1] = slice(1, None)
        dx[tuple(a)] = np.abs(x[tuple(b)] - x[tuple(a)])
        weights[axis] = scale * (np.maximum(dx, floor) / floor) ** (exponent - 2.0)
    return weights


def _warm_start(
    system, previous_x, previous_flows: Flows | None, previous_v, offsets
) -> np.ndarray:
    n_x = len(system.free)
    start = np.zeros(system.A.shape[0] + system.B.shape[0])
    start[:n_x] = previous_x.ravel()[system.free]
    if previous_flows is not None and len(previous_flows.source):
        index = flow_lookup(previous_flows, system.flows.source, system.flows.offset)
        found = index >= 0
        v = np.zeros(len(system.flows.source))
        v[found] = previous_v[index[found]]
        start[n_x : system.A.shape[0]] = v
    else:  # material stays where it is (offset 0 is the cell itself)
        stay = np.flatnonzero(np.all(offsets[system.flows.offset] == 0, axis=1))
        start[n_x + stay] = previous_x.ravel()[system.flows.source[stay]]
    return start


def _previous_unknowns(system, previous_free, previous_flows: Flows) -> np.ndarray | None:
    """The index of each primal unknown of ``system`` (free cells, then flows) among the
    previous system's, or None if one of them is new."""
    cell = np.searchsorted(previous_free, system.free)
    if len(system.free) and (
        cell.max() >= len(previous_free) or (previous_free[cell] != system.free).any()
    ):
        return None
    flow = flow_lookup(previous_flows, system.flows.source, system.flows.offset)
    if (flow < 0).any():
        return None
    return np.concatenate([cell, len(previous_free) + flow])


def unknown_slices(system, shape4: tuple) -> np.ndarray:
    """The time slice of every primal unknown of ``system`` (int32 [n]): a free cell's own, a
    flow's source cell's; the grid is ``shape4`` [S, X, Y, Z]."""
    cells = int(np.prod(shape4[1:]))
    n_x = len(system.free)
    out = np.empty(n_x + len(system.flows.source), np.int32)
    # into the int32 array directly: no n-sized int64 temporary while the earlier
    # hierarchy and the new system are in memory (squash-ball at resolution 64: 150 MB)
    np.floor_divide(system.free, cells, out=out[:n_x], casting="unsafe")
    np.floor_divide(system.flows.source, cells, out=out[n_x:], casting="unsafe")
    return out


def _plain(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot store a {type(value).__name__} in the IRLS history")


def history_arrays(history: list) -> dict[str, np.ndarray]:
    """The IRLS history as a cache entry's array (JSON text, NaN kept)."""
    return {"history": np.array(json.dumps(history, default=_plain))}


def history_from_arrays(arrays) -> list:
    """The history :func:`history_arrays` stored (``mass`` back as arrays)."""
    history = json.loads(str(arrays["history"]))
    for record in history:
        record["mass"] = np.asarray(record["mass"], dtype=float)
    return history


def _matrix_arrays(name: str, matrices) -> dict[str, np.ndarray]:
    if matrices is None:
        return {}
    out = {f"{name}_count": np.array(len(matrices))}
    for i, matrix in enumerate(matrices):
        matrix = matrix.tocsr()
        out[f"{name}_{i}_data"] = matrix.data
        out[f"{name}_{i}_indices"] = matrix.indices
        out[f"{name}_{i}_indptr"] = matrix.indptr
        out[f"{name}_{i}_shape"] = np.array(matrix.shape)
    return out


def _matrices(arrays, name: str) -> list | None:
    if f"{name}_count" not in arrays:
        return None
    return [
        sp.csr_matrix(
            (arrays[f"{name}_{i}_data"], arrays[f"{name}_{i}_indices"], arrays[f"{name}_{i}_indptr"]),
            shape=tuple(int(n) for n in arrays[f"{name}_{i}_shape"]),
        )
        for i in range(int(arrays[f"{name}_count"]))
    ]


class _State(NamedTuple):
    """What an IRLS iteration leaves to the next: a checkpoint's content."""

    value: np.ndarray
    x: np.ndarray
    band: float
    iterations: int
    history: list
    free: np.ndarray | None
    flows: Flows | None
    v: np.ndarray | None
    interpolations: list | None
    coarse: list | None


def _state_arrays(state: _State) -> dict[str, np.ndarray]:
    arrays = {
        "value": state.value,
        "x": state.x,
        "band": np.array(state.band),
        "iterations": np.array(state.iterations),
        **history_arrays(state.history),
        **_matrix_arrays("interpolation", state.interpolations),
        **_matrix_arrays("coarse", state.coarse),
    }
    if state.flows is not None:
        arrays.update(
            free=state.free, source=state.flows.source, target=state.flows.target,
            offset=state.flows.offset, v=state.v,
        )
    return arrays


def _state(arrays) -> _State:
    flows = None
    if "source" in arrays:
        flows = Flows(arrays["source"], arrays["target"], arrays["offset"])
    return _State(
        arrays["value"], arrays["x"], float(arrays["band"]), int(arrays["iterations"]),
        history_from_arrays(arrays), arrays.get("free"), flows, arrays.get("v"),
        _matrices(arrays, "interpolation"), _matrices(arrays, "coarse"),
    )


def run_irls(
    value: np.ndarray,
    weights: np.ndarray,
    offsets: np.ndarray,
    region: np.ndarray,
    *,
    alpha: float,
    reg: float,
    exponent: float,
    floor: float,
    scale: float,
    clamp: float,
    stop_fraction: float,
    max_iterations: int,
    solver_options: dict,
    guess: np.ndarray | None = None,
    regularize_towards: str = "zero",
    reuse_interpolation: bool = True,
    reuse_coarse: bool = False,
    later_maxiter: int | None = None,
    parallel: bool = True,
    still_depth: int = 0,
    progress=None,
    checkpoints: Chain | None = None,
) -> IRLSResult:
    """Run the IRLS loop from the initial labels.

    Parameters
    ----------
    value : float64 [S, X, Y, Z]
        Initial values: ``nan`` free, 0 outside, 1 inside / data.
    weights : float64 [3, S, X, Y, Z]
        First-iteration continuity weights (0 on outward boundary faces, 1 elsewhere);
        overwritten with the later iterations' weights.
    region : bool [S, X, Y, Z]
        Cells counted for the stopping criterion (the hull: cells not carved at the start).
    solver_options : dict
        Keyword arguments for :func:`.saddle.solve_saddle`.
    guess : float64 [S, X, Y, Z], optional
        Starting values of the free cells for the first solve (e.g. the implicit fit's
        inside indicator); flows start as "material stays in its cell".
    regularize_towards : ``"zero"`` or ``"previous"``
        What the regulariser ``F_r`` pulls the free cells' values towards: 0 (the paper), or
        each solve's starting values (``guess``, then the previous iterate); see the flow
        method's ``Options.regularize_towards``.
    reuse_interpolation : bool
        From the second iteration on, the inner V-cycle keeps the previous solve's AMG
        interpolation, restricted to the unknowns still free (see
        :func:`.amg.restricted_hierarchy`); a new set-up only if an unknown is new.
    reuse_coarse : bool
        With ``reuse_interpolation``: keep the previous solve's coarse matrices too
        (restricted, :func:`.amg.frozen_hierarchy`) instead of forming ``A + B^T B`` and
        its Galerkin products again.
    later_maxiter : int, optional
        MINRES iteration limit of the solves after the first (warm-started from the previous
        iterate); None: ``solver_options["maxiter"]``.
    parallel : bool
        The V-cycle's Gauss-Seidel sweeps run on all cores, blocks of time slices at once
        (:func:`unknown_slices`, :mod:`.sweeps`); False: one row after the other.
    still_depth : int
        Material stays in the cells fixed inside at least this many cells deep (see
        :func:`.system.still_interior`); 0: flows everywhere.
    checkpoints : Chain, optional
        Cache entries of the iterations (:class:`fourd.cache.Chain`, one key per possible
        iteration, keyed by the caller from all of the above but ``max_iterations`` and
        ``stop_fraction``): after each iteration but the last, everything the next one starts
        from (the labels, the iterate, the flows, the AMG hierarchy it reuses) replaces the
        previous iteration's entry, and a run finding one continues after it, with the same
        result as without the interruption.
    """
    if regularize_towards not in ("zero", "previous"):
        raise ValueError(f"regularize_towards must be zero or previous, got {regularize_towards!r}")
    value = value.copy()
    full = len(offsets) == 27
    total = max(int(region.sum()), 1)
    x = np.where(np.isnan(value), 0.5 if guess is None else guess, value)
    history = []
    previous_flows, previous_v = None, None
    previous_free, previous_interpolations, previous_coarse = None, None, None
    band = clamp
    iterations = 0
    first = 0
    if checkpoints is not None:
        step, entry = checkpoints.latest()
        if entry is not None and step + 1 < max_iterations:
            state = _state(entry)
            value, x, band, iterations, history = (
                state.value, state.x, state.band, state.iterations, state.history
            )
            previous_free, previous_flows, previous_v = state.free, state.flows, state.v
            previous_interpolations, previous_coarse = state.interpolations, state.coarse
            weights = irls_weights(x, exponent=exponent, floor=floor, scale=scale, out=weights)
            first = step + 1
            report_resumed(log, f"{first} flow iterations")
            if progress is not None:
                progress.update(first)
    for iteration in range(first, max_iterations):
        alive = speed_prune(value != 0, full=full, keep=value == 1)
        value[~alive] = 0.0
        x[~alive] = 0.0
        system = None  # the previous system is not needed while the next one is built
        system = build_system(
            value, weights, offsets, alpha=alpha, reg=reg, still_depth=still_depth
        )
        n_x = len(system.free)
        decided_before = int((~np.isnan(value) & region).sum())
        if n_x == 0:
            break
        start = _warm_start(system, x, previous_flows, previous_v, offsets)
        f = system.f
        if regularize_towards == "previous":
            # F_r = reg * sum (x - x_start)^2 + reg * sum v^2: the same matrix, another right side
            f = f.copy()
            f[:n_x] += reg * start[:n_x]
        reuse = reuse_matrices = None
        if reuse_interpolation and previous_interpolations is not None:
            rows = _previous_unknowns(system, previous_free, previous_flows)
            # lists that restrict_interpolations empties as it goes: each earlier level is
            # freed once restricted
            interpolations = list(previous_interpolations)
            coarse = None if previous_coarse is None else list(previous_coarse)
            previous_interpolations = previous_coarse = None
            if rows is not None and coarse is not None:
                reuse, reuse_matrices = restrict_interpolations(
                    interpolations, rows, coarse, consume=True
                )
            elif rows is not None:
                reuse = restrict_interpolations(interpolations, rows, consume=True)
            del interpolations, coarse, rows
        # the previous solve's vectors, flows and hierarchy are not needed in this one
        # (squash-ball at resolution 64: 0.5 GB)
        previous_flows = previous_v = previous_interpolations = previous_coarse = None
        solution = None
        release_free_heap()
        solve_options = dict(solver_options)
        if iteration > 0 and later_maxiter is not None:
            solve_options["maxiter"] = later_maxiter
        solution = solve_saddle(
            system.A, system.B, f, system.g, x0=start, reuse=reuse, reuse_coarse=reuse_matrices,
            overwrite_x0=True, groups=unknown_slices(system, value.shape) if parallel else None,
            **solve_options,
        )
        del start, reuse, reuse_matrices
        previous_free, previous_interpolations = system.free, solution.interpolations
        if reuse_coarse:
            previous_coarse = solution.coarse_matrices
        solution = solution._replace(interpolations=None, coarse_matrices=None)
        iterations += 1
        xs = solution.u[:n_x]
        x.ravel()[system.free] = xs
        previous_flows, previous_v = system.flows, solution.u[n_x:]
        free_values = value.ravel()[system.free]
        free_values[xs <= band] = 0.0
        free_values[xs >= 1.0 - band] = 1.0
        flat = value.ravel()
        flat[system.free] = free_values
        decided_now = int((~np.isnan(value) & region).sum())
        x = np.where(np.isnan(value), x, value)
        # into the first iteration's array, which the caller's call still holds (squash-ball
        # at resolution 64: 126 MB)
        weights = irls_weights(x, exponent=exponent, floor=floor, scale=scale, out=weights)
        fraction = decided_now / total
        record = {
            "iteration": iteration,
            "unknowns": int(system.A.shape[0]),
            "free_cells": n_x,
            "flows": int(len(system.flows.source)),
            "constraints": int(system.B.shape[0]),
            "infeasible": system.infeasible,
            "minres_iterations": solution.iterations,
            "inner_iterations": solution.inner_iterations,
            "residual": solution.residual,
            "converged": solution.converged,
            "seconds": solution.seconds,
            "decided": fraction,
            "mass": x.reshape(len(x), -1).sum(axis=1),
            "clamp": band,
        }
        history.append(record)
        log.info(
            "flow iteration %d: %d unknowns (%d cells, %d flows), %d constraints, MINRES %d its "
            "(residual %.1e, %.1fs), %.1f%% decided",
            iteration,
            record["unknowns"],
            n_x,
            record["flows"],
            record["constraints"],
            solution.iterations,
            solution.residual,
            solution.seconds,
            100 * fraction,
        )
        if progress is not None:
            progress.update(1)
        if fraction >= stop_fraction:
            break
        if decided_now - decided_before < 0.005 * total:
            band = min(1.5 * band, 0.45)
        if checkpoints is not None and iteration + 1 < max_iterations:
            state = _State(
                value, x, band, iterations, history, previous_free, previous_flows, previous_v,
                previous_interpolations, previous_coarse,
            )
            checkpoints.save(iteration, _state_arrays(state), keep_earlier=False)
            del state
    alive = speed_prune(value != 0, full=full, keep=value == 1)
    x[~alive] = 0.0
    return IRLSResult(x, ~np.isnan(value), iterations, history)
