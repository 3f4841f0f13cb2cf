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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.appearance.guide import anchor_guide
from fourd.cache import Chain, report_resumed
from fourd.geometry.field import Field4D
from fourd.methods.kinematic.arap import arap_energy, blended_arap_rhs, with_rest_shape
from fourd.methods.kinematic.arap_solve import ConstrainedSolver, SlidePrecompute, slide_precompute
from fourd.methods.kinematic.projection import (
    _data_target,
    _field_times,
    _implicit_target,
    _project,
    value_and_gradient,
)
from fourd.methods.kinematic.register import ArapIcp, RegisterOptions, registration_due
from fourd.methods.kinematic.rigid import rigid_prediction
from fourd.progress import progress

log = logging.getLogger("fourd.methods.kinematic.sliding")

#: The step relaxes again towards a late guide (the colour guide) only when its weights add up
#: to at least this share of the vertices.
LATE_GUIDE_SUPPORT = 0.01


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
        with 4 iterations and 0.0027 / 0.0032 with 1 (``experiments/registration_oracle.py
        --slide-iterations``). See the ``kinematic`` method's ``slide_memory`` for what 0.8
        measured.
    anchor_gate : float
        Anchors farther than this many template edges from the step's prediction count less
        (Gaussian weight; 0: all count fully).
    anchor_pull : float
        Weight of the anchor-guided positions (:mod:`fourd.appearance.guide`) in the as-rigid-as-possible
        solve of each step, in units of each vertex's stiffness (0: they only move the start).
    edge_stiffness : tuple or None
        ``(edges [E, 2], values [E])``: factors on the ARAP weights of those template edges
        (:func:`~fourd.methods.kinematic.arap_solve.slide_precompute`), e.g. the bending
        stiffness learned from a first tracking; None: the cotangent weights alone (the paper).
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
    edge_stiffness: tuple | None = field(default=None, compare=False, repr=False)
    anchor_pull: float = 0.0
    anchor_gate: float = 0.0

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
    guide=None,
    late_guide=None,
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

    ``guide`` (optional): a :class:`~fourd.appearance.guide.Guide` of anchor-guided
    positions, blended into the start after the rigid prediction by its weights (before the
    registration and the projection).

    ``late_guide`` (optional): a function of positions [N, 3] that returns a Guide (the colour
    guide, :mod:`fourd.appearance.color_guide`), called on the step's result, after which the iterations
    run again from there, pulled towards it.

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
    if guide is not None and len(guide.vertices) and options.anchor_gate > 0:
        # an anchor may correct the prediction by about what the tracking drifts in a step;
        # farther off it is more likely the flow's error than the tracking's (shading, fast
        # thin parts), and counts less
        gate = options.anchor_gate * pre.edge_length
        off = np.linalg.norm(guide.positions - start[guide.vertices], axis=1)
        guide = guide._replace(weight=guide.weight * np.exp(-((off / gate) ** 2)))
    if guide is not None and len(guide.vertices):
        start = start.copy()
        w = guide.weight[:, None]
        start[guide.vertices] = (1.0 - w) * start[guide.vertices] + w * guide.positions
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
    remembered = with_rest_shape(pre, vertices) if options.previous_shape > 0 else None

    def relax(current, guide):
        """The rotation / position iterations from ``current``, pulled towards ``guide``."""
        pull = None
        if guide is not None and len(guide.vertices) and options.anchor_pull > 0:
            pull = np.zeros(n)
            pull[guide.vertices] = options.anchor_pull * guide.weight
        solver = ConstrainedSolver(pre, normals, offsets, constrained, options.regularization, pull)
        for iteration in range(options.iterations):
            rhs = blended_arap_rhs(pre, current, remembered, options.previous_shape)
            reference = current
            if pull is not None:
                reference = current.copy()
                reference[guide.vertices] = guide.positions
            solved = solver.solve(rhs, reference)
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
        return current, solver

    current, solver = relax(guess, guide)
    if late_guide is not None:
        # the colour guide reads the frame's colours where the geometry put the vertices, then
        # the iterations run again from there, pulled towards where the colours say
        late = late_guide(current)
        # a guide that pins nothing down (a uniform colour, smooth skin) would only relax again
        if late is not None and late.weight.sum() >= LATE_GUIDE_SUPPORT * n:
            current, solver = relax(current, late)
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
    """What :func:`slide` returns with ``return_steps``: the animation, each sub-step's
    diagnostics, and ``state``, what a sliding that goes on from the last time starts from
    (its ``start``: ``vertices`` [N, 3], ``motion`` [N, 3] when there was a step,
    ``registration`` ``[kept, unexplained]`` when one ran)."""

    animation: AnimatedMesh
    steps: list
    state: dict


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
    checkpoints: Chain | None = None,
    anchors: Sequence | None = None,
    colour_guides: Sequence | None = None,
    start: Mapping[str, np.ndarray] | None = None,
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
    checkpoints : Chain, optional
        The cache entries of the ``T - 1`` steps (:class:`fourd.cache.Chain`, keyed by the
        caller from everything above): each step's frame and the state the next step starts
        from (the motion, the last registration's outcome) are stored as it finishes, and
        the steps already stored are loaded instead of slid again. The result is the same;
        ``return_steps`` then lists the steps slid now.
    anchors : sequence, optional
        Per time, ``(source [M, 3], target [M, 3], confidence [M])`` of the anchor tracks from
        the previous time to this one (entry 0 and unknown steps None): the step starts the
        vertices near them where they went (:func:`~.guide.anchor_guide`).
    colour_guides : sequence, optional
        Per time, a function of the step's result that returns a :class:`~.guide.Guide` (the
        colour guide, :class:`~fourd.appearance.color_guide.PhotometricGuides`), or None: the step then
        relaxes again pulled towards it (``late_guide`` of :func:`slide_step`).
    start : mapping, optional
        Go on from an earlier sliding that ended at ``times[0]``: its :attr:`SlideResult.state`
        (``vertices`` are then the first output frame; ``rest_vertices`` stays the rest
        shape). The result is the same as one sliding over both runs' times.

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
    if checkpoints is not None and len(checkpoints) != len(times) - 1:
        raise ValueError(
            f"checkpoints must hold one key per step ({len(times) - 1}), got {len(checkpoints)}"
        )
    pre = slide_precompute(rest, faces, options.edge_stiffness)
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
    last_registration = None  # (kept, unexplained fraction) of the previous data step
    if start is not None:
        current, motion, last_registration = _from_state(start)
        current = current.reshape(rest.shape)
        frames[0] = current
        observed[0] = observed_at(0, current)
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
    first = 1
    if checkpoints is not None:
        done = checkpoints.prefix()
        for k, entry in enumerate(done, start=1):
            frames[k] = entry["vertices"]
            observed[k] = entry["observed"]
        if done:
            current, motion, last_registration = _from_state(done[-1])
            first = len(done) + 1
            report_resumed(log, f"{len(done)} of {len(times) - 1} slid frames")
    for k in progress(range(first, len(times)), desc="sliding", total=len(times) - first):
        sub = np.linspace(times[k - 1], times[k], options.substeps + 1)
        for s in range(options.substeps):
            nearest = k if (sub[s + 1] - times[k - 1]) > 0.5 * (times[k] - times[k - 1]) else k - 1
            tree = None if trees is None else trees[nearest]
            if trees is not None and tree is None:
                tree = cKDTree(np.full((1, 3), np.inf))
            previous = current
            surface = surfaces[k] if surfaces is not None and s == options.substeps - 1 else None
            guide = late_guide = None
            if anchors is not None and anchors[k] is not None and s == options.substeps - 1:
                source, target, confidence = anchors[k]
                guide = anchor_guide(
                    frames[k - 1], source, target, confidence, radius=2.0 * pre.edge_length
                )
            if colour_guides is not None and s == options.substeps - 1:
                late_guide = colour_guides[k]
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
                guide=guide,
                late_guide=late_guide,
            )
            if np.isfinite(info.unexplained):  # nan: no data term or no registration
                last_registration = (info.registered, info.unexplained)
            motion = (current - previous) / (sub[s + 1] - sub[s])
            steps.append(info)
        frames[k] = current
        observed[k] = observed_at(k, current)
        if checkpoints is not None:
            state = _state(current, motion, last_registration)
            checkpoints.save(k - 1, {**state, "observed": observed[k]})
    animation = AnimatedMesh(
        faces=faces, vertices=frames, times=times, observed=observed, rest=rest
    )
    if not return_steps:
        return animation
    return SlideResult(animation, steps, _state(current, motion, last_registration))


def _state(vertices, motion, registration) -> dict[str, np.ndarray]:
    """What the next step starts from, as arrays (:attr:`SlideResult.state`, the checkpoints)."""
    state = {"vertices": vertices}
    if motion is not None:
        state["motion"] = motion
    if registration is not None:
        state["registration"] = np.array(registration, dtype=np.float64)
    return state


def _from_state(state) -> tuple:
    """``(vertices, motion or None, (kept, unexplained) or None)`` of a :func:`_state`."""
    registration = None
    if "registration" in state:
        kept, unexplained = state["registration"]
        registration = (bool(kept), float(unexplained))
    vertices = np.array(state["vertices"], dtype=np.float64)
    return vertices, state.get("motion"), registration
