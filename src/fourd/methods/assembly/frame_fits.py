"""The loop shared by the fits that slide the assembled frames one after another (the rest fit,
:mod:`~fourd.methods.assembly.rest_fit`, and the colour fit,
:mod:`~fourd.methods.assembly.color_fit`): frames ``1 .. T - 1`` in order, each fitted from the
state the frame before left, each result kept in a :class:`~fourd.cache.Chain` so that a
stopped run resumes at the first frame it had not kept.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from fourd.cache import NO_CACHE, Chain, StageCache, report_resumed
from fourd.progress import progress

log = logging.getLogger("fourd.methods.assembly")


class FrameFit(Protocol):
    """A fit carried from frame to frame."""

    def resume(self, assembled: np.ndarray, fitted: np.ndarray) -> None:
        """Carry on after a frame fitted before: its ``assembled`` and ``fitted`` positions."""


def fit_frames(
    fit: FrameFit,
    positions: np.ndarray,
    step: Callable[[int], np.ndarray | None],
    *,
    stage: str,
    key: str,
    inputs: Sequence[Sequence],
    label: str,
    cache: StageCache = NO_CACHE,
) -> np.ndarray:
    """``positions [T, N, 3]`` with frames ``1 .. T - 1`` replaced by ``step(t)`` in order
    (None: the frame left as it is), in place.

    Parameters
    ----------
    fit : FrameFit
        The fit ``step`` advances; told of each frame read from the cache instead.
    stage, key : str
        The cache entries' stage, and the key of everything the fit of frame 1 depends on
        besides its own inputs.
    inputs : sequence of sequences
        Per frame ``1 .. T - 1``, what its fit depends on besides the frames before it (key
        parts, :meth:`fourd.cache.Chain.of`).
    label : str
        The fit's name in the progress bar and the log.
    cache : StageCache
        Where each frame's result is kept; the keys hash every frame, so only when enabled.
    """
    chain, done = None, []
    if cache.enabled:
        chain = Chain.of(cache, stage, key, inputs)
        done = chain.prefix()
    for t, entry in enumerate(done, start=1):
        if not entry.get("skipped", False):  # the rest fit kept no flag before it shared this loop
            fit.resume(positions[t], entry["positions"])
            positions[t] = entry["positions"]
    if done:
        report_resumed(log, f"{len(done)} of {len(positions) - 1} frames' {label}")
    for t in progress(range(len(done) + 1, len(positions)), desc=f"assembly {label}", unit="frame"):
        fitted = step(t)
        if fitted is not None:
            positions[t] = fitted
        if chain is not None:
            skipped = fitted is None
            chain.save(
                t - 1,
                {
                    "positions": np.zeros((0, 3)) if skipped else fitted,
                    "skipped": np.bool_(skipped),
                },
            )
    return positions
