"""Large-motion registration of the template to one input frame's points: as-rigid-as-possible
ICP with correspondences both ways (beyond the paper).

Why: the paper's initial guess (5.1) projects vertices onto ``f(., t') = 0`` along the normals.
When a limb moves farther between two frames than its own width (crane's kick: up to 14% of
the diagonal per kept frame, several limb widths), the space-time surface does not connect
the two poses, the projection snaps the limb onto whatever surface is nearest, and the
tracking loses it for the rest of the sequence. Registering the template to the frame's own
points first brings the limb to its new place; the sliding step then proceeds as before.

Each iteration, with ``r`` shrinking geometrically from ``start_radius`` to ``end_radius``
(in median edge lengths):

* every vertex takes the tangent-plane projection of its nearest input point within ``r``
  whose normal agrees with the vertex normal (model to data);
* every input point within ``r`` of a vertex with an agreeing normal pulls its nearest vertex
  towards it (data to model: the points of a limb that moved away pull the limb);
* the vertices minimise ``E_ARAP + w sum_i |p_i - y_i|^2`` with ``y_i`` the mean of the
  vertex's targets (its current position when it has none) and the ARAP rotations of the
  current positions (Sorkine & Alexa's local / global step), over-relaxed.

``w`` is the same for every vertex, so the matrix ``L + w I`` is factorised once per sequence
and every iteration is one back-substitution. A small ``w`` (stiff ARAP) measured best on
crane: the limb moves as a whole instead of its vertices sliding to the nearest points
(``exp`` runs, 20k samples, correspondence mean / last, 30 plain iterations: w = 1: 0.020 /
0.034, 0.1: 0.016 / 0.024, 0.01: 0.012 / 0.017, 0.003: 0.011 / 0.015). A few last iterations
at the smallest radius use a ten times larger ``w`` (a second factorisation) so that the
template also follows what does not bend rigidly before the projection of the sliding step.

It runs only on frames where the ordinary prediction leaves more than ``threshold`` of the
input points unexplained (:func:`unexplained_fraction`), or more than ``follow_threshold``
while a fast motion goes on or starts (:func:`registration_due`), and its result is kept
only when it explains more of them (:func:`fourd.methods.kinematic.sliding.slide_step`).
Run on every frame, the nearest-point pulls act as friction against the tangential motion
that the space-time constraint recovers on smooth turning shapes (rigid-turn correspondence
0.0016 -> 0.0069); on a shape that splits in two it would stretch the template over both
parts.

References
----------
Sorkine, Alexa: As-rigid-as-possible surface modeling, SGP 2007; Besl, McKay: A method for
registration of 3-D shapes, PAMI 1992 (ICP); Li, Sumner, Pauly: Global correspondence
optimization for non-rigid registration of depth scans, SGP 2008 (both-ways correspondences).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from fourd.geometry.factors import TriangularFactors, solve_ordered, unpermuted_factors
from fourd.geometry.meshes import vertex_components
from fourd.geometry.neighbors import bucket_grid, nearest_within
from fourd.geometry.normals import vertex_normals
from fourd.methods.kinematic.arap import blended_arap_rhs, with_rest_shape

log = logging.getLogger("fourd.methods.kinematic.register")

#: k-d trees of the registration (the first iteration's searches, and the few later queries
#: whose warm-start bound spans too many grid cells): sliding-midpoint splits build in half
#: the time of scipy's balanced default and query as fast (10,000 vertices: build 1.25
#: against 2.41 ms, 7,400 queries 3.9 against 4.1 ms; the same nearest neighbours).
TREE_OPTIONS = {"balanced_tree": False, "leafsize": 32}
#: Cell side of the grids of the warm-started nearest-point searches, in median edge lengths
#: of the template.
GRID_CELL = 2.0
#: Largest search radius, in grid cells, up to which the unanswered queries of a warm-started
#: search without a k-d tree scan the grid instead of building one (the template's vertices
#: move every iteration, so their tree would be built anew each time: 303 builds, 0.36 s of
#: crane's 2.45 s of registration).
REST_GRID_REACH = 6


@dataclass(frozen=True)
class RegisterOptions:
    """Parameters of the large-motion registration.

    Attributes
    ----------
    threshold : float
        Run on a frame when more than this fraction of its points lie farther than
        ``unexplained_distance`` from every predicted vertex (above 1: never).
    follow_threshold, rise : float
        Also run when more than ``follow_threshold`` of the points are unexplained and either
        the previous data step kept its registration (the fast motion goes on) or the
        fraction rose by more than ``rise`` since the previous step (a limb starts to move).
        A fraction that creeps up slowly is surface turning into view, which no template
        vertex can explain; registering it drags the template along the nearest points
        against the sliding (``rigid-turn`` with ``threshold`` 0.01: correspondence 0.0012 /
        0.0017 -> 0.021 / 0.063, its fraction rising by at most 0.002 per step to 0.022).
        Measured (``exp`` runs, 20k samples, correspondence mean / last, ``follow_threshold``
        0.03, which leaves only ``threshold``, -> 0.01): crane 0.0078 / 0.0172 -> 0.0073 /
        0.0119 (frames 12, 13 and 19 registered, 1.5-2.5% unexplained), held-out crane-130
        0.0121 / 0.0187 -> 0.0114 / 0.0178, crane-90 0.0100 / 0.0150 -> 0.0096 / 0.0151,
        squash-ball 0.0248 / 0.0167 -> 0.0242 / 0.0150, horse-gallop 0.0089 / 0.0043 ->
        0.0087 / 0.0043; the same on rigid-turn, dfaust-hopping, bending-arm,
        touching-spheres, elephant-gallop and crane-50. The hysteresis alone (no ``rise``)
        gave crane 0.0076 / 0.0167; both at 0.005 crane 0.0073 / 0.0112 and bending-arm
        0.0186 / 0.0317 (0.0202 / 0.0338), but squash-ball 0.0328 / 0.0457.
    retry_iterations, retry_radius : int, float
        When a registration still leaves more than ``threshold`` of the points unexplained,
        a second one of ``retry_iterations`` stiff iterations from ``retry_radius`` median
        edges (and the ``refine_iterations``) continues from its result, kept when it
        explains more (0 iterations: none). The stiff template converges slowly (see
        ``relaxation``), and where a limb has moved far it stops short of it: on the
        held-out crane-50, whose kicking leg was lost from frame 8 to 16 (``exp`` runs, 20k
        samples, Chamfer / completeness-95 / correspondence mean / last, without -> with):
        0.0045 / 0.0301 / 0.0260 / 0.0339 -> 0.0038 / 0.0165 / 0.0236 / 0.0303 (0.65 ->
        0.78-0.86 s/frame); elephant-gallop 0.0069 / 0.0418 / 0.0236 / 0.0373 -> 0.0068 /
        0.0407 / 0.0239 / 0.0388; squash-ball correspondence 0.0242 / 0.0150 -> 0.0241 /
        0.0145. The same on crane, crane-90, crane-130, horse-gallop, bending-arm and
        touching-spheres; crane, dfaust-hopping and rigid-turn never retry (their
        registrations explain the frame). A full second pass (30 iterations from 40 edges)
        gave crane-50 0.0227 / 0.0308 at 1.1 s/frame; one pass with ``relaxation`` 0.95
        instead of a retry 0.0235 / 0.0306 but horse-gallop 0.0087 / 0.0043 -> 0.0132 /
        0.0094.
    give_up : float
        A registration (with its retry) that explains more than the prediction but still
        leaves more than this fraction of the points unexplained is kept only when it also
        explains more than the paper's step, the projection of 5.1 from the prediction. The
        template then cannot follow the frame (a shape that split), and the stiff ICP may
        settle on a part of the points, from which the next frames' registrations go on. On
        splitting-blob the retry (7629064) took the template onto one of the two parts from
        frame 11 on (registrations kept at 41-49% unexplained): Chamfer / completeness-95
        0.0150 / 0.0202 before the retry, 0.0394 / 0.472 with it (``exp`` runs, 20k
        samples). Shorter versions of the scene (10,000 samples; the split in 10 frames at
        128 rays, 12 at 160, 20 at 256), completeness-95 with the retry and nothing more /
        registrations leaving more than 0.2 never kept / this rule: 0.13 / 0.34 / 0.11,
        0.19 / 0.15 / 0.15, 0.47 / 0.011 / 0.013. Only splitting-blob and crane-50 (within
        0.0001) changed on the bench.
    unexplained_distance : float
        In units of the data radius ``epsilon`` of the sliding (5.4: at least 2 median edge
        lengths, and 3 point spacings in ``kinematic``), so that a template finer than the
        data does not count the gaps between points.
    iterations : int
        ARAP-ICP iterations with the stiff weight ``weight``.
    relaxation : float
        Over-relaxation ``rho`` of every global step after the first, ``x <- s + rho (s - x)``
        with ``s`` the step's solution: with a stiff ARAP the plain iterates creep towards the
        limb's new place by a near-constant step (about 0.15 edge per iteration at the end
        of 30 on crane). ``rho = 0.8`` with 15 iterations measured as 30 plain ones.
    weight : float
        Data weight ``w`` relative to the mean diagonal of the template's Laplacian.
    start_radius, end_radius : float
        Correspondence radius of the first and last stiff iteration, in median edge lengths.
        A limb of crane's held-out frames moves up to 15 edges per kept frame, so the
        search starts well beyond that (``exp`` runs, crane from frame 90, correspondence
        mean / last: 15 iterations from 20 edges 0.0244 / 0.0366, 30 from 40 edges 0.0143 /
        0.0225; with 30 iterations the registration costs about 0.8 s per frame).
    refine_iterations, refine_weight : int, float
        Plain iterations after the stiff ones, at ``end_radius`` with the softer data weight
        ``refine_weight`` (same units as ``weight``): the stiff template leaves a misfit of
        a few edges where the shape did not move rigidly, and the projection that follows
        would close it by moving vertices along their normals, crushing and stretching the
        template there.
    normal_agreement : float
        Least cosine between a vertex normal and an input point's normal for them to match.
    point_stride : int
        Every ``point_stride``-th point of the frame takes part.
    constant_velocity : bool
        Start from the previous frame's positions moved on by the previous step's vertex
        velocities (the sliding passes them) when those leave fewer of the frame's points
        unexplained than the rigid prediction, else from the prediction. Along a smooth limb
        the nearest-point correspondences recover only part of the motion (60-85% on the
        fastest-moving tenth of crane's held-out frames 90-128, registering from the true
        previous pose), and what they miss, a slide along the limb, nothing brings back; carried over
        from the previous step, most of it is there from the start. Always carried, a
        reversal overshoots (squash-ball correspondence 0.163 / 0.232 against 0.064 / 0.086
        when chosen).
    previous_shape : float
        Weight ``b`` of the previous frame's shape in the registration's ARAP term: the term
        is ``(1 - b) E_ARAP(rest) + b E_ARAP(previous)``, two energies over the same
        cotangent weights (so ``L + w I`` and its factorisation stay), each with its own
        rotations. With 0 (the default) the template's rest shape alone: a stiff ARAP-ICP then
        pulls every registered frame back towards the rest shape, against the stretch and
        twist of real skin (the crane truth's edges are 8% longer or shorter than at frame 0
        in the median at the kick's height, and its upper arms twist 54-64 degrees about
        themselves; ``experiments/arap_basin.py``). ``exp`` runs (20k samples, correspondence
        mean / last frame) 0 -> 0.5: crane 0.0073 / 0.0119 -> 0.0068 / 0.0115 (at f8321eb
        0.0073 / 0.0120 -> 0.0070 / 0.0125), crane-50 0.0235 / 0.0304 -> 0.0192 / 0.0227, crane-90 0.0096 / 0.0151 -> 0.0089 / 0.0110,
        crane-130 0.0114 / 0.0178 -> 0.0112 / 0.0168, horse-gallop 0.0087 / 0.0043 ->
        0.0077 / 0.0038; but bending-arm 0.0202 / 0.0338 -> 0.0219 / 0.0391,
        touching-spheres 0.0163 / 0.0205 -> 0.0177 / 0.0295, elephant-gallop 0.0239 ->
        0.0248, and splitting-blob completeness-95 0.0112 -> 0.22 (the remembered shape
        keeps the template stretched over both parts). 1 (the previous shape alone) lost the
        arms on crane (0.0109 / 0.0354).
    stop_explained : float
        End the stiff iterations as soon as no more than this fraction of the frame's points
        is unexplained (:meth:`ArapIcp.unexplained`, checked before each), then refine (0:
        all ``iterations``, the default). A diagnostic of where the registration's error
        comes from (``experiments/registration_oracle.py --stop-explained``; crane,
        correspondence mean / last frame): from the true positions 0.0058 / 0.0080 with all
        iterations and 0.0043 / 0.0058 with 0.005, as good as replacing each registration by
        the truth (0.0042 / 0.0060), so the stiff iterations themselves leave a right state,
        pulled towards the rest shape's ARAP minimum; but from the method's own seeds 0.0073
        / 0.0120 -> 0.0091 / 0.0141 (0.001: 0.0077 / 0.0130): there the full relaxation is
        what corrects the seed.
    """

    threshold: float = 0.03
    unexplained_distance: float = 1.5
    iterations: int = 30
    relaxation: float = 0.8
    weight: float = 0.003
    start_radius: float = 40.0
    end_radius: float = 3.0
    normal_agreement: float = 0.3
    point_stride: int = 2
    refine_iterations: int = 3
    refine_weight: float = 0.03
    constant_velocity: bool = True
    follow_threshold: float = 0.01
    rise: float = 0.01
    retry_iterations: int = 10
    retry_radius: float = 10.0
    give_up: float = 0.2
    previous_shape: float = 0.0
    stop_explained: float = 0.0

    def __post_init__(self):
        if self.iterations < 1 or self.point_stride < 1:
            raise ValueError(
                f"iterations and point_stride must be at least 1, got {self.iterations} and "
                f"{self.point_stride}"
            )
        if not (
            self.weight > 0 and self.refine_weight > 0 and self.start_radius > 0
            and self.end_radius > 0
        ):
            raise ValueError("weight, refine_weight, start_radius and end_radius must be positive")
        if not 0.0 <= self.previous_shape < 1.0:
            raise ValueError(f"previous_shape must lie in [0, 1), got {self.previous_shape}")
        if not 0.0 <= self.stop_explained < 1.0:
            raise ValueError(f"stop_explained must lie in [0, 1), got {self.stop_explained}")
        if self.give_up < 0:
            raise ValueError(f"give_up must not be negative, got {self.give_up}")
        if self.retry_iterations < 0 or self.retry_radius <= 0:
            raise ValueError("retry_iterations must not be negative, retry_radius positive")
        if self.refine_iterations < 0:
            raise ValueError(f"refine_iterations must not be negative, got {self.refine_iterations}")
        if not 0.0 <= self.relaxation < 1.0:
            raise ValueError(f"relaxation must lie in [0, 1), got {self.relaxation}")
        if self.threshold < 0 or self.follow_threshold < 0 or self.unexplained_distance <= 0:
            raise ValueError(
                "threshold and follow_threshold must not be negative, unexplained_distance "
                "positive"
            )


@numba.njit(cache=True)
def _targets(x, vn, points, normals, nearest_point, nearest_vertex, agreement, out):
    """Per vertex the mean of its targets (its own position where it has none) into ``out``
    [N, 3]: the tangent-plane projection of ``x`` [N, 3] onto its nearest point
    (``nearest_point`` [N], -1 for none) and the points whose nearest vertex it is
    (``nearest_vertex`` [P], -1 for none), each only where the vertex normal ``vn`` and the
    point's normal agree (cosine above ``agreement``)."""
    n = len(x)
    count = len(points)
    projected = np.zeros((n, 3))
    counts = np.zeros(n)
    for v in range(n):
        p = nearest_point[v]
        if p < 0:
            continue
        m0 = normals[p, 0]
        m1 = normals[p, 1]
        m2 = normals[p, 2]
        if vn[v, 0] * m0 + vn[v, 1] * m1 + vn[v, 2] * m2 > agreement:
            along = (x[v, 0] - points[p, 0]) * m0 + (x[v, 1] - points[p, 1]) * m1 + (
                x[v, 2] - points[p, 2]
            ) * m2
            projected[v, 0] = x[v, 0] - m0 * along
            projected[v, 1] = x[v, 1] - m1 * along
            projected[v, 2] = x[v, 2] - m2 * along
            counts[v] = 1.0
    pulls = np.zeros((n, 3))
    for p in range(count):
        v = nearest_vertex[p]
        if v < 0:
            continue
        if vn[v, 0] * normals[p, 0] + vn[v, 1] * normals[p, 1] + vn[v, 2] * normals[p, 2] > agreement:
            pulls[v, 0] += points[p, 0]
            pulls[v, 1] += points[p, 1]
            pulls[v, 2] += points[p, 2]
            counts[v] += 1.0
    for v in range(n):
        if counts[v] > 0:
            for a in range(3):
                out[v, a] = (projected[v, a] + pulls[v, a]) / counts[v]
        else:
            for a in range(3):
                out[v, a] = x[v, a]


@numba.njit(cache=True)
def _farthest_move(before, after):
    """Largest distance between the rows of ``before`` and ``after`` [N, 3]."""
    most = 0.0
    for i in range(len(before)):
        d0 = after[i, 0] - before[i, 0]
        d1 = after[i, 1] - before[i, 1]
        d2 = after[i, 2] - before[i, 2]
        most = max(most, d0 * d0 + d1 * d1 + d2 * d2)
    return np.sqrt(most)


@numba.njit(cache=True, parallel=True)
def _warm_bounds(queries, targets, previous, lower, radius, out):
    """:func:`_nearest`'s search bounds into ``out`` [Q]: the distance to the previous
    nearest target (rounded up) or ``radius`` where that is farther or there was none, -1
    (no search) where the lower bound reaches ``radius``."""
    for q in numba.prange(len(queries)):
        t = previous[q]
        if t >= 0:
            d0 = queries[q, 0] - targets[t, 0]
            d1 = queries[q, 1] - targets[t, 1]
            d2 = queries[q, 2] - targets[t, 2]
            out[q] = min(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) * (1.0 + 1e-9), radius)
        elif lower[q] >= radius:
            out[q] = -1.0
        else:
            out[q] = radius


def _nearest(queries, targets, grid, tree, previous, lower, radius):
    """The nearest of ``targets`` [T, 3] within ``radius`` of each of ``queries`` [Q, 3],
    exactly, warm-started from the previous iteration's answer.

    ``previous`` [Q] is that answer (-1: none) and ``lower`` [Q] a lower bound on the
    distance to every target where it was none. A query with a previous nearest searches
    only as far as that target now lies (on the targets' ``grid``, a
    :func:`~fourd.geometry.neighbors.bucket_grid`: mostly a few cells); one whose lower
    bound reaches ``radius`` has none; the rest go to the k-d tree ``tree`` of the targets
    (None: built only then, and not at all when ``radius`` is at most
    :data:`REST_GRID_REACH` cells: the grid is then scanned that far instead).

    Returns the nearest [Q] (-1: none) and the lower bounds [Q]: ``radius`` where none was
    found by a search, the old bound where none was searched, 0 elsewhere. The caller lowers
    them by how far the queries and targets move before the next call.
    """
    bounds = np.empty(len(queries))
    _warm_bounds(queries, targets, previous, lower, float(radius), bounds)
    nearest, unsearched = nearest_within(grid[0], grid[1], grid[2], queries, bounds)
    rest = np.flatnonzero(unsearched)
    if len(rest) and tree is None and radius <= REST_GRID_REACH * grid[2]:
        # a few hundred queries (outliers, points the template has not reached): a wider
        # scan of the grid costs less than building a k-d tree of the targets
        reach = 2 * REST_GRID_REACH + 2
        nearest[rest], unsearched = nearest_within(
            grid[0], grid[1], grid[2], queries[rest], bounds[rest], max_cells=reach**3
        )
        rest = rest[unsearched]
    if len(rest):
        if tree is None:
            tree = cKDTree(targets, **TREE_OPTIONS)
        _, found = tree.query(queries[rest], k=1, distance_upper_bound=radius)
        nearest[rest] = np.where(found < len(targets), found, -1)
    lower = np.where(nearest >= 0, 0.0, np.where(bounds < 0, lower, radius))
    return nearest, lower


def registration_due(
    unexplained: float, previous: tuple[bool, float] | None, options: RegisterOptions
) -> bool:
    """Whether to register a frame whose rigid prediction leaves the fraction
    ``unexplained`` of its points unexplained, given the previous data step's ``(kept,
    unexplained)`` (None: no previous data step); see :class:`RegisterOptions`."""
    if unexplained > options.threshold:
        return True
    if previous is None or unexplained <= options.follow_threshold:
        return False
    kept, before = previous
    return bool(kept or unexplained - before > options.rise)


def unexplained_fraction(vertices: np.ndarray, points: np.ndarray, distance: float) -> float:
    """Fraction of ``points`` [P, 3] farther than ``distance`` from every one of ``vertices``
    [N, 3] (searched on a grid of cells ``distance`` wide: a k-d tree built per call cost
    about four times as much)."""
    if len(points) == 0 or len(vertices) == 0:
        return 0.0
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    grid, origin, cell = bucket_grid(vertices, distance)
    found, unsearched = nearest_within(
        grid, origin, cell, points, np.full(len(points), float(distance))
    )
    rest = np.flatnonzero(unsearched)
    if len(rest):  # cells coarsened to keep the grid small
        d, _ = cKDTree(vertices).query(points[rest], k=1, distance_upper_bound=distance)
        found[rest] = np.where(np.isfinite(d), 0, -1)
    return float(np.mean(found < 0))


class ArapIcp:
    """The registration for one template (:func:`fourd.methods.kinematic.arap_solve.slide_precompute`
    output ``pre`` and its ``faces``); ``L + w I`` is factorised on first use, once per data
    weight (the stiff and the refining one). ``epsilon``: the data radius of the sliding (0: 2
    median edge lengths)."""

    def __init__(
        self, pre, faces: np.ndarray, options: RegisterOptions = RegisterOptions(),
        epsilon: float = 0.0,
    ):
        self.pre = pre
        self.distance = options.unexplained_distance * (epsilon or 2.0 * pre.edge_length)
        self.faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        self.options = options
        diagonal = pre.laplacian.diagonal()
        scale = float(diagonal.mean()) if len(diagonal) else 0.0
        self.weight = options.weight * scale
        self.refine_weight = options.refine_weight * scale
        self._factors: dict[float, object] = {}
        self.component_count, self.components = vertex_components(self.faces, len(diagonal))

    def _solve(self, rhs: np.ndarray, weight: float) -> np.ndarray:
        """``(L + weight I)^-1 rhs`` [N, 3]: SuperLU's factors, back-substituted for the three
        columns at once (:mod:`fourd.geometry.factors`; SuperLU's own solve where it
        pivoted)."""
        if weight not in self._factors:
            n = self.pre.laplacian.shape[0]
            matrix = (self.pre.ordered_laplacian + weight * sp.identity(n)).tocsc()
            lu = spla.splu(
                matrix, permc_spec="NATURAL", diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
            self._factors[weight] = unpermuted_factors(lu) or lu
        order = self.pre.order
        factor = self._factors[weight]
        if isinstance(factor, TriangularFactors):
            return solve_ordered(factor, rhs, order)
        out = np.empty_like(rhs)
        out[order] = factor.solve(np.ascontiguousarray(rhs[order]))
        return out

    def unexplained(self, vertices: np.ndarray, points: np.ndarray) -> float:
        """:func:`unexplained_fraction` of every ``point_stride``-th of ``points`` at
        ``unexplained_distance``."""
        return unexplained_fraction(vertices, points[:: self.options.point_stride], self.distance)

    def seed(
        self, predicted: np.ndarray, carried: np.ndarray, points: np.ndarray, before: float
    ) -> np.ndarray:
        """Start of the registration [N, 3], per connected component of the template either
        its ``predicted`` or its ``carried`` positions [N, 3] (see ``constant_velocity``),
        whichever leaves fewer of the frame's ``points`` unexplained; ``before`` is the
        :meth:`unexplained` fraction of ``predicted``.

        The whole template is carried when that explains more, then each further component
        (a hoof or a leg that the first frame's surface cut off) is tried the other way on
        its own. The components move independently, and a velocity taken over a step in
        which one was lost and found again is a jump: carried on, it sets the piece on a
        part that another component already explains, from where nothing brings it back
        (horse-gallop with ``flow`` ``coherent=true``, a hoof of 146 vertices flew off at
        0.75 input units per frame from frame 15).
        """
        seed = predicted
        fraction = self.unexplained(carried, points)
        if fraction < before:
            seed, before = carried, fraction
        if self.component_count < 2:
            return seed
        other = carried if seed is predicted else predicted
        for c in range(self.component_count):
            members = self.components == c
            trial = seed.copy()
            trial[members] = other[members]
            fraction = self.unexplained(trial, points)
            if fraction < before:
                seed, before = trial, fraction
        return seed

    def register_frame(
        self, vertices: np.ndarray, points: np.ndarray, normals: np.ndarray,
        previous: np.ndarray | None = None,
    ) -> tuple[np.ndarray, float]:
        """:meth:`register` and, when that leaves more than ``threshold`` of the points
        unexplained, the retry of :class:`RegisterOptions` from its result, kept when it
        explains more. Returns the positions [N, 3] and their :meth:`unexplained` fraction."""
        o = self.options
        registered = self.register(vertices, points, normals, previous=previous)
        after = self.unexplained(registered, points)
        if after > o.threshold and o.retry_iterations > 0:
            again = self.register(
                registered, points, normals,
                iterations=o.retry_iterations, start_radius=o.retry_radius, previous=previous,
            )
            unexplained = self.unexplained(again, points)
            log.debug("registration retried: unexplained %.3f -> %.3f", after, unexplained)
            if unexplained < after:
                registered, after = again, unexplained
        return registered, after

    def register(
        self,
        vertices: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        *,
        iterations: int | None = None,
        start_radius: float | None = None,
        previous: np.ndarray | None = None,
    ) -> np.ndarray:
        """Positions [N, 3] of the template registered from ``vertices`` [N, 3] to the frame's
        ``points`` [P, 3] with unit outward ``normals`` [P, 3]; ``iterations`` and
        ``start_radius`` replace the options' stiff iterations and first radius (a retry);
        ``previous`` [N, 3] is the previous frame's shape (``previous_shape``; None: the rest
        shape alone).

        The nearest-point pairs of every iteration after the first are searched warm-started
        from the previous iteration's (:func:`_nearest`): the same pairs as k-d tree queries
        (two per iteration, on two threads before), in about 60% of the registration's time
        (one crane registration replayed, medians of 7, interleaved: 0.44-0.45 -> 0.27-0.30
        s; the output equal bit for bit)."""
        o = self.options
        iterations = o.iterations if iterations is None else iterations
        start_radius = o.start_radius if start_radius is None else start_radius
        x = np.array(vertices, dtype=np.float64, copy=True)
        points_all = points
        stride = self.options.point_stride
        points = np.ascontiguousarray(points[::stride], dtype=np.float64)
        normals = np.ascontiguousarray(normals[::stride], dtype=np.float64)
        if len(points) == 0:
            return x
        cell = GRID_CELL * self.pre.edge_length
        point_grid = bucket_grid(points, cell)
        tree = cKDTree(points, **TREE_OPTIONS)
        to_point, point_lower = np.full(len(x), -1), np.zeros(len(x))
        to_vertex, vertex_lower = np.full(len(points), -1), np.zeros(len(points))
        remembered = None
        if previous is not None and o.previous_shape > 0:
            remembered = with_rest_shape(self.pre, previous)
        stiff = True  # until stop_explained ends the stiff iterations
        for it in range(iterations + o.refine_iterations):
            if it < iterations and o.stop_explained > 0:
                stiff = stiff and self.unexplained(x, points_all) > o.stop_explained
                if not stiff:
                    continue
            radius = self._radius(it, iterations, start_radius)
            # model to data: each vertex's nearest point (its tangent-plane projection is a
            # target); data to model: each point's nearest vertex (the point pulls it)
            to_point, point_lower = _nearest(
                x, points, point_grid, tree, to_point, point_lower, radius
            )
            to_vertex, vertex_lower = _nearest(
                points, x, bucket_grid(x, cell), None, to_vertex, vertex_lower, radius
            )
            before = x
            x = self._step(it, iterations, x, points, normals, to_point, to_vertex, remembered)
            # the points stay, so no distance between a point and a vertex changes by more
            # than the farthest move of a vertex
            move = _farthest_move(before, x)
            point_lower = np.maximum(point_lower - move, 0.0)
            vertex_lower = np.maximum(vertex_lower - move, 0.0)
        return x

    def _radius(self, it: int, iterations: int, start_radius: float) -> float:
        """Correspondence radius of iteration ``it``: from ``start_radius`` to ``end_radius``
        edges geometrically over the ``iterations`` stiff ones, then constant."""
        end = self.options.end_radius
        fraction = min(it / max(iterations - 1, 1), 1.0)
        return self.pre.edge_length * start_radius * (end / start_radius) ** fraction

    def _step(self, it, iterations, x, points, normals, to_point, to_vertex, remembered=None):
        """One ARAP-ICP iteration ``it`` (stiff while below ``iterations``) from positions
        ``x`` [N, 3], given each vertex's nearest point ``to_point`` [N] and each point's
        nearest vertex ``to_vertex`` [P] (-1: none within the radius); ``remembered``: the
        template's precomputation with the previous frame's edges (``previous_shape``)."""
        o = self.options
        refining = it >= iterations
        weight = self.refine_weight if refining else self.weight
        vn = vertex_normals(x, self.faces)
        shape = blended_arap_rhs(self.pre, x, remembered, o.previous_shape)
        targets = np.empty((len(x), 3))
        _targets(x, vn, points, normals, to_point, to_vertex, o.normal_agreement, targets)
        rhs = shape + weight * targets
        solved = self._solve(rhs, weight)
        # stiff steps over-relaxed: with a stiff ARAP the iterates creep along one direction
        return solved + o.relaxation * (solved - x) if 0 < it and not refining else solved
