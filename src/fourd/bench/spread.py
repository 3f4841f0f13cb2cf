"""How far a row's scores move from rounding alone: the same scans moved by offsets far below
their noise but far above rounding, reconstructed again and scored (``fourd bench --spread N``).

A method whose optimiser stops after a fixed number of steps, or that makes discrete decisions
(a matching's cutoff, a resampling, a clipping), amplifies rounding differences, so one run's
scores are one draw: the same commit scores differently on another machine or numpy build.
The row then reports each score's median over the runs and its range.
"""

from __future__ import annotations

import dataclasses
import statistics

import numpy as np

#: The offsets' scale, a fraction of the scans' bounding-box diagonal (the scans' noise is
#: about 1e-3 of it; float64 rounding of coordinates 1e-16).
SCALE = 1e-9


def moved_scans(scans, run: int, scale: float = SCALE):
    """``scans`` (a :class:`~fourd.sequence.PointCloudSequence`) with every point moved by
    ``N(0, scale * diagonal)`` per coordinate, seeded by ``run``; run 0 is ``scans`` itself."""
    if run == 0:
        return scans
    diagonal = scans.diagonal()
    rng = np.random.default_rng(run)
    frames = tuple(
        dataclasses.replace(
            frame, points=frame.points + rng.normal(scale=scale * diagonal, size=frame.points.shape)
        )
        for frame in scans.frames
    )
    return dataclasses.replace(scans, frames=frames)


def _number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def combined_metrics(runs: list[dict]) -> dict:
    """One row's metrics from those of several runs of it (``runs[0]`` on the unmoved scans):
    every number that differs between the runs the median over them, with ``spread`` {key:
    [min, max]}; the rest (the numbers that do not, the per-frame curves) of run 0; the
    timing's seconds per frame the median, its peak memories the largest."""
    first = runs[0]
    metrics, spread = {}, {}
    for key, value in first.items():
        values = [run.get(key) for run in runs]
        if _number(value) and all(_number(v) for v in values) and len(set(values)) > 1:
            finite = [float(v) for v in values if np.isfinite(v)]
            metrics[key] = statistics.median(finite) if finite else float(value)
            if finite:
                spread[key] = [min(finite), max(finite)]
        else:
            metrics[key] = value
    timings = [run.get("timing") or {} for run in runs]
    if all("seconds_per_frame" in t for t in timings):
        metrics["timing"] = {
            **timings[0],
            "seconds_per_frame": statistics.median(t["seconds_per_frame"] for t in timings),
            "seconds": [s for t in timings for s in t.get("seconds", [])],
            "peak_memory_mb": max(t["peak_memory_mb"] for t in timings),
            "peak_memory_all_runs_mb": max(
                t.get("peak_memory_all_runs_mb", t["peak_memory_mb"]) for t in timings
            ),
        }
        seconds = [t["seconds_per_frame"] for t in timings]
        spread["seconds_per_frame"] = [min(seconds), max(seconds)]
    metrics["spread"] = spread
    metrics["runs"] = len(runs)
    return metrics
