"""The video's anchors as a term of eq. (3): each anchor tracked by optical flow from frame
``t`` to ``t + 1`` (:func:`fourd.appearance.anchors`, thesis ``004_f87f5acf96d50b57.txt``
section 5.4.1) asks the surfel nearest its start in frame ``t`` to move as it did,

    E_anchor = w sum_a omega_a |(s_i(a)^{t+1} - s_i(a)^t) - (target_a - source_a)|^2,

truncated at ``eps_top`` as the data term is (eq. 5), with ``i(a)`` the surfel nearest
``source_a`` in frame ``t`` (found again at every state, as
the data term's association is) and ``omega_a`` the anchor's confidence; ``w`` is in 1 /
length^2 (:func:`~.options.energy_weights`: ``anchor_weight / sigma^2``, an anchor as
trusted as a data point at one noise level).

Beyond the paper: the paper's data term (eq. 5) pulls only across the surface, so nothing but
the shape says where along it a surfel went, and on a featureless stretch (a waving sheet, a
twisting limb) the surfels slide. The anchors pull along the surface as well. An anchor's
offset from its surfel (at most about ``eps_sampl``) turning with the surface is left out: at
a few degrees per frame it moves the target by a few hundredths of ``eps_sampl``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.methods.surfels.state import SurfelState, layout
from fourd.methods.surfels.term import Blocks, Term, term

log = logging.getLogger("fourd.methods.surfels.anchors")

#: Anchors are tracked only from where a camera's image has hue texture this many times above
#: its noise (``AnchorOptions.texture``): elsewhere the flow follows the lamps' shading, as
#: ``kinematic`` measured (benchmarks/METHODS.md, ``anchor_texture``).
ANCHOR_TEXTURE = 3.0
#: Tracked from one point per cube of this many point spacings (``AnchorOptions.sources``):
#: a surfel is several spacings across, so denser anchors only repeat each other.
ANCHOR_SOURCES = 2.0


class Forward(NamedTuple):
    """A frame's anchors into the next frame.

    source : float64 [M, 3]
        Points of this frame.
    target : float64 [M, 3]
        Where each went in the next frame.
    confidence : float64 [M]
        In (0, 1) (:class:`fourd.appearance.AnchorPair`).
    """

    source: np.ndarray
    target: np.ndarray
    confidence: np.ndarray

    def reversed(self) -> Forward:
        """The same anchors from the next frame back to this one."""
        return Forward(self.target, self.source, self.confidence)


@dataclass(frozen=True)
class AnchorData:
    """The anchors of the consecutive frame pairs of a state.

    frames : int64 [M]
        The pair's first frame ``t`` of each anchor (``0 <= t < T - 1``).
    source, target : float64 [M, 3]
    weights : float64 [M]
        Each anchor's weight relative to the term's (its confidence).
    """

    frames: np.ndarray
    source: np.ndarray
    target: np.ndarray
    weights: np.ndarray

    def __post_init__(self):
        count = len(self.frames)
        if self.source.shape != (count, 3) or self.target.shape != (count, 3):
            raise ValueError("anchor sources and targets must be [M, 3], one frame each")
        if self.weights.shape != (count,) or np.any(self.weights < 0):
            raise ValueError("anchor weights must be [M] and not negative")

    def shifted(self, frames: int) -> AnchorData:
        """The same anchors with their frame indices moved by ``frames``."""
        return AnchorData(self.frames + frames, self.source, self.target, self.weights)


def pair_anchors(pairs: list) -> AnchorData | None:
    """:class:`AnchorData` from one :class:`Forward` (or None: no anchors) per consecutive
    pair of a state's frames (``pairs[t]`` links frame ``t`` to ``t + 1``), each anchor
    weighted by its confidence; None when there is none."""
    present = [(t, f) for t, f in enumerate(pairs) if f is not None and len(f.source)]
    if not present:
        return None
    return AnchorData(
        np.concatenate([np.full(len(f.source), t, dtype=np.int64) for t, f in present]),
        np.concatenate([f.source for _, f in present]).astype(np.float64),
        np.concatenate([f.target for _, f in present]).astype(np.float64),
        np.concatenate([f.confidence for _, f in present]).astype(np.float64),
    )


def anchor_term(
    state: SurfelState,
    anchors: AnchorData,
    weight: float,
    reach: float,
    *,
    derivatives: bool = True,
) -> Term:
    """``E_anchor`` (module docstring) at ``state``: residuals ``[M, 3]``. An anchor with no
    surfel within ``reach`` (input units) of its source contributes nothing; one whose surfel
    moved farther than ``reach`` from the anchor's move contributes the constant ``w omega_a
    reach^2`` and no gradient (truncated, as the data term is: the flow lifted onto the wrong
    layer of a fold passes the tracking's checks)."""
    lay = layout(state)
    surfels = np.zeros(len(anchors.frames), dtype=np.int64)
    near = np.zeros(len(anchors.frames), dtype=bool)
    for t in np.unique(anchors.frames):
        mine = np.flatnonzero(anchors.frames == t)
        distance, nearest = cKDTree(state.positions[t]).query(anchors.source[mine])
        surfels[mine] = nearest
        near[mine] = distance <= reach
    t, i = anchors.frames, surfels
    gaps = state.positions[t + 1, i] - state.positions[t, i] - (anchors.target - anchors.source)
    inside = np.linalg.norm(gaps, axis=1) <= reach
    outside = weight * reach**2 * float(np.sum(anchors.weights[near & ~inside]))
    root = np.sqrt(weight * anchors.weights * (near & inside))[:, None]
    residuals = root * gaps
    if not derivatives:
        return term(residuals, None, outside)
    blocks = Blocks(residuals.size, lay.size)
    rows = 3 * np.arange(len(t))
    eye = np.eye(3)
    blocks.add(rows, lay.position(t + 1, i), root[:, :, None] * eye, eye > 0)
    blocks.add(rows, lay.position(t, i), -root[:, :, None] * eye, eye > 0)
    return term(residuals, blocks, outside)


def with_video_anchors(frames: list, times, video, names=()) -> list:
    """``frames`` (:class:`~.seeds.FramePoints`, preprocessed) each with the video's anchors
    into the next as ``forward`` (None for the last), tracked on their points (their own outlier
    removal would repeat the cleaning) at ``times``, filmed by ``video``
    (:class:`~fourd.io.video.Video`, one image per camera and frame)."""
    from fourd.appearance.anchor_tracks import cleaned_anchors

    tracked = cleaned_anchors(
        [frame.points for frame in frames],
        times,
        video,
        names,
        texture=ANCHOR_TEXTURE,
        sources=ANCHOR_SOURCES,
    )
    log.info("surfels: anchors from the video: %d over %d frame pairs", tracked.total, len(tracked))
    forward = [Forward(p.source, p.target, p.confidence) for p in tracked] + [None]
    return [frame._replace(forward=f) for frame, f in zip(frames, forward, strict=True)]
