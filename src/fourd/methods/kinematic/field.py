"""The space-time point cloud (000_00387fefe94cc850.txt section 2) and the 4D MPU wrapped as a
:class:`fourd.geometry.field.Field4D` in real time units, optionally over sliding windows of
frames (bounded memory on long sequences)."""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from fourd.cache import NO_CACHE, StageCache, report_resumed, stage_key
from fourd.methods.kinematic.mpu4d import (
    MPU4D,
    MPUOptions,
    fit_mpu4d,
    mpu_arrays,
    mpu_from_arrays,
)

log = logging.getLogger("fourd.methods.kinematic.field")


class SpaceTimePoints(NamedTuple):
    """Oriented 4D points ``(x, y, z, delta * (t - t0) / dt)`` with normals ``(n, 0)``."""

    points: np.ndarray  # [P, 4]
    normals: np.ndarray  # [P, 4]
    frame: np.ndarray  # [P] frame index of every point


def space_time_points(
    points: Sequence[np.ndarray],
    normals: Sequence[np.ndarray],
    times: np.ndarray,
    *,
    delta: float,
    time_origin: float,
    time_unit: float,
) -> SpaceTimePoints:
    """Stack per-frame points into the paper's 4D point cloud.

    ``w = delta * (t - time_origin) / time_unit``: with ``time_unit`` the typical frame step,
    consecutive frames are ``delta`` apart in ``w`` as in the paper (``w = delta * frame
    index``), and arbitrary time stamps keep their spacing.
    """
    w = delta * (np.asarray(times, dtype=np.float64) - time_origin) / time_unit
    xyz = np.concatenate([np.asarray(p, float).reshape(-1, 3) for p in points])
    nrm = np.concatenate([np.asarray(n, float).reshape(-1, 3) for n in normals])
    counts = [len(p) for p in points]
    frame = np.repeat(np.arange(len(points)), counts)
    X = np.c_[xyz, w[frame]]
    N = np.c_[nrm, np.zeros(len(nrm))]
    return SpaceTimePoints(X, N, frame)


class Segment(NamedTuple):
    """One fitted window: valid for times in ``[start, stop]``."""

    start: float
    stop: float
    mpu: MPU4D


class SpaceTimeField:
    """A :class:`~fourd.geometry.field.Field4D` over one or several 4D MPU fits.

    Parameters
    ----------
    windows : list of (start, stop)
        Time intervals covered by each fit (consecutive, touching).
    build : callable(index) -> MPU4D
        Fits window ``index`` (called lazily; at most ``cache`` fits are kept in memory).
    time_origin, time_scale : float
        ``w = time_scale * (t - time_origin)``.
    """

    def __init__(
        self,
        windows: Sequence[tuple[float, float]],
        build: Callable[[int], MPU4D],
        *,
        time_origin: float,
        time_scale: float,
        cache: int = 2,
    ):
        self.windows = [(float(a), float(b)) for a, b in windows]
        self._build = build
        self._cache: OrderedDict[int, MPU4D] = OrderedDict()
        self._cache_size = max(1, cache)
        self.time_origin = float(time_origin)
        self.time_scale = float(time_scale)
        self.fits = 0

    @classmethod
    def single(cls, mpu: MPU4D, *, time_origin: float, time_scale: float) -> SpaceTimeField:
        return cls(
            [(-np.inf, np.inf)], lambda index: mpu, time_origin=time_origin, time_scale=time_scale
        )

    def mpu(self, index: int) -> MPU4D:
        if index in self._cache:
            self._cache.move_to_end(index)
            return self._cache[index]
        fitted = self._build(index)
        self.fits += 1
        self._cache[index] = fitted
        while len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return fitted

    def _window_of(self, times: np.ndarray) -> np.ndarray:
        stops = np.array([b for _, b in self.windows])
        return np.minimum(np.searchsorted(stops, times, side="left"), len(self.windows) - 1)

    def _evaluate(self, points, times, gradient: bool):
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        times = np.broadcast_to(np.asarray(times, dtype=np.float64), (len(points),))
        q = np.c_[points, self.time_scale * (times - self.time_origin)]
        values = np.empty(len(points))
        grads = np.empty((len(points), 4)) if gradient else None
        which = self._window_of(times)
        for index in np.unique(which):
            sel = which == index
            v, g = self.mpu(int(index)).evaluate(q[sel], gradient=gradient)
            values[sel] = v
            if gradient:
                grads[sel] = g
        if gradient:
            grads[:, 3] *= self.time_scale
        return values, grads

    def value(self, points: np.ndarray, times) -> np.ndarray:
        """``f`` at ``points`` [M, 3] and ``times`` (scalar or [M]); negative inside."""
        return self._evaluate(points, times, False)[0]

    def value_and_gradient(self, points: np.ndarray, times) -> tuple[np.ndarray, np.ndarray]:
        """Both in one tree traversal."""
        return self._evaluate(points, times, True)

    def gradient(self, points: np.ndarray, times) -> np.ndarray:
        """``(df/dx, df/dy, df/dz, df/dt)`` [M, 4], ``t`` in the sequence's time units."""
        return self._evaluate(points, times, True)[1]


#: The cache entries of 4D fits (one per window).
STAGE = "kinematic-fit"


def fit_key(
    stp: SpaceTimePoints,
    times: np.ndarray,
    *,
    mpu_options: MPUOptions,
    window: int,
    overlap: int,
    time_origin: float,
    time_scale: float,
) -> str:
    """The cache key of :func:`fit_windows`' fits: everything they depend on."""
    return stage_key(
        STAGE, stp.points, stp.normals, stp.frame, np.asarray(times, float), mpu_options,
        window, overlap, time_origin, time_scale,
    )


def fit_windows(
    stp: SpaceTimePoints,
    times: np.ndarray,
    *,
    mpu_options: MPUOptions,
    window: int,
    overlap: int,
    time_origin: float,
    time_scale: float,
    cache: StageCache = NO_CACHE,
    key: str = "",
) -> SpaceTimeField:
    """A :class:`SpaceTimeField` over all frames (``window = 0``) or over windows of
    ``window`` frames, each fitted with ``overlap`` extra frames on both sides so that the
    function is continuous enough across the window boundary.

    With a ``cache``, each fit is stored under ``key`` (:func:`fit_key` of the same
    arguments) and the window's index, and a fit found there is loaded instead."""
    count = len(times)

    def fitted(index: int, points, normals, what: str) -> MPU4D:
        window_key = stage_key(key, index)
        stored = cache.load(STAGE, window_key)
        if stored is not None:
            if index not in reported:
                report_resumed(log, what)
                reported.add(index)
            return mpu_from_arrays(stored)
        mpu = fit_mpu4d(points, normals, options=mpu_options)
        cache.save(STAGE, window_key, mpu_arrays(mpu))
        return mpu

    reported: set[int] = set()
    if window <= 0 or window >= count:
        mpu = fitted(0, stp.points, stp.normals, "the 4D fit")
        return SpaceTimeField.single(mpu, time_origin=time_origin, time_scale=time_scale)
    spans = window_spans(times, window, overlap)

    def build(index: int) -> MPU4D:
        span = spans[index]
        sel = (stp.frame >= span.fit_first) & (stp.frame <= span.fit_last)
        log.debug("fitting window %d: frames %d-%d (%d points)", index, span.fit_first,
                  span.fit_last, int(sel.sum()))
        return fitted(
            index, stp.points[sel], stp.normals[sel],
            f"the 4D fit of window {index + 1} of {len(spans)}",
        )

    return SpaceTimeField([(s.start, s.stop) for s in spans], build, time_origin=time_origin,
                          time_scale=time_scale)


class WindowSpan(NamedTuple):
    """One window of :func:`window_spans`: its frames ``first..last``, the frames its 4D fit
    takes in (``fit_first..fit_last``, the overlap added) and the times it answers for
    (``start`` to ``stop``: from the previous window's stop to halfway to the next frame)."""

    first: int
    last: int
    fit_first: int
    fit_last: int
    start: float
    stop: float


def window_spans(times: np.ndarray, window: int, overlap: int) -> list[WindowSpan]:
    """The windows of ``window`` frames over frames with ``times`` [T] (the last may be
    shorter), each fitted with ``overlap`` extra frames on both sides.

    >>> [tuple(s)[:4] for s in window_spans(np.arange(5.0), 2, 1)]
    [(0, 1, 0, 2), (2, 3, 1, 4), (4, 4, 3, 4)]
    """
    count = len(times)
    spans = []
    for a in range(0, count, window):
        b = min(a + window, count) - 1
        start = spans[-1].stop if spans else -np.inf
        stop = 0.5 * (times[b] + times[b + 1]) if b + 1 < count else np.inf
        spans.append(WindowSpan(a, b, max(0, a - overlap), min(count - 1, b + overlap),
                                float(start), float(stop)))
    return spans
