"""The negative log-posterior of eq. (3): the weighted sum of the likelihood and the priors,
with its gradient and Gauss-Newton Hessian over the unknowns of :class:`~.state.Layout`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import scipy.sparse as sp

from fourd.geometry.sparse_products import csr_product, csr_transpose
from fourd.methods.surfels.anchors import anchor_term
from fourd.methods.surfels.color_guide import guide_term
from fourd.methods.surfels.hessian import planned_derivatives
from fourd.methods.surfels.match import Data, Matches, MatchOptions, match_term
from fourd.methods.surfels.motion import accel_term, rigid_term
from fourd.methods.surfels.smoothness import laplace_term, smooth_normal_term, smooth_position_term
from fourd.methods.surfels.state import Layout, SurfelState, layout, moving_frames
from fourd.methods.surfels.term import keep_columns
from fourd.methods.surfels.topology import Topology

#: Terms whose Jacobian pattern follows the state (their association), never kept.
ASSOCIATED = ("match", "anchor", "guide")

#: The key of the Hessian's kept structure among ``total_energy``'s ``patterns``
#: (:class:`~.hessian.HessianPlan`).
HESSIAN_PLAN = "hessian"


@dataclass(frozen=True)
class Weights:
    """Weights of the terms of eq. (3); 0 leaves a term out. Terms on positions are lengths
    squared, terms on normals dimensionless: a normal weight of ``w eps_sampl^2`` balances
    a position weight ``w``. The defaults keep the data term only (the method's defaults are
    not chosen yet).

    match : float
        Multiplies the data weights ``omega`` (eq. 5).
    smooth_position, smooth_normal : float
        ``w_smooth^(1)``, ``w_smooth^(2)`` (eq. 6, 7).
    laplace : float
        ``w_Laplace`` (eq. 8; the paper: 10% of the position weight).
    rigid, rigid_normal : float
        ``w_rigid`` on neighbour offsets and on normals (eq. 9).
    accel, accel_normal : float
        ``w_accel`` on positions and on normals (eq. 10).
    anchor : float
        Multiplies the video anchors' weights (:mod:`.anchors`, beyond the paper).
    guide : float
        Multiplies the colour guides' weights (:mod:`.color_guide`, beyond the paper).
    """

    match: float = 1.0
    smooth_position: float = 0.0
    smooth_normal: float = 0.0
    laplace: float = 0.0
    rigid: float = 0.0
    rigid_normal: float = 0.0
    accel: float = 0.0
    accel_normal: float = 0.0
    anchor: float = 0.0
    guide: float = 0.0

    def __post_init__(self):
        for field in fields(self):
            if not getattr(self, field.name) >= 0:
                raise ValueError(f"weight {field.name} must not be negative")


@dataclass(frozen=True)
class Energy:
    """Eq. (3) at a state.

    value : float
    terms : dict[str, float]
        Value of each term included (``match``, ``smooth_position``, ..., ``accel``).
    gradient : float64 [n] or None
    hessian : csr_matrix [n, n] or None
        Gauss-Newton approximation (sum of ``2 J^T J``), its entries on and above the
        diagonal only (the rest by symmetry: half the memory, and the conjugate gradients'
        products read half, :func:`~fourd.geometry.sparse_products.symmetric_multiply`).
    """

    value: float
    terms: dict
    gradient: np.ndarray | None
    hessian: sp.csr_matrix | None


def total_energy(
    state: SurfelState,
    topology: Topology,
    data: Data,
    matches: Matches,
    weights: Weights | None = None,
    match: MatchOptions | None = None,
    *,
    derivatives: bool = True,
    columns: np.ndarray | None = None,
    urshape: bool = False,
    patterns: dict | None = None,
    shared: dict | None = None,
) -> Energy:
    """Eq. (3) with the association ``matches`` held fixed (default weights and options:
    :class:`Weights`, :class:`~.match.MatchOptions`).

    With ``urshape`` frame 0 is the urshape (sec. 3.2): a frame without data that the
    rigidity prior ties to every other frame (:func:`~.motion.rigid_term`), in place of the
    ties between consecutive frames; the acceleration prior leaves it out.

    ``columns`` (int [k], sorted unknowns of the layout) restricts the gradient [k] and
    Hessian [k, k] to those unknowns (the others held fixed): the Jacobians lose the other
    columns before ``J^T J`` is formed, which is what makes a local optimisation cheap. The
    priors then leave out their frames, steps and triples of frames that touch none of those
    unknowns (:func:`prior_reach`): constants, so the value is eq. (3) up to a constant (the
    data of frames that do not move is the caller's to leave out, as
    :func:`~.optimizer.gauss_newton` does).

    ``patterns`` (a dict, empty at first) keeps the priors' Jacobian patterns
    (:class:`~.term.Pattern`, of ``columns`` only) between calls on the same topology,
    layout and ``columns``, so that later calls assemble values only; it must not outlive
    them. With the data term and no other associated one, it keeps the Hessian's structure
    too (:class:`~.hessian.HessianPlan`, under :data:`HESSIAN_PLAN`). ``shared`` (a dict,
    empty at first) keeps the same patterns of every column, for calls on the same
    topology, layout and ``urshape`` with other ``columns`` (the hole filling's frames, one
    after the other)."""
    w = weights or Weights()
    match = match or MatchOptions()
    d = derivatives
    kept = {} if patterns is None or not derivatives else patterns
    lay = layout(state)
    restrict = columns is not None and not np.array_equal(columns, np.arange(lay.size))
    reach = prior_reach(lay, columns if restrict else None, urshape=urshape)

    def pattern(name: str):
        # the pattern of these columns, else made from the one of every column kept for
        # other columns with the same reach
        if name not in kept and derivatives and shared and (name, reach.key) in shared:
            full = shared[name, reach.key]
            kept[name] = full.keep_columns(columns) if restrict else full
        return kept.get(name)

    parts = {}
    if w.match > 0:
        parts["match"] = match_term(state, data, matches, w.match, match, derivatives=d)
    surface = topology.along_surface  # the shape priors' neighbours
    shape_priors = (
        ("smooth_position", smooth_position_term),
        ("smooth_normal", smooth_normal_term),
        ("laplace", laplace_term),
    )
    for name, prior in shape_priors:
        if getattr(w, name) > 0 and _any(reach.frames):
            parts[name] = prior(
                state,
                surface,
                getattr(w, name),
                derivatives=d,
                pattern=pattern(name),
                frames=reach.frames,
            )
    if (w.rigid > 0 or w.rigid_normal > 0) and state.frames > 1 and _any(reach.steps):
        parts["rigid"] = rigid_term(
            state,
            topology,
            w.rigid,
            w.rigid_normal,
            derivatives=d,
            urshape=urshape,
            pattern=pattern("rigid"),
            steps=reach.steps,
        )
    if w.anchor > 0 and data.anchors is not None and state.frames > 1:
        parts["anchor"] = anchor_term(
            state, data.anchors, w.anchor, topology.radius, derivatives=d
        )
    if w.guide > 0 and data.guides is not None:
        parts["guide"] = guide_term(state, data.guides, w.guide, derivatives=d)
    first = 1 if urshape else 0
    if (w.accel > 0 or w.accel_normal > 0) and state.frames - first > 2 and _any(reach.centres):
        parts["accel"] = accel_term(
            state, w.accel, w.accel_normal, derivatives=d, first=first,
            pattern=pattern("accel"), centres=reach.centres,
        )
    values = {name: part.value for name, part in parts.items()}
    total = float(sum(values.values()))
    if not derivatives:
        return Energy(total, values, None, None)
    for name, part in parts.items():
        if name not in ASSOCIATED and name not in kept:
            if shared is not None:
                shared[name, reach.key] = part.pattern
            kept[name] = part.pattern.keep_columns(columns) if restrict else part.pattern
    jacobians = {name: part.jacobian for name, part in parts.items()}
    if restrict:
        # the priors assembled from kept patterns have their columns already
        for name, jacobian in jacobians.items():
            if jacobian.shape[1] != len(columns):
                jacobians[name] = keep_columns(jacobian, columns)
    priors = [name for name in parts if name not in ASSOCIATED]
    if patterns is not None and priors and [n for n in parts if n in ASSOCIATED] == ["match"]:
        # the data term's rows within their surfels' blocks, the priors' patterns kept: the
        # Hessian's structure is kept between the calls too
        data_jacobian, data_residuals = jacobians["match"], parts["match"].residuals
        prior_jacobians = [jacobians[name] for name in priors]
        prior_residuals = np.concatenate([parts[name].residuals for name in priors])
        # the list passed is the priors' Jacobians' last reference (let go once read)
        parts.clear()
        jacobians.clear()
        planned = planned_derivatives(
            data_jacobian,
            data_residuals,
            prior_jacobians,
            prior_residuals,
            tuple(kept[name] for name in priors),
            kept.get(HESSIAN_PLAN),
            lay,
            columns if restrict else None,
        )
        gradient, hessian, kept[HESSIAN_PLAN] = planned
        return Energy(total, values, gradient, hessian)
    # one Jacobian of every term, so that J^T J is formed once (a sum of the terms' Hessians
    # allocates each partial sum)
    residuals = np.concatenate([np.zeros(0)] + [part.residuals for part in parts.values()])
    width = len(columns) if restrict else lay.size
    jacobian = sp.vstack([sp.csr_matrix((0, width))] + list(jacobians.values()), format="csr")
    parts.clear()
    jacobians.clear()
    transposed = csr_transpose(jacobian)
    gradient = 2.0 * (transposed @ residuals)
    # on all cores (scipy's product runs on one): the top merges and the final optimisation
    # run alone
    hessian = csr_product(transposed, jacobian, upper=True)
    hessian.data *= 2.0
    return Energy(total, values, gradient, hessian)


@dataclass(frozen=True)
class PriorReach:
    """Where the priors touch the moving unknowns (:func:`prior_reach`); None: everywhere.

    frames : int [F] or None
        The frames of the shape priors (eq. 6-8).
    steps : int [K] or None
        The steps of the rigidity prior (eq. 9).
    centres : int [C] or None
        The middle frames of the acceleration prior's triples (eq. 10).
    """

    frames: np.ndarray | None
    steps: np.ndarray | None
    centres: np.ndarray | None

    @property
    def key(self) -> bytes:
        """The three, for the patterns kept between calls (``total_energy``'s ``shared``)."""
        return b"|".join(
            b"all" if r is None else r.tobytes() for r in (self.frames, self.steps, self.centres)
        )


def prior_reach(lay: Layout, columns: np.ndarray | None, *, urshape: bool = False) -> PriorReach:
    """The frames, steps and triples of frames whose priors' rows touch one of the unknowns
    ``columns`` (int [k] of ``lay``; None: all); the other rows depend on held unknowns
    alone. A frame moves when one of its positions or normal offsets does; a rigidity step
    when its rotation or either frame it joins (the urshape for every step, with
    ``urshape``) does; a triple when any of its three frames does."""
    if columns is None:
        return PriorReach(None, None, None)
    frames, steps = moving_frames(lay, columns)
    origin = np.zeros(len(steps), dtype=np.int64) if urshape else np.arange(len(steps))
    steps = steps | frames[origin] | frames[1:]
    middle = np.arange(2 if urshape else 1, lay.frames - 1)
    centres = frames[middle - 1] | frames[middle] | frames[middle + 1]
    reach = [
        None if np.all(touched) else indices[touched]
        for touched, indices in (
            (frames, np.arange(lay.frames)),
            (steps, np.arange(len(steps))),
            (centres, middle),
        )
    ]
    return PriorReach(*reach)


def _any(indices: np.ndarray | None) -> bool:
    """Whether a reach (:class:`PriorReach`) holds anything: None is all."""
    return indices is None or len(indices) > 0
