"""The colours' guide as a term of eq. (3): where each surfel's colours say it is in a frame,

    E_guide = w sum_(i, t) omega_i^t |s_i^t - g_i^t|^2,

with ``g_i^t`` the surfel's position in frame ``t`` moved along the surface to where the
colours around it match those its patch had in the frame where it was first observed
(per-surfel Lucas-Kanade on the frame's coloured points,
:func:`fourd.appearance.photometric.photometric_shift`, as ``kinematic``'s colour guide,
:mod:`fourd.appearance.color_guide`), ``omega_i^t = exp(-(u / scale)^2)`` from the shift's
uncertainty ``u`` and ``w`` in 1 / length^2 (:func:`~.options.energy_weights`:
``color_weight / sigma^2``).

Beyond the paper. The video's anchors (:mod:`.anchors`) tie consecutive frames, so their small
errors add up from frame to frame: on bending-arm in printed cloth the surfels themselves (not
the mesh carried from them) drift by about 0.0009 of the diagonal a frame with good anchors,
as ``kinematic`` does with its anchors alone. The colours' reference is one frame, not the
previous one, so what they correct does not accumulate.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import field_for_reads
from fourd.methods.surfels.state import SurfelState, layout
from fourd.methods.surfels.term import Blocks, Term, term

log = logging.getLogger("fourd.methods.surfels.color_guide")


class GuideSettings(NamedTuple):
    """How the guides are found (input units): the Lucas-Kanade's patch ``radius`` and the
    uncertainty ``scale`` that gets weight ``exp(-1)`` (:func:`color_guides`). ``reference``
    (log colours [K, 3], or None) are the first ``K`` surfels' reference colours, carried from
    where they were first found (the streamed run's mesh surfels, from its first window,
    :mod:`.stream`) instead of taken from the first frame at hand that observes them."""

    radius: float
    scale: float
    reference: np.ndarray | None = None


@dataclass(frozen=True)
class GuideData:
    """Where the colours say surfels are.

    frames, surfels : int64 [M]
        The frame and the surfel of each guide.
    targets : float64 [M, 3]
    weights : float64 [M]
        Each guide's weight relative to the term's (its certainty).
    """

    frames: np.ndarray
    surfels: np.ndarray
    targets: np.ndarray
    weights: np.ndarray

    def __post_init__(self):
        count = len(self.frames)
        if self.surfels.shape != (count,) or self.targets.shape != (count, 3):
            raise ValueError("guides need one surfel [M] and one target [M, 3] each")
        if self.weights.shape != (count,) or np.any(self.weights < 0):
            raise ValueError("guide weights must be [M] and not negative")

    def shifted(self, frames: int) -> GuideData:
        """The same guides with their frame indices moved by ``frames``."""
        return GuideData(self.frames + frames, self.surfels, self.targets, self.weights)


def guide_term(
    state: SurfelState, guides: GuideData, weight: float, *, derivatives: bool = True
) -> Term:
    """``E_guide`` (module docstring) at ``state``: residuals ``[M, 3]``."""
    root = np.sqrt(weight * guides.weights)[:, None]
    residuals = root * (state.positions[guides.frames, guides.surfels] - guides.targets)
    if not derivatives:
        return term(residuals, None)
    blocks = Blocks(residuals.size, layout(state).size)
    eye = np.eye(3)
    blocks.add(
        3 * np.arange(len(guides.frames)),
        layout(state).position(guides.frames, guides.surfels),
        root[:, :, None] * eye,
        eye > 0,
    )
    return term(residuals, blocks)


def color_guides(
    state: SurfelState,
    observed: np.ndarray,
    points: list,
    normals: list,
    colors: list,
    settings: GuideSettings,
) -> GuideData | None:
    """The guides of every surfel of ``state`` in every frame with colours.

    Parameters
    ----------
    state : SurfelState
        ``T`` frames of ``S`` surfels.
    observed : bool [T, S]
        Surfels with data in each frame: each takes its reference colours from the first
        frame that observes it (frame 0 for one that none does) and has no guide there.
    points, normals, colors : lists of ``T`` arrays [P_t, 3]
        Each frame's points, their unit normals and colours in [0, 1] (``colors[t]`` None:
        frame ``t`` has none).
    settings : GuideSettings

    Returns None when no frame has colours. The carried ``settings.reference`` surfels are
    guided in every frame."""
    fields = _color_fields(points, normals, colors, state.count)
    if not fields:
        return None
    reference, first = _reference_colors(state, observed, fields)
    if settings.reference is not None:
        carried = len(settings.reference)
        reference[:carried], first[:carried] = settings.reference, -1
    parts = []
    for t in fields:
        shift = photometric_shift(
            state.positions[t], state.normals[t], reference, fields[t], radius=settings.radius
        )
        # in its reference frame a surfel's patch matches itself: no guide there
        finite = np.flatnonzero(np.isfinite(shift.uncertainty) & (first != t))
        weight = np.exp(-((shift.uncertainty[finite] / settings.scale) ** 2))
        keep = finite[weight > 1e-3]
        parts.append((t, keep, state.positions[t, keep] + shift.shift[keep], weight[weight > 1e-3]))
    guides = GuideData(
        np.concatenate([np.full(len(k), t, dtype=np.int64) for t, k, _, _ in parts]),
        np.concatenate([k for _, k, _, _ in parts]).astype(np.int64),
        np.concatenate([g for _, _, g, _ in parts]).reshape(-1, 3),
        np.concatenate([w for _, _, _, w in parts]),
    )
    log.info(
        "surfels: colour guides: %d over %d frames, mean certainty %.2f",
        len(guides.frames),
        len(fields),
        float(guides.weights.sum()) / max(1, state.count * len(fields)),
    )
    return guides


def reference_colors(
    state: SurfelState, observed: np.ndarray, points: list, normals: list, colors: list
) -> np.ndarray | None:
    """The log colours [S, 3] each surfel of ``state`` takes as its reference in
    :func:`color_guides` (the arguments as there); None when no frame has colours."""
    fields = _color_fields(points, normals, colors, state.count)
    return _reference_colors(state, observed, fields)[0] if fields else None


def _color_fields(points: list, normals: list, colors: list, reads: int) -> dict:
    """Frame -> colour field of every frame with colours (and at least 8 points)."""
    return {
        t: field_for_reads(points[t], normals[t], colors[t], reads)
        for t in range(len(points))
        if colors[t] is not None and len(points[t]) >= 8
    }


def _reference_colors(state: SurfelState, observed: np.ndarray, fields: dict):
    """Each surfel's reference colours [S, 3] from the colour ``fields`` (frame -> field) and
    the frame they come from [S]: the first that observes it (0 for one that none does), or
    the frame with colours nearest to it."""
    first = np.argmax(observed, axis=0)
    first[~observed.any(axis=0)] = 0
    reference = np.full((state.count, 3), np.nan)
    for t in np.unique(first):
        mine = np.flatnonzero(first == t)
        source = t if t in fields else min(fields, key=lambda k: abs(k - t))
        reference[mine] = fields[source].sample(state.positions[source, mine])
    return reference, first
