"""Projection of points onto the zero set of a space-time implicit at one time (section 5.1),
or onto a frame's own surface where it has points (the data term).
"""

from __future__ import annotations

import numpy as np

from fourd.geometry.field import Field4D


def _field_times(times, count: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(times, dtype=np.float64), (count,))


def value_and_gradient(field: Field4D, points: np.ndarray, times) -> tuple[np.ndarray, np.ndarray]:
    """``f`` and ``grad f`` in one pass when the field offers ``value_and_gradient``."""
    both = getattr(field, "value_and_gradient", None)
    if both is not None:
        return both(points, times)
    return field.value(points, times), field.gradient(points, times)


def project_to_surface(
    field: Field4D,
    points: np.ndarray,
    time: float,
    *,
    iterations: int = 8,
    max_step: float = np.inf,
    tolerance: float = 0.0,
    surface=None,
) -> np.ndarray:
    """Project ``points`` [M, 3] onto ``f(., time) = 0`` by Newton steps along the spatial
    gradient (the time component of the gradient set to zero, 000_00387fefe94cc850.txt 5.1).

    With ``surface`` (a :class:`~fourd.methods.kinematic.framesurface.FrameSurface` of the
    input frame at ``time``) the target is that frame's surface where it has points and ``f``
    elsewhere. Points where the gradient vanishes (no support) stay where they are.
    """
    target = (
        _implicit_target(field, time) if surface is None else _data_target(field, surface, time)
    )
    return _project(target, points, iterations, max_step=max_step, tolerance=tolerance)


def _implicit_target(field: Field4D, time: float):
    """``x [M, 3] -> (f [M], grad_x f [M, 3], None)`` at ``time``: the 4D implicit only."""

    def evaluate(x):
        values, grads = value_and_gradient(field, x, _field_times(time, len(x)))
        return values, grads[:, :3], None

    return evaluate


def _data_target(field: Field4D, surface, time: float, full_coverage: float = 0.99):
    """``x [M, 3] -> (f [M], grad [M, 3], weights [M])``: the frame's own surface
    (:class:`~fourd.methods.kinematic.framesurface.FrameSurface`) where it has points, blended
    into the 4D implicit (as a distance: ``f / |grad_x f|``) where it has fewer; ``weights`` is
    1 where the frame's points alone define the surface, else 0. ``implicit = (f [M], grad f
    [M, 4])`` at ``x`` and ``time``, when already known, saves evaluating the 4D implicit."""

    def evaluate(x, implicit=None):
        values, grads, coverage = surface.evaluate(x)
        partial = np.flatnonzero(coverage < 1.0)
        if len(partial):
            if implicit is None:
                f4, g4 = value_and_gradient(field, x[partial], _field_times(time, len(partial)))
            else:
                f4, g4 = implicit[0][partial], implicit[1][partial]
            norm = np.maximum(np.linalg.norm(g4[:, :3], axis=1), 1e-12)
            b = coverage[partial]
            values[partial] = b * values[partial] + (1.0 - b) * f4 / norm
            grads[partial] = b[:, None] * grads[partial] + (1.0 - b)[:, None] * (
                g4[:, :3] / norm[:, None]
            )
        return values, grads, (coverage >= full_coverage).astype(np.float64)

    return evaluate


def _project(evaluate, points, iterations, *, max_step=np.inf, tolerance=0.0):
    """Newton steps of ``points`` [M, 3] onto the zero set of ``evaluate`` (a target of
    :func:`_implicit_target` or :func:`_data_target`)."""
    x = np.array(points, dtype=np.float64, copy=True)
    active = np.arange(len(x))
    for _ in range(iterations):
        if len(active) == 0:
            break
        values, grads, _ = evaluate(x[active])
        norm2 = np.einsum("ij,ij->i", grads, grads)
        ok = norm2 > 1e-20
        step = np.zeros_like(grads)
        step[ok] = -(values[ok] / norm2[ok])[:, None] * grads[ok]
        length = np.linalg.norm(step, axis=1)
        too_long = length > max_step
        step[too_long] *= (max_step / length[too_long])[:, None]
        x[active] += step
        # converged once the Newton step (~ the distance to the surface) is below the
        # tolerance: Newton's quadratic convergence leaves it far closer than that, and this
        # saves the evaluation that would only confirm it
        keep = ok & (np.abs(values) > tolerance) & (length > tolerance)
        active = active[keep]
    return x
