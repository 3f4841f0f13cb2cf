"""Sliding a template mesh along a space-time surface ``f(x, t) = 0`` as rigidly as possible.

For each next time ``t'`` (000_00387fefe94cc850.txt, section 5):

1. initial guess (5.1): every vertex is projected onto ``f(., t') = 0`` by gradient steps with
   the time component of the gradient set to zero;
2. rotations (5.2): per-vertex best rotations of the cotangent-weighted edge covariance
   ``S_i = sum_j w_ij (p0_i - p0_j)(p_i - p_j)^T`` by SVD;
3. positions (5.3): the minimiser of the ARAP energy (1) subject to the tangential-motion
   constraint (2) ``(p_i' - p_i) . grad_x f + (t' - t) df/dt = 0`` for every observed vertex,
   i.e. system (5) with one Lagrange multiplier per vertex; the system matrix depends only on
   the normals at time ``t``, so it is factorised once per time step and every further
   iteration is a back-substitution;
4. a fixed number of iterations with re-projection onto ``f(., t') = 0`` between them;
5. vertices with no input point within an epsilon-ball (5.4) get lambda = 0 (no constraint),
   follow as rigidly as possible and are marked not observed.

Implementation of (5): the multipliers are eliminated exactly by the null-space method. A
constrained vertex is written ``p_i = a_i + T_i u_i`` with ``a_i`` a point on its constraint
plane and ``T_i`` [3, 2] an orthonormal basis of that plane; an unconstrained vertex keeps its
three coordinates. The reduced matrix ``B^T (L (x) I_3) B`` (B block diagonal) is symmetric
positive definite (a tiny Tikhonov term towards the current estimate removes the translation
null space) and has at most ``3n`` unknowns instead of the saddle system's ``4n``. It gives
the same positions as system (5).

Beyond the paper (documented options, defaults on):

* ``residual_correction``: the constraint's right side includes ``-f(p_i^t, t)``, the first
  order Taylor condition for ``f(p_i', t') = 0``; with an exact surface at time ``t`` this is
  the paper's constraint, and it keeps linearisation errors from accumulating (drift).
* ``substeps``: the space-time function is continuous in time, so a large step between input
  times is split into equal sub-steps, each a full sliding step of the paper. This is what
  keeps the projection from grabbing a neighbouring limb when the motion between frames is
  large compared with the surface's feature size.
* ``project_output``: observed vertices of the final iterate are projected onto ``f = 0``.
* ``rigid_guess``: before the projection of 5.1, the vertices are moved by the rigid motion
  that best satisfies the constraints (2) (one global, then one per patch of
  ``rigid_neighbours`` vertices), refined by Gauss-Newton steps against ``f(., t')`` itself
  (point-to-plane ICP on the implicit). The projection alone moves vertices only along the
  normals, so a turning body's tangential motion would be left to the ARAP iterations, which
  recover it far too slowly (measured: a rigidly turning blob drifts by 10% of its size in
  five steps without it, not at all with it).
* ``projection_limit``: after a large-motion registration, a vertex that the projection of
  5.1 would move farther than a few edges is left unconstrained for the step instead (the
  registration left it off the surface, and the nearest surface is rarely its own).
* ``linearize_at = "guess"``: constraint (2) linearised at the initial guess on
  ``f(., t') = 0`` rather than at ``p^t``; still one factorisation per time step.
* the data term (``surfaces``): at an input time, the rigid prediction, the projections and
  constraint (2) use that frame's own points (an IMLS surface) where it has points, so the
  pose bias of a space-time fit that blends neighbouring frames does not enter the tracking.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numba
import numpy as np
import pymetis
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.geometry.field import Field4D
from fourd.geometry.laplacian import cotangent_weights, weights_laplacian
from fourd.methods.kinematic.arap import arap_energy, blended_arap_rhs, with_rest_shape
from fourd.methods.kinematic.register import ArapIcp, RegisterOptions, registration_due
from fourd.progress import progress

log = logging.getLogger("fourd.methods.kinematic.sliding")

#: The global rigid fit of :func:`rigid_prediction` makes no motion along the directions whose
#: curvature in the least-squares fit is below this fraction of the largest: moving the shape
#: along them hardly changes the fit (the spin of a shape of revolution), so noise alone
#: would choose the motion there, and it adds up over the frames. Measured (20k samples,
#: correspondence mean / last frame): a still, noisy spheroid (8 frames) spun about its axis,
#: 0.031 mean displacement at the last frame, 0.003 with this; squash-ball 0.064 / 0.086 ->
#: 0.025 / 0.015, touching-spheres 0.019 / 0.032 -> 0.017 / 0.025. rigid-turn turns about
#: axes at 0.004-0.006 of the largest: 0.01 took it from 0.0016 to 0.12 (squash-ball
#: 0.022 / 0.003 there), so the bound stays below it. Degeneracy-aware ICP, by truncation.
DEGENERATE_MOTION = 0.002


@dataclass(frozen=True)
class SlideOptions:
    """Parameters of the template sliding.

    Attributes
    ----------
    iterations : int
        Fixed number of rotation / position iterations per time step (the paper: 3-10).
    epsilon : float
        Radius of the ball that must contain an input point for a vertex to stay constrained
        (observed). 0: derived from the template's median edge length (2x).
    substeps : int
        Sub-steps per step between consecutive output times (1: the paper).
    projection_iterations : int
        Gradient steps of the projection of the initial guess and of the output onto ``f = 0``.
    reprojection_iterations : int
        Gradient steps of the re-projections between iterations.
    projection_tolerance : float
        A vertex stops projecting once its Newton step is below this fraction of the median
        edge length; the Gauss-Newton steps of the rigid prediction stop once no vertex moves
        by more than a tenth of that.
    max_step : float
        Largest move of one projection step (0: 4x the median edge length), so that a vertex
        never jumps across a thin gap in one step.
    residual_correction : bool
        Include ``f(p^t, t)`` in the constraint (see the module notes).
    project_output : bool
        Project observed vertices of the final iterate onto ``f = 0``.
    regularization : float
        Weight of the Tikhonov term (relative to the Laplacian diagonal).
    extrapolate : bool
        Start the initial-guess projection from a constant-velocity prediction of the previous
        step's motion (beyond the paper; recovers sustained rigid motion that the normal
        constraint alone leaves ambiguous, e.g. tangential rotation).
    rigid_guess : bool
        Before the projection, move the vertices by the linearised rigid motion that best
        satisfies the constraints (2) globally, then per patch of ``rigid_neighbours``
        vertices (point-to-plane steps on the implicit; beyond the paper).
    rigid_neighbours : int
    rigid_iterations : int
        At most this many Gauss-Newton steps of that rigid prediction against ``f(., t')``
        itself (point-to-plane ICP on the implicit) after the first, linearised one.
    data_rigid_iterations : int
        At most this many Gauss-Newton steps of the rigid prediction against an input frame's
        own points when the step has a data term (see :func:`slide_step`).
    rigid_samples : int
        Where the rigid prediction is one global motion (a step with a data term, or
        ``rigid_neighbours`` below 2), its Gauss-Newton steps fit it to this many vertices
        spread over the template (0: all), except the last ``rigid_refine_iterations``, which
        fit it to every vertex. The motion has six unknowns, and the target's evaluations at
        every vertex took about a tenth of crane's time: the steps seldom meet their stopping
        rule on noisy data, so nearly every step ran all of them. The count of steps is kept:
        on a deforming shape the steps do not converge, and more of them moved squash-ball's
        template (correspondence mean / last frame 0.0241 / 0.0145 -> 0.0361 / 0.0471 with
        two refining steps added after six on the sample).
    rigid_refine_iterations : int
        How many of those steps, the last ones, fit the global motion to every vertex.
    register : RegisterOptions or None
        Large-motion registration (:mod:`.register`): at a step with a data term whose
        prediction leaves many of the frame's points unexplained, the template is registered
        to them by as-rigid-as-possible ICP before the projection of 5.1 (None: never).
    projection_limit : float
        At a step whose large-motion registration was kept: a vertex that the projection of
        5.1 would move farther than this many median edge lengths from its registered
        position is left there, unconstrained in this step (lambda = 0, as a vertex without
        data). The registration left it off the surface, and the Newton steps would take it
        to whichever surface is nearest, stretching and crushing the template around it
        (crane held-out frames 90-128: edges stretched 1.5x or more went from under 0.01%
        after the registration to 2-3% after the projection); ARAP carries it with its
        neighbours instead. Other steps keep the paper's projection, which is how the
        template follows fast motion where a registration is rejected (splitting-blob:
        Chamfer 0.020 -> 0.048 with the limit on every step). 0: no limit (the paper).
    linearize_at : "previous" or "guess"
        Where constraint (2) is linearised: at the previous positions ``p^t`` with the 4D
        normal there (the paper), or at the initial guess on ``f(., t') = 0`` (the first-order
        condition for ``f(p', t') = 0`` around a closer point: the second-order error of the
        paper's form, which grows with the motion per step, no longer accumulates as drift).
        Either way the matrix is factorised once per time step.
    still_normals : float
        With the data term: where the 4D implicit's zero set moves less than this many median
        edge lengths in the step, constraint (2) takes its normal direction from
        ``grad_x f`` there instead of from the frame's own surface (0: never; beyond the
        paper). The frame's surface carries that frame's scan noise, so its normals tilt a
        little differently in every frame, and ARAP lets the template slide along the
        surface where nothing holds it: a still crane (frame 0 scanned 20 times, standard
        protocol) drifted 0.0010 -> 0.0095 in correspondence by the last frame, its standing
        foot creeping 0.1 input units up the leg. The implicit is smooth over time, and
        where it moves it lags or leads the frame (horse-gallop, every vertex: 0.0094 /
        0.0039 -> 0.0122 / 0.0058), so only the still parts take its normal. Measured
        (20k samples, correspondence mean / last frame, 0 -> 0.2): still crane 0.0041 /
        0.0095 -> 0.0016 / 0.0026; crane 0.0088 / 0.0175 -> 0.0080 / 0.0169; rigid-turn
        0.0016 / 0.0023 -> 0.0013 / 0.0017; touching-spheres 0.0174 / 0.0241 -> 0.0163 /
        0.0207; dfaust-hopping 0.0043 / 0.0058 -> 0.0043 / 0.0060; horse-gallop 0.0094 /
        0.0039 -> 0.0094 / 0.0041.
    previous_shape : float
        Weight ``b`` of the previous positions' shape in the ARAP term of (5): ``(1 - b)
        E_ARAP(rest) + b E_ARAP(previous)``, each with its own rotations, over the same
        cotangent weights (0: the template's rest shape alone, the paper). The rest shape
        alone pulls every step towards its own proportions: with the true positions in place
        of every large-motion registration, crane's correspondence ends at 0.0042 / 0.0060
        with 4 iterations and 0.0027 / 0.0032 with 1 (``benchmarks/registration_oracle.py
        --slide-iterations``). See the ``kinematic`` method's ``slide_memory`` for what 0.8
        measured.
    """

    iterations: int = 4
    epsilon: float = 0.0
    substeps: int = 1
    projection_iterations: int = 6
    reprojection_iterations: int = 2
    projection_tolerance: float = 1e-2
    max_step: float = 0.0
    residual_correction: bool = True
    project_output: bool = True
    regularization: float = 1e-4
    extrapolate: bool = False
    rigid_guess: bool = True
    rigid_neighbours: int = 48
    rigid_iterations: int = 2
    data_rigid_iterations: int = 6
    rigid_samples: int = 2000
    rigid_refine_iterations: int = 2
    register: RegisterOptions | None = RegisterOptions()
    projection_limit: float = 0.0
    linearize_at: Literal["previous", "guess"] = "guess"
    still_normals: float = 0.2
    previous_shape: float = 0.0

    def __post_init__(self):
        if not 0.0 <= self.previous_shape < 1.0:
            raise ValueError(f"previous_shape must lie in [0, 1), got {self.previous_shape}")
        if self.iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {self.iterations}")
        if self.substeps < 1:
            raise ValueError(f"substeps must be at least 1, got {self.substeps}")
        if (
            self.epsilon < 0 or self.max_step < 0 or self.regularization < 0
            or self.projection_limit < 0 or self.still_normals < 0 or self.rigid_samples < 0
            or self.rigid_refine_iterations < 0
        ):
            raise ValueError(
                "epsilon, max_step, regularization, projection_limit, still_normals, "
                "rigid_samples and rigid_refine_iterations must not be negative"
            )


def _field_times(times, count: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(times, dtype=np.float64), (count,))


def value_and_gradient(field: Field4D, points: np.ndarray, times) -> tuple[np.ndarray, np.ndarray]:
    """``f`` and ``grad f`` in one pass when the field offers ``value_and_gradient``."""
    both = getattr(field, "value_and_gradient", None)
    if both is not None:
        return both(points, times)
    return field.value(points, times), field.gradient(points, times)


@numba.njit(cache=True, parallel=True)
def _patch_systems(positions, normals, residuals, weights, groups, A, b, centroids, sizes, traces):
    """Per group: centroid, RMS size, the 6x6 weighted normal equations of the linearised
    point-to-plane rigid motion (rotation part made unitless by the size) and the trace of
    the unweighted ones."""
    for g in numba.prange(groups.shape[0]):
        K = groups.shape[1]
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        for k in range(K):
            v = groups[g, k]
            c0 += positions[v, 0]
            c1 += positions[v, 1]
            c2 += positions[v, 2]
        c0 /= K
        c1 /= K
        c2 /= K
        ss = 0.0
        for k in range(K):
            v = groups[g, k]
            ss += (
                (positions[v, 0] - c0) ** 2
                + (positions[v, 1] - c1) ** 2
                + (positions[v, 2] - c2) ** 2
            )
        size = np.sqrt(ss / K) + 1e-300
        J = np.empty(6)
        trace = 0.0
        for i in range(6):
            b[g, i] = 0.0
            for j in range(6):
                A[g, i, j] = 0.0
        for k in range(K):
            v = groups[g, k]
            q0 = (positions[v, 0] - c0) / size
            q1 = (positions[v, 1] - c1) / size
            q2 = (positions[v, 2] - c2) / size
            n0 = normals[v, 0]
            n1 = normals[v, 1]
            n2 = normals[v, 2]
            J[0] = q1 * n2 - q2 * n1
            J[1] = q2 * n0 - q0 * n2
            J[2] = q0 * n1 - q1 * n0
            J[3] = n0
            J[4] = n1
            J[5] = n2
            r = residuals[v]
            wv = weights[v]
            for i in range(6):
                trace += J[i] * J[i]
                b[g, i] -= wv * J[i] * r
                for j in range(i, 6):
                    A[g, i, j] += wv * J[i] * J[j]
        for i in range(6):
            for j in range(i):
                A[g, i, j] = A[g, j, i]
        centroids[g, 0] = c0
        centroids[g, 1] = c1
        centroids[g, 2] = c2
        sizes[g] = size
        traces[g] = trace


def _rigid_increments(
    positions, normals, residuals, groups, regularization, weights=None, degenerate=0.0
):
    """Linearised point-to-plane rigid motions: for every group of vertices (rows of
    ``groups`` [G, K] indexing ``positions``) the ``(omega, c)`` minimising
    ``sum_k w_k (n_k . (omega x q_k + c) + r_k)^2 + reg |(omega, c)|^2`` with ``q_k`` the
    offsets from the group's centroid and ``reg`` relative to the unweighted system (a group
    with little weight is held near no motion), and no motion along the directions of
    ``(omega, c)`` whose eigenvalue is below ``degenerate`` times the largest. Returns
    ``omega [G, 3], c [G, 3], centroids [G, 3]``."""
    G = len(groups)
    A = np.empty((G, 6, 6))
    b = np.empty((G, 6))
    centroids = np.empty((G, 3))
    sizes = np.empty(G)
    traces = np.empty(G)
    weights = np.ones(len(positions)) if weights is None else weights
    _patch_systems(
        np.ascontiguousarray(positions, dtype=np.float64),
        np.ascontiguousarray(normals, dtype=np.float64),
        np.ascontiguousarray(residuals, dtype=np.float64),
        np.ascontiguousarray(weights, dtype=np.float64),
        np.ascontiguousarray(groups, dtype=np.int64),
        A,
        b,
        centroids,
        sizes,
        traces,
    )
    damping = regularization * traces / 6.0 + 1e-300
    if degenerate > 0:
        values, vectors = np.linalg.eigh(A)
        seen = values > degenerate * values[:, -1:]
        projected = np.einsum("gij,gi->gj", vectors, b) / (values + damping[:, None])
        x = np.einsum("gij,gj->gi", vectors, np.where(seen, projected, 0.0))
    else:
        x = np.linalg.solve(A + damping[:, None, None] * np.eye(6), b[..., None])[..., 0]
    return x[:, :3] / sizes[:, None], x[:, 3:], centroids


def _rotate(vectors, rotvecs):
    """Rodrigues: rotate ``vectors`` [M, 3] by rotation vectors ``rotvecs`` ([M, 3] or [3])."""
    rotvecs = np.broadcast_to(rotvecs, vectors.shape)
    angle = np.linalg.norm(rotvecs, axis=1, keepdims=True)
    axis = rotvecs / np.maximum(angle, 1e-300)
    cos, sin = np.cos(angle), np.sin(angle)
    return (
        vectors * cos
        + np.cross(axis, vectors) * sin
        + axis * np.einsum("ij,ij->i", axis, vectors)[:, None] * (1.0 - cos)
    )


def rigid_prediction(
    positions,
    normals,
    residuals,
    *,
    neighbours: int = 0,
    regularization: float = 1e-3,
    groups: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    sample: np.ndarray | None = None,
):
    """Predicted positions from the first-order space-time constraint: a global linearised
    rigid motion, refined by local ones over the ``neighbours`` nearest vertices (beyond the
    paper: the projection of 5.1 alone only moves vertices along the normals).

    ``residuals`` are ``dt * df/dt + f`` at the vertices, ``normals`` the spatial gradients,
    ``weights`` [N] (optional) the vertices' weights in the fits. ``sample`` [S] (optional,
    global motion only): the indices of the vertices that ``normals``, ``residuals`` and
    ``weights`` belong to; the global motion fitted to them moves every vertex.
    """
    if sample is not None and (groups is not None or neighbours > 1):
        raise ValueError("sample fits the global motion only: no groups or neighbours")
    fitted = positions if sample is None else positions[sample]
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-12
    safe = np.where(ok, norm, 1.0)
    unit = np.where(ok[:, None], normals / safe[:, None], 0.0)
    res = np.where(ok, residuals / safe, 0.0)
    omega, c, centroid = _rigid_increments(
        fitted,
        unit,
        res,
        np.arange(len(fitted))[None],
        regularization,
        weights,
        degenerate=DEGENERATE_MOTION,
    )
    rotation = _rotate(np.eye(3), omega[0]).T  # one global motion: a 3x3 product
    moved = (positions - centroid[0]) @ rotation.T + (centroid[0] + c[0])
    if groups is not None or (neighbours > 1 and len(positions) > neighbours):
        res = res + np.einsum("ij,ij->i", unit, moved - positions)
        if groups is None:
            _, groups = cKDTree(moved).query(moved, k=neighbours, workers=-1)
        omega, c, centroid = _rigid_increments(moved, unit, res, groups, regularization, weights)
        moved = centroid + _rotate(moved - centroid, omega) + c
    return moved


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


class SlidePrecompute(NamedTuple):
    """What stays fixed over the whole sliding: the template's cotangent weights, Laplacian
    and edge incidence (libigl's ``arap_precomputation``)."""

    rest: np.ndarray
    edge_i: np.ndarray
    edge_j: np.ndarray
    edge_w: np.ndarray
    incidence: sp.csr_matrix
    laplacian: sp.csr_matrix
    rest_edges: np.ndarray
    edge_length: float
    indptr: np.ndarray
    order: np.ndarray
    ordered_laplacian: sp.csr_matrix


def median_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Median length of the edges of ``faces`` [F, 3] over ``vertices`` [N, 3]."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    lengths = np.linalg.norm(vertices[faces[:, [1, 2, 0]]] - vertices[faces], axis=2)
    return float(np.median(lengths))


def slide_precompute(rest_vertices: np.ndarray, faces: np.ndarray) -> SlidePrecompute:
    """Cotangent weights (clamped at zero), Laplacian ``L`` and directed edge lists of the
    template."""
    rest = np.asarray(rest_vertices, dtype=np.float64)
    Wc = cotangent_weights(rest, faces, clamp_negative=True).tocsr()
    Wc.sort_indices()
    W = Wc.tocoo()
    n = len(rest)
    incidence = sp.csr_matrix((np.ones(W.nnz), (W.row, np.arange(W.nnz))), shape=(n, W.nnz))
    laplacian = weights_laplacian(W)
    rest_edges = np.ascontiguousarray(rest[W.row] - rest[W.col])
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    edge_length = median_edge_length(rest, faces) if len(faces) else 1.0
    order = elimination_order(laplacian)
    ordered = laplacian[order][:, order].tocsr()
    ordered.sort_indices()
    return SlidePrecompute(
        rest,
        W.row.astype(np.int64),
        W.col.astype(np.int64),
        W.data.astype(np.float64),
        incidence,
        laplacian,
        rest_edges,
        edge_length,
        Wc.indptr.astype(np.int64),
        order,
        ordered,
    )


def elimination_order(laplacian: sp.csr_matrix) -> np.ndarray:
    """A fill-reducing vertex order [N] for the sparse factorisations of the sliding: METIS's
    nested dissection of the template's vertex graph, computed once. The reduced systems of
    every step share this graph (2 or 3 unknowns per vertex), so their factorisations take
    this order instead of ordering again each step.

    Nested dissection rather than minimum degree: SuperLU's factorisation of the reduced
    system of a step took 67 instead of 95 ms on dfaust-hopping (20,430 unknowns) and 86
    instead of 145 ms on rigid-turn (20,088) in this order, with about as many nonzeros in
    the factors: its separators give SuperLU larger supernodes."""
    n = laplacian.shape[0]
    if n < 2:
        return np.arange(n)
    # the structure of L (explicit zeros too), symmetric, without the diagonal
    coo = sp.coo_matrix(laplacian)
    off = coo.row != coo.col
    if not off.any():
        return np.arange(n)
    rows, cols = np.concatenate([coo.row[off], coo.col[off]]), np.concatenate([coo.col[off], coo.row[off]])
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    graph.sort_indices()
    perm, _ = pymetis.nested_dissection(
        adjacency=pymetis.CSRAdjacency(
            graph.indptr.astype(np.int64), graph.indices.astype(np.int64)
        )
    )
    return np.asarray(perm, dtype=np.int64)


def _tangent_bases(normals: np.ndarray) -> np.ndarray:
    """Orthonormal [M, 3, 2] bases of the planes orthogonal to unit ``normals`` [M, 3]."""
    helper = np.zeros_like(normals)
    smallest = np.argmin(np.abs(normals), axis=1)
    helper[np.arange(len(normals)), smallest] = 1.0
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    return np.stack([t1, t2], axis=2)


@numba.njit(cache=True)
def _reduced_matrix(indptr, indices, data, dims, bases, mu):
    """CSR of ``K = B^T (L (x) I_3 + diag(mu)) B`` over the reduced unknowns: vertex ``v``
    has ``dims[v]`` unknowns (the first columns of ``bases[v]`` [3, 3], orthonormal), block
    ``(v, w)`` is ``L_vw T_v^T T_w`` (+ ``mu_v I`` on the diagonal). Vertices in the order of
    ``L`` (CSR ``indptr, indices, data`` with sorted indices), so the columns come sorted."""
    n = len(dims)
    start = np.zeros(n + 1, dtype=np.int64)
    for v in range(n):
        start[v + 1] = start[v] + dims[v]
    row_ptr = np.zeros(start[n] + 1, dtype=np.int64)
    for v in range(n):
        width = 0
        for e in range(indptr[v], indptr[v + 1]):
            width += dims[indices[e]]
        for a in range(dims[v]):
            row_ptr[start[v] + a + 1] = width
    for r in range(start[n]):
        row_ptr[r + 1] += row_ptr[r]
    cols = np.empty(row_ptr[-1], dtype=np.int32)
    vals = np.empty(row_ptr[-1])
    for v in range(n):
        for a in range(dims[v]):
            k = row_ptr[start[v] + a]
            for e in range(indptr[v], indptr[v + 1]):
                w = indices[e]
                lw = data[e]
                for b in range(dims[w]):
                    dot = (
                        bases[v, 0, a] * bases[w, 0, b]
                        + bases[v, 1, a] * bases[w, 1, b]
                        + bases[v, 2, a] * bases[w, 2, b]
                    )
                    value = lw * dot
                    if w == v and a == b:
                        value += mu[v]
                    cols[k] = start[w] + b
                    vals[k] = value
                    k += 1
    return row_ptr, cols, vals


class ConstrainedSolver:
    """System (5) for one time step: factorised once, solved per iteration by back-substitution.

    Parameters
    ----------
    pre : SlidePrecompute
    normals : ndarray [N, 3]
        Spatial part of ``grad f`` at the vertices at time ``t``.
    offsets : ndarray [N]
        Right sides ``c_i`` of the constraints ``normals_i . p_i = c_i``.
    constrained : ndarray bool [N]
        False where lambda_i = 0 (5.4).
    regularization : float

    The reduced matrix ``B^T (L (x) I_3) B`` is assembled directly in the template's
    elimination order (:func:`elimination_order`) and factorised without pivoting (it is
    symmetric positive definite).
    """

    def __init__(self, pre, normals, offsets, constrained, regularization):
        n = len(pre.rest)
        norm = np.linalg.norm(normals, axis=1)
        constrained = constrained & (norm > 1e-12)
        unit = normals / np.maximum(norm, 1e-300)[:, None]
        self.anchor = np.zeros((n, 3))
        self.anchor[constrained] = (offsets[constrained] / norm[constrained])[:, None] * unit[
            constrained
        ]
        # per vertex an orthonormal basis whose first dims columns span its unknowns: the
        # constraint plane (2 columns) or all of space (3)
        self.bases = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        self.bases[constrained, :, :2] = _tangent_bases(unit[constrained])
        self.dims = np.where(constrained, 2, 3)
        diag = pre.laplacian.diagonal()
        self.mu_vertex = regularization * np.where(diag > 0, diag, max(diag.mean(), 1e-12))
        self.mu = np.repeat(self.mu_vertex, 3)
        self.laplacian = pre.laplacian
        self.order = pre.order
        L = pre.ordered_laplacian
        dims = self.dims[self.order]
        row_ptr, cols, vals = _reduced_matrix(
            L.indptr.astype(np.int64),
            L.indices.astype(np.int64),
            L.data,
            dims,
            np.ascontiguousarray(self.bases[self.order]),
            self.mu_vertex[self.order],
        )
        size = len(row_ptr) - 1
        # symmetric: its CSR arrays are its CSC arrays
        K = sp.csc_matrix((vals, cols, row_ptr), shape=(size, size))
        self.factor = spla.splu(
            K, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
        self._unknown = np.arange(3)[None, :] < dims[:, None]  # [N, 3] in elimination order
        self.constrained = constrained
        self._La = pre.laplacian @ self.anchor + self.mu_vertex[:, None] * self.anchor

    @property
    def L3(self) -> sp.csr_matrix:
        """``L (x) I_3 + diag(mu)`` [3N, 3N] (the full system's stiffness; for checks)."""
        return sp.kron(self.laplacian, sp.identity(3), format="csr") + sp.diags(self.mu)

    def solve(self, rhs: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """Positions [N, 3] minimising ``P^T L P - 2 rhs.P`` (+ Tikhonov towards ``reference``)
        under the constraints."""
        r = rhs + self.mu_vertex[:, None] * reference - self._La
        reduced = np.einsum("nab,na->nb", self.bases, r)[self.order][self._unknown]
        u = np.zeros((len(r), 3))
        u[self._unknown] = self.factor.solve(reduced)
        moved = np.empty_like(u)
        moved[self.order] = u
        return self.anchor + np.einsum("nab,nb->na", self.bases, moved)


class SlideStep(NamedTuple):
    """Diagnostics of one sliding step (``registered``: the large-motion registration ran
    and was kept; ``unexplained``: the fraction of the frame's points the rigid prediction
    left unexplained, nan without a registration or data)."""

    time: float
    constrained: int
    energy: float
    max_constraint_residual: float
    registered: bool = False
    unexplained: float = float("nan")


def _still_normals(gradient, dt, normals, limit):
    """``normals`` [N, 3] (the frame surface's gradients at the guess) with, at the vertices
    where the 4D implicit's zero set moves less than ``limit`` (input units) in this step (its
    normal speed ``|f_t| dt / |grad_x f|``, from its ``gradient`` [N, 4] at the guess), the
    direction of ``grad_x f`` instead, at the same length (see
    :attr:`SlideOptions.still_normals`)."""
    length = np.maximum(np.linalg.norm(gradient[:, :3], axis=1), 1e-12)
    still = np.abs(gradient[:, 3]) * abs(dt) < limit * length
    out = normals.copy()
    scale = np.linalg.norm(normals[still], axis=1) / length[still]
    out[still] = gradient[still, :3] * scale[:, None]
    return out


def slide_step(
    pre: SlidePrecompute,
    field: Field4D,
    vertices: np.ndarray,
    time: float,
    next_time: float,
    *,
    options: SlideOptions,
    data_tree: cKDTree | None = None,
    velocity: np.ndarray | None = None,
    diagnostics: bool = False,
    patches: np.ndarray | None = None,
    surface=None,
    registration: ArapIcp | None = None,
    registration_velocity: np.ndarray | None = None,
    previous_registration: tuple[bool, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, SlideStep]:
    """One step of section 5: ``vertices`` at ``time`` -> positions at ``next_time``.

    ``velocity`` [N, 3] (optional): the previous step's vertex velocities; the projection of
    the initial guess then starts from ``vertices + dt * velocity`` (constant-velocity
    prediction, beyond the paper) instead of ``vertices``.

    ``surface`` (optional): the :class:`~fourd.methods.kinematic.framesurface.FrameSurface`
    of the input frame at ``next_time`` (the data term): the rigid prediction is then one
    global motion iterated ``data_rigid_iterations`` times against the frame's points (the
    vertices near them weighted 1, the others 0), and the projections and constraint (2) use
    the frame's surface where it has points and ``f(., next_time)`` elsewhere.

    ``registration`` (optional, with ``surface``): the large-motion registration of the
    template. It runs after the rigid prediction when that leaves enough of the frame's
    points unexplained (:func:`~.register.registration_due`, given the previous data step's
    ``previous_registration = (kept, unexplained fraction)``, None for none), and its result
    is kept when it explains more of them. It starts from ``vertices + dt *
    registration_velocity`` when that is given [N, 3] (the previous step's vertex
    velocities), else from the prediction.

    Returns ``(positions [N, 3], constrained [N] bool, diagnostics)``.
    """
    n = len(vertices)
    epsilon = options.epsilon or 2.0 * pre.edge_length
    max_step = options.max_step or 4.0 * pre.edge_length
    dt = next_time - time
    start = vertices if velocity is None else vertices + dt * velocity
    if surface is None:
        target = _implicit_target(field, next_time)
        rigid_iterations, groups = options.rigid_iterations, patches
    else:
        target = _data_target(field, surface, next_time)
        rigid_iterations, groups = options.data_rigid_iterations, None
    sample = None  # the vertices the global rigid motion is fitted to first (None: all)
    if groups is None and 0 < options.rigid_samples < n:
        sample = np.linspace(0, n - 1, options.rigid_samples).astype(np.int64)
    values, grad = value_and_gradient(field, vertices, _field_times(time, n))
    normals = grad[:, :3]
    offsets = np.einsum("ij,ij->i", normals, vertices) - dt * grad[:, 3]
    if options.residual_correction:
        offsets -= values
    tolerance = options.projection_tolerance * pre.edge_length
    if options.rigid_guess:
        # constraint residual of the start positions, to first order
        residual = np.einsum("ij,ij->i", normals, start) - offsets
        # from every vertex: a squashing ellipsoid's symmetric motion cancels only over all of
        # them (from the sample, the flow test's vertices came back 0.060 radii off, not 0.034)
        start = rigid_prediction(start, normals, residual, neighbours=0)
        # Gauss-Newton on the target itself: point-to-plane ICP against the implicit (or the
        # frame's points), stopped once no vertex moves by more than a tenth of the projection
        # tolerance (on the data the steps shrink about tenfold each, so what is left is far
        # below it; at the tolerance itself, horse-gallop and touching-spheres moved more).
        # A global motion is fitted to the sample first, its last steps to every vertex.
        stages = [(None, rigid_iterations)]
        if sample is not None:
            refine = min(options.rigid_refine_iterations, rigid_iterations)
            stages = [(sample, rigid_iterations - refine), (None, refine)]
        for fit, count in stages:
            for _ in range(count):
                values_next, grad_next, weights = target(start if fit is None else start[fit])
                moved = rigid_prediction(
                    start, grad_next, values_next, groups=groups, weights=weights, sample=fit
                )
                converged = np.abs(moved - start).max() < 0.1 * tolerance
                start = moved
                if converged:
                    break
    registered_step, before = False, float("nan")
    guess = None  # the projection of 5.1, when a rejected registration already made it
    if registration is not None and surface is not None and len(surface.points):
        before = registration.unexplained(start, surface.points)
        if registration_due(before, previous_registration, registration.options):
            # from the prediction, or from the previous step's motion carried on
            # (RegisterOptions.constant_velocity) when that explains more of the frame
            seed = start
            if registration_velocity is not None:
                carried = vertices + dt * registration_velocity
                seed = registration.seed(start, carried, surface.points, before)
            registered, after = registration.register_frame(
                seed, surface.points, surface.normals, previous=vertices
            )
            # kept only when it explains more of the frame: where the template cannot
            # follow (a shape that splits) it would stretch the template over both parts
            kept = after < before
            plain = float("nan")
            if kept and after > registration.options.give_up:
                # the paper's step from the prediction, as the registration's rival
                guess = _project(
                    target, start, options.projection_iterations, max_step=max_step,
                    tolerance=tolerance,
                )
                plain = registration.unexplained(guess, surface.points)
                kept = after < plain
            log.debug(
                "t=%g: large-motion registration, unexplained %.3f -> %.3f%s%s",
                next_time, before, after,
                "" if np.isnan(plain) else f" (projected prediction {plain:.3f})",
                "" if kept else " (rejected)",
            )
            if kept:
                start, guess = registered, None
                registered_step = True
    if guess is None:
        guess = _project(
            target, start, options.projection_iterations, max_step=max_step, tolerance=tolerance
        )
    if options.linearize_at == "guess":
        # the same tangential-motion constraint, linearised at the initial guess on
        # f(., t') = 0 instead of at p^t: n' . (p' - g) + f(g, t') = 0 with n' = grad_x f(g, t')
        if surface is not None and options.still_normals > 0:
            implicit = value_and_gradient(field, guess, _field_times(next_time, len(guess)))
            values_g, normals, _ = target(guess, implicit)
            limit = options.still_normals * pre.edge_length
            normals = _still_normals(implicit[1], dt, normals, limit)
        else:
            values_g, normals, _ = target(guess)
        offsets = np.einsum("ij,ij->i", normals, guess) - values_g
    constrained = np.ones(n, dtype=bool)
    if data_tree is not None:
        distance, _ = data_tree.query(guess, k=1, distance_upper_bound=epsilon, workers=-1)
        constrained = np.isfinite(distance)
    if options.projection_limit > 0 and registered_step:
        limit = options.projection_limit * pre.edge_length
        jumped = np.linalg.norm(guess - start, axis=1) > limit
        guess[jumped] = start[jumped]
        constrained &= ~jumped
    solver = ConstrainedSolver(pre, normals, offsets, constrained, options.regularization)
    remembered = with_rest_shape(pre, vertices) if options.previous_shape > 0 else None
    current = guess
    for iteration in range(options.iterations):
        rhs = blended_arap_rhs(pre, current, remembered, options.previous_shape)
        solved = solver.solve(rhs, current)
        if iteration < options.iterations - 1:
            current = solved.copy()
            mask = solver.constrained
            current[mask] = _project(
                target,
                solved[mask],
                options.reprojection_iterations,
                max_step=max_step,
                tolerance=tolerance,
            )
        else:
            current = solved
    residual = np.abs(np.einsum("ij,ij->i", normals, current) - offsets)[solver.constrained]
    if options.project_output:
        mask = solver.constrained
        current = current.copy()
        current[mask] = _project(
            target,
            current[mask],
            options.projection_iterations,
            max_step=max_step,
            tolerance=tolerance,
        )
    info = SlideStep(
        float(next_time),
        int(solver.constrained.sum()),
        arap_energy(pre, current) if diagnostics else float("nan"),
        float(residual.max()) if residual.size else 0.0,
        registered_step,
        before,
    )
    return current, solver.constrained, info


class SlideResult(NamedTuple):
    animation: AnimatedMesh
    steps: list


def slide(
    rest_vertices: np.ndarray,
    faces: np.ndarray,
    field: Field4D,
    times: Sequence[float] | np.ndarray,
    *,
    options: SlideOptions = SlideOptions(),
    data: Sequence[np.ndarray] | None = None,
    return_steps: bool = False,
    surfaces: Sequence | None = None,
):
    """Slide a template along ``field = 0`` through ``times``, as rigidly as possible.

    Parameters
    ----------
    rest_vertices : ndarray [N, 3]
        The template (urshape) at ``times[0]``; it is the first output frame as given.
    faces : ndarray int [F, 3]
    field : Field4D
        Space-time implicit, negative inside, zero on the surface (time in the units of
        ``times``).
    times : array [T], strictly increasing
        Output times; steps go from each to the next (split into ``options.substeps``).
    options : SlideOptions
    data : sequence of T arrays [P_k, 3], optional
        Input points at each output time (the nearest input frame's for in-between times):
        a vertex with no point within ``epsilon`` is unconstrained (lambda = 0) and marked not
        observed (5.4). Without data every vertex is constrained and observed.
    return_steps : bool
        Also return the per-step diagnostics (a :class:`SlideResult`).
    surfaces : sequence of T FrameSurface or None, optional
        The data term: per output time, the surface of the input frame at exactly that time
        (None where there is none); the last sub-step into that time registers, projects and
        constrains observed vertices against it (see :func:`slide_step`).

    Returns
    -------
    AnimatedMesh (``rest`` = the template), or SlideResult when ``return_steps``.

    References
    ----------
    000_00387fefe94cc850.txt section 5; Sorkine & Alexa, As-rigid-as-possible surface
    modeling, SGP 2007.
    """
    rest = np.asarray(rest_vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    times = np.asarray(times, dtype=np.float64).ravel()
    if rest.ndim != 2 or rest.shape[1] != 3 or len(rest) == 0:
        raise ValueError(f"rest_vertices must be [N, 3] and non-empty, got {rest.shape}")
    if len(times) == 0 or np.any(np.diff(times) <= 0):
        raise ValueError("times must be non-empty and strictly increasing")
    if data is not None and len(data) != len(times):
        raise ValueError(f"data must hold one point array per time ({len(times)}), got {len(data)}")
    if surfaces is not None and len(surfaces) != len(times):
        raise ValueError(
            f"surfaces must hold one entry per time ({len(times)}), got {len(surfaces)}"
        )
    pre = slide_precompute(rest, faces)
    epsilon = options.epsilon or 2.0 * pre.edge_length
    trees = None
    if data is not None:
        trees = [cKDTree(np.asarray(d, float).reshape(-1, 3)) if len(d) else None for d in data]

    def observed_at(k, positions):
        if trees is None or trees[k] is None:
            return (
                np.ones(len(positions), dtype=bool)
                if trees is None
                else np.zeros(len(positions), bool)
            )
        distance, _ = trees[k].query(positions, k=1, distance_upper_bound=epsilon, workers=-1)
        return np.isfinite(distance)

    frames = np.empty((len(times), len(rest), 3))
    observed = np.empty((len(times), len(rest)), dtype=bool)
    frames[0] = rest
    observed[0] = observed_at(0, rest)
    current = rest
    motion = None  # the previous step's vertex velocities [N, 3]
    steps = []
    patches = None
    if options.rigid_guess and 1 < options.rigid_neighbours < len(rest):
        # patches of the template (fixed connectivity: neighbours on the template stay so)
        _, patches = cKDTree(rest).query(rest, k=options.rigid_neighbours, workers=-1)
    registration = (
        ArapIcp(pre, faces, options.register, epsilon)
        if options.register is not None and surfaces is not None
        else None
    )
    last_registration = None  # (kept, unexplained fraction) of the previous data step
    for k in progress(range(1, len(times)), desc="sliding", total=len(times) - 1):
        sub = np.linspace(times[k - 1], times[k], options.substeps + 1)
        for s in range(options.substeps):
            nearest = k if (sub[s + 1] - times[k - 1]) > 0.5 * (times[k] - times[k - 1]) else k - 1
            tree = None if trees is None else trees[nearest]
            if trees is not None and tree is None:
                tree = cKDTree(np.full((1, 3), np.inf))
            previous = current
            surface = surfaces[k] if surfaces is not None and s == options.substeps - 1 else None
            current, _, info = slide_step(
                pre,
                field,
                current,
                sub[s],
                sub[s + 1],
                options=options,
                data_tree=tree,
                velocity=motion if options.extrapolate else None,
                diagnostics=return_steps,
                patches=patches,
                surface=surface,
                registration=registration,
                registration_velocity=(
                    motion if registration is not None and options.register.constant_velocity
                    else None
                ),
                previous_registration=last_registration,
            )
            if np.isfinite(info.unexplained):  # nan: no data term or no registration
                last_registration = (info.registered, info.unexplained)
            motion = (current - previous) / (sub[s + 1] - sub[s])
            steps.append(info)
        frames[k] = current
        observed[k] = observed_at(k, current)
    animation = AnimatedMesh(
        faces=faces, vertices=frames, times=times, observed=observed, rest=rest
    )
    return SlideResult(animation, steps) if return_steps else animation
