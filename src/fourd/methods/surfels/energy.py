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
from fourd.methods.surfels.match import Data, Matches, MatchOptions, match_term
from fourd.methods.surfels.motion import accel_term, rigid_term
from fourd.methods.surfels.smoothness import laplace_term, smooth_normal_term, smooth_position_term
from fourd.methods.surfels.state import SurfelState, layout
from fourd.methods.surfels.term import keep_columns
from fourd.methods.surfels.topology import Topology

#: Terms whose Jacobian pattern follows the state (their association), never kept.
ASSOCIATED = ("match", "anchor", "guide")


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
    columns before ``J^T J`` is formed, which is what makes a local optimisation cheap.

    ``patterns`` (a dict, empty at first) keeps the priors' Jacobian patterns
    (:class:`~.term.Pattern`, of ``columns`` only) between calls on the same topology,
    layout and ``columns``, so that later calls assemble values only; it must not outlive
    them. ``shared`` (a dict, empty at first) keeps the same patterns of every column, for
    calls on the same topology, layout and ``urshape`` with other ``columns`` (the hole
    filling's frames, one after the other)."""
    w = weights or Weights()
    match = match or MatchOptions()
    d = derivatives
    kept = {} if patterns is None or not derivatives else patterns
    size = layout(state).size
    restrict = columns is not None and not np.array_equal(columns, np.arange(size))
    for name, full in (shared or {}).items() if derivatives else ():
        if name not in kept:
            kept[name] = full.keep_columns(columns) if restrict else full
    parts = {}
    if w.match > 0:
        parts["match"] = match_term(state, data, matches, w.match, match, derivatives=d)
    surface = topology.along_surface  # the shape priors' neighbours
    if w.smooth_position > 0:
        parts["smooth_position"] = smooth_position_term(
            state, surface, w.smooth_position, derivatives=d, pattern=kept.get("smooth_position")
        )
    if w.smooth_normal > 0:
        parts["smooth_normal"] = smooth_normal_term(
            state, surface, w.smooth_normal, derivatives=d, pattern=kept.get("smooth_normal")
        )
    if w.laplace > 0:
        parts["laplace"] = laplace_term(
            state, surface, w.laplace, derivatives=d, pattern=kept.get("laplace")
        )
    if (w.rigid > 0 or w.rigid_normal > 0) and state.frames > 1:
        parts["rigid"] = rigid_term(
            state,
            topology,
            w.rigid,
            w.rigid_normal,
            derivatives=d,
            urshape=urshape,
            pattern=kept.get("rigid"),
        )
    if w.anchor > 0 and data.anchors is not None and state.frames > 1:
        parts["anchor"] = anchor_term(
            state, data.anchors, w.anchor, topology.radius, derivatives=d
        )
    if w.guide > 0 and data.guides is not None:
        parts["guide"] = guide_term(state, data.guides, w.guide, derivatives=d)
    first = 1 if urshape else 0
    if (w.accel > 0 or w.accel_normal > 0) and state.frames - first > 2:
        parts["accel"] = accel_term(
            state, w.accel, w.accel_normal, derivatives=d, first=first, pattern=kept.get("accel")
        )
    values = {name: part.value for name, part in parts.items()}
    total = float(sum(values.values()))
    if not derivatives:
        return Energy(total, values, None, None)
    for name, part in parts.items():
        if name not in ASSOCIATED and name not in kept:
            if shared is not None:
                shared[name] = part.pattern
            kept[name] = part.pattern.keep_columns(columns) if restrict else part.pattern
    # one Jacobian of every term, so that J^T J is formed once (a sum of the terms' Hessians
    # allocates each partial sum)
    residuals = np.concatenate([np.zeros(0)] + [part.residuals for part in parts.values()])
    jacobians = [sp.csr_matrix((0, size))] + [part.jacobian for part in parts.values()]
    parts.clear()
    if restrict:
        # the priors assembled from kept patterns have their columns already
        jacobians = [
            jacobian if jacobian.shape[1] == len(columns) else keep_columns(jacobian, columns)
            for jacobian in jacobians
        ]
    jacobian = sp.vstack(jacobians, format="csr")
    del jacobians
    transposed = csr_transpose(jacobian)
    gradient = 2.0 * (transposed @ residuals)
    # on all cores (scipy's product runs on one): the top merges and the final optimisation
    # run alone
    hessian = csr_product(transposed, jacobian, upper=True)
    hessian.data *= 2.0
    return Energy(total, values, gradient, hessian)
