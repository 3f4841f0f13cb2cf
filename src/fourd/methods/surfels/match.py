"""The likelihood (eq. 5): each data point attracted to its nearest surfel of the same frame
by the squared distance to the surface, truncated for outliers.

The squared distance to the surface near a surfel ``s`` with normal ``n`` is approximated as
Pottmann and Hofer do near the surface: the distance to the tangent plane, plus an optional
share ``beta`` of the distance to ``s`` itself,
``rho^2 = (1 - beta) <d - s, n>^2 + beta |d - s|^2``. The share defaults to 0 (the tangential
curvature of the squared distance vanishes at the surface): it holds each surfel at the
centroid of its own data in every frame, which fights the correspondences (a rigid motion
recovered 2.6 degrees off of 4 with ``beta = 0.1``, 0.15 off with 0); with the priors off it
is what keeps surfels from sliding. Points with ``rho`` beyond the cutoff ``tau`` contribute the constant
``omega tau^2`` and no gradient (a Gaussian mixed with a uniform outlier density).

Two regimes (:class:`MatchOptions`): ``"global"`` for already aligned surfaces cuts off at
``eps_top``; ``"alignment"`` (the assembly's first alignment of frames, large motion) cuts off
at the 85th percentile of the distances, rejects points whose normal is more than 45 degrees
off the surfel's, and prunes points failing the doublet test (the data point nearest their
surfel lies farther than ``eps_top`` from them).

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.1 "Likelihood" (``001_3fedd1c3a0ac4198.txt``).
Pottmann, Hofer: Geometry of the squared distance function to curves and surfaces,
Visualization and Mathematics III, 2003.
Pauly, Mitra, Giesen, Gross, Guibas: Example-based 3D scan completion, SGP 2005 (doublets).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from functools import cached_property

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from fourd.geometry.neighbors import bucket_grid, nearest_within
from fourd.methods.surfels.anchors import AnchorData
from fourd.methods.surfels.color_guide import GuideData
from fourd.methods.surfels.state import SurfelState, layout, tangent_basis
from fourd.methods.surfels.term import Term, index_type, term


@dataclass(frozen=True)
class Data:
    """The data points of all frames, flattened.

    points : float64 [D, 3]
    frames : int64 [D]
        Frame of each point, ``0 <= frame < T``.
    weights : float64 [D]
        ``omega``: inverse noise variance in normal direction (1 / length^2).
    normals : float64 [D, 3] or None
        Oriented data normals (only the ``"alignment"`` regime's angle test uses them).
    anchors : AnchorData or None
        The video's anchors between consecutive frames (:mod:`.anchors`).
    guides : GuideData or None
        Where the colours say surfels are (:mod:`.color_guide`).
    """

    points: np.ndarray
    frames: np.ndarray
    weights: np.ndarray
    normals: np.ndarray | None = None
    anchors: AnchorData | None = None
    guides: GuideData | None = None

    def __post_init__(self):
        count = len(self.points)
        if self.points.shape != (count, 3) or self.frames.shape != (count,):
            raise ValueError("data points must be [D, 3] with one frame index each")
        if self.weights.shape != (count,) or np.any(self.weights < 0):
            raise ValueError("data weights must be [D] and not negative")
        if self.normals is not None and self.normals.shape != (count, 3):
            raise ValueError("data normals must be [D, 3]")

    def of_frames(self, frames: np.ndarray) -> Data:
        """The points of the frames true in ``frames`` (bool [T]) only, with the anchors of
        the pairs that join one of them and the guides in one (frame indices unchanged);
        ``self`` when that is everything."""
        frames = np.asarray(frames, dtype=bool)
        points = frames[self.frames]
        anchors = guides = None
        if self.anchors is not None:
            anchors = frames[self.anchors.frames] | frames[self.anchors.frames + 1]
        if self.guides is not None:
            guides = frames[self.guides.frames]
        if all(keep is None or keep.all() for keep in (points, anchors, guides)):
            return self
        return Data(
            self.points[points],
            self.frames[points],
            self.weights[points],
            None if self.normals is None else self.normals[points],
            None if anchors is None or not anchors.any() else _kept(self.anchors, anchors),
            None if guides is None or not guides.any() else _kept(self.guides, guides),
        )

    def in_frame(self, frame: int) -> np.ndarray:
        """The indices of frame ``frame``'s points, int64 [P_t] ascending (sorted into frames
        once: every association asks)."""
        return self._by_frame[frame] if frame < len(self._by_frame) else np.zeros(0, np.int64)

    def tree(self, frame: int) -> cKDTree:
        """The k-d tree of frame ``frame``'s points, built on first use and kept: the
        alignment regime's doublet test asks at every association, and the points do not
        move."""
        if frame not in self._trees:
            self._trees[frame] = cKDTree(self.points[self.in_frame(frame)])
        return self._trees[frame]

    @cached_property
    def _by_frame(self) -> list[np.ndarray]:
        order = np.argsort(self.frames, kind="stable")
        return np.split(order, np.cumsum(np.bincount(self.frames))[:-1]) if len(order) else []

    @cached_property
    def _trees(self) -> dict[int, cKDTree]:
        return {}


def _kept(rows, keep: np.ndarray):
    """``rows`` (a dataclass of arrays, one row each) with the rows true in ``keep`` only."""
    return replace(rows, **{field.name: getattr(rows, field.name)[keep] for field in fields(rows)})


def frame_data(
    frames: list[np.ndarray],
    *,
    weight: float = 1.0,
    normals: list[np.ndarray] | None = None,
    anchors: AnchorData | None = None,
) -> Data:
    """:class:`Data` from one array of points [P_t, 3] per frame, all with ``weight``, and
    the ``anchors`` between the frames."""
    points = np.concatenate([np.asarray(f, dtype=np.float64).reshape(-1, 3) for f in frames])
    index = np.repeat(np.arange(len(frames)), [len(f) for f in frames])
    stacked = None if normals is None else np.concatenate(normals).astype(np.float64)
    return Data(
        points, index.astype(np.int64), np.full(len(points), float(weight)), stacked, anchors
    )


@dataclass(frozen=True)
class MatchOptions:
    """How data points are associated with surfels and which are let through.

    regime : str
        ``"global"`` (cut off at ``eps_top``) or ``"alignment"`` (percentile cutoff, angle
        and doublet tests).
    tangential : float
        ``beta``, the share of the point-to-surfel distance in the squared distance (0: the
        tangent plane only).
    percentile : float
        The alignment cutoff: this percentile of the distances (paper: 85).
    max_angle : float
        Alignment: degrees between data and surfel normals beyond which a point is rejected.
    doublet : float
        Alignment: the doublet tolerance in ``eps_top``.
    """

    regime: str = "global"
    tangential: float = 0.0
    percentile: float = 85.0
    max_angle: float = 45.0
    doublet: float = 1.0

    def __post_init__(self):
        if self.regime not in ("global", "alignment"):
            raise ValueError(f"regime must be global or alignment, got {self.regime!r}")
        if not 0 <= self.tangential <= 1 or not 0 < self.percentile <= 100:
            raise ValueError("need 0 <= tangential <= 1 and 0 < percentile <= 100")


@dataclass(frozen=True)
class Matches:
    """Data points associated with surfels (fixed during one Gauss-Newton step).

    surfels : int64 [D]
        Nearest surfel of each data point in its frame.
    active : bool [D]
        Points within the cutoff and passing the regime's tests.
    cutoff : float
        ``tau`` (input units).
    """

    surfels: np.ndarray
    active: np.ndarray
    cutoff: float


def associate(
    state: SurfelState,
    data: Data,
    scale: float,
    options: MatchOptions | None = None,
    *,
    previous: Matches | None = None,
) -> Matches:
    """Nearest surfel of every data point in its frame, and which points count.

    Parameters
    ----------
    scale : float
        ``eps_top`` (input units): the global cutoff and the doublet tolerance's unit.
    options : MatchOptions, optional
    previous : Matches, optional
        An association of the same data with the same surfels at a nearby state (the
        optimiser's state before a step): each point's nearest surfel is then searched only
        as far as its previous one now lies (:func:`nearest_from`), with the same result.
    """
    options = options or MatchOptions()
    if data.frames.size and (data.frames.min() < 0 or data.frames.max() >= state.frames):
        raise ValueError(f"data frames must lie in 0..{state.frames - 1}")
    surfels = np.zeros(len(data.points), dtype=np.int64)
    doublet = np.ones(len(data.points), dtype=bool)
    alignment = options.regime == "alignment"
    for t in range(state.frames):
        here = data.in_frame(t)
        if not len(here):
            continue
        points = data.points[here]
        if previous is not None and len(previous.surfels) == len(data.points):
            found = nearest_from(state.positions[t], points, previous.surfels[here], scale)
        else:
            _, found = cKDTree(state.positions[t]).query(points, workers=-1)
        surfels[here] = found
        if alignment:
            # the tree holds this frame's points in the order of ``here``
            _, nearest = data.tree(t).query(state.positions[t], workers=-1)
            back = points[nearest[found]]
            doublet[here] = np.linalg.norm(back - points, axis=1) <= options.doublet * scale
    rho = np.sqrt(_squared_distance(state, data, surfels, options.tangential))
    if alignment:
        cutoff = float(np.percentile(rho, options.percentile)) if len(rho) else 0.0
        active = (rho <= cutoff) & doublet
        if data.normals is not None:
            normals = state.normals[data.frames, surfels]
            cosine = np.einsum("da,da->d", data.normals, normals) / np.maximum(
                np.linalg.norm(data.normals, axis=1) * np.linalg.norm(normals, axis=1), 1e-300
            )
            active &= cosine >= np.cos(np.radians(options.max_angle))
    else:
        cutoff = float(scale)
        active = rho <= cutoff
    return Matches(surfels, active, cutoff)


def nearest_from(
    positions: np.ndarray, points: np.ndarray, guess: np.ndarray, cell: float
) -> np.ndarray:
    """The nearest of ``positions`` [S, 3] to each of ``points`` [P, 3] (int64 [P]), searched
    on a grid of ``cell`` (input units) only as far as each point's ``guess`` [P] (an index
    into ``positions``) lies: the nearest is no farther. Exact, as a k-d tree's query (ties
    aside), and several times faster where the guesses are near (a step's association
    from the one before: crane's 16-frame merge, 229,375 points against 1,398 surfels a
    frame, 59 ms in a k-d tree); points whose guess is far go to a k-d tree."""
    guess = np.asarray(guess, dtype=np.int64)
    offset = points - positions[guess]
    # a hair past the guess, so that rounding cannot leave it outside its own bound
    bounds = np.sqrt(np.einsum("pa,pa->p", offset, offset)) * (1.0 + 1e-9) + 1e-300
    grid, origin, side = bucket_grid(positions, cell)
    found, unsearched = nearest_within(grid, origin, side, points, bounds)
    missing = found < 0
    found[missing & ~unsearched] = guess[missing & ~unsearched]
    if unsearched.any():
        _, found[unsearched] = cKDTree(positions).query(points[unsearched], workers=-1)
    return found


def _squared_distance(state, data, surfels, tangential):
    """``rho^2`` [D] of every data point to its surfel (normals made unit)."""
    out = np.empty(len(data.points))
    _rho_squared(
        np.ascontiguousarray(data.points, dtype=np.float64),
        np.asarray(data.frames, dtype=np.int64),
        np.asarray(surfels, dtype=np.int64),
        np.ascontiguousarray(state.positions, dtype=np.float64),
        np.ascontiguousarray(state.normals, dtype=np.float64),
        float(tangential),
        out,
    )
    return out


@numba.njit(cache=True, nogil=True)
def _rho_squared(points, frames, surfels, positions, normals, tangential, out):
    """:func:`_squared_distance` in one pass (numpy's gathers and temporaries took 18 ms for
    crane's 16-frame merge, 229,375 points, against 2.5 ms here; the dot products summed in
    order, where numpy's ``einsum`` rounds differently by up to 1e-18)."""
    for d in range(len(points)):
        f = frames[d]
        s = surfels[d]
        o0 = points[d, 0] - positions[f, s, 0]
        o1 = points[d, 1] - positions[f, s, 1]
        o2 = points[d, 2] - positions[f, s, 2]
        n0 = normals[f, s, 0]
        n1 = normals[f, s, 1]
        n2 = normals[f, s, 2]
        length = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-300)
        along = o0 * (n0 / length) + o1 * (n1 / length) + o2 * (n2 / length)
        out[d] = (1.0 - tangential) * along**2 + tangential * (o0 * o0 + o1 * o1 + o2 * o2)


def match_term(
    state: SurfelState,
    data: Data,
    matches: Matches,
    weight: float = 1.0,
    options: MatchOptions | None = None,
    *,
    derivatives: bool = True,
) -> Term:
    """Eq. (5), truncated: ``weight sum_d omega_d min(rho_d^2, tau^2)`` with the association
    and active set of ``matches``; residuals ``[D_active, 4]`` (plane, then point offsets)."""
    options = options or MatchOptions()
    beta = options.tangential
    active = np.flatnonzero(matches.active)
    omega = weight * data.weights[active]
    frames, surfels = data.frames[active], matches.surfels[active]
    offset = data.points[active] - state.positions[frames, surfels]
    normals = state.normals[frames, surfels]
    plane = np.sqrt(omega * (1.0 - beta))
    point = np.sqrt(omega * beta)
    residuals = np.concatenate(
        [(plane * np.einsum("da,da->d", offset, normals))[:, None], point[:, None] * offset],
        axis=1,
    )
    inactive = ~matches.active
    constant = weight * float(np.sum(data.weights[inactive])) * matches.cutoff**2
    if not derivatives:
        return term(residuals, None, constant)
    lay = layout(state)
    basis = tangent_basis(state.normals)[frames, surfels]
    tilt = plane[:, None] * np.einsum("da,dab->db", offset, basis)
    # each point's rows in CSR order, built directly (its association changes every step, so
    # no pattern is kept): the plane's row on the surfel's position and normal offset, then,
    # with a tangential share, the point offsets' identity on its position
    position = lay.position(frames, surfels)
    normal = lay.normal(frames, surfels)
    entries = [-plane[:, None] * normals, tilt]
    columns = [position[:, None] + np.arange(3), normal[:, None] + np.arange(2)]
    if beta > 0:
        entries.append(np.broadcast_to(-point[:, None], (len(active), 3)))
        columns.append(position[:, None] + np.arange(3))
    width = 8 if beta > 0 else 5
    starts = width * np.arange(len(active))[:, None] + (
        np.array([0, 5, 6, 7]) if beta > 0 else np.array([0, 5, 5, 5])
    )
    indptr = np.append(starts.ravel(), width * len(active))
    index = index_type(lay.size, len(active) * width)
    jacobian = sp.csr_matrix(
        (
            np.concatenate(entries, axis=1).ravel(),
            np.concatenate(columns, axis=1).astype(index).ravel(),
            indptr.astype(index),
        ),
        shape=(residuals.size, lay.size),
    )
    jacobian.has_sorted_indices = True
    return term(residuals, jacobian, constant)
