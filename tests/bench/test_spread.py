"""The spread of a row's scores: scans moved far below their noise, the medians of the runs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fourd.bench import runner
from fourd.bench.spread import SCALE, combined_metrics, moved_scans
from fourd.errors import InputError
from fourd.sequence import Frame, PointCloudSequence


def _scans():
    rng = np.random.default_rng(0)
    return PointCloudSequence(
        frames=tuple(Frame(rng.uniform(0.0, 2.0, (50, 3)), time=t) for t in range(3))
    )


def test_moved_scans_move_every_point_by_a_seeded_offset_far_below_the_noise():
    scans = _scans()
    assert moved_scans(scans, 0) is scans
    once, again, other = moved_scans(scans, 1), moved_scans(scans, 1), moved_scans(scans, 2)
    diagonal = np.linalg.norm(np.ptp(np.concatenate([f.points for f in scans.frames]), axis=0))
    for frame, moved, same, elsewhere in zip(
        scans.frames, once.frames, again.frames, other.frames, strict=True
    ):
        offsets = moved.points - frame.points
        assert np.all(offsets != 0.0)
        # normal offsets of SCALE times the diagonal: none beyond six of them
        assert np.abs(offsets).max() < 6 * SCALE * diagonal
        assert np.std(offsets) == pytest.approx(SCALE * diagonal, rel=0.3)
        np.testing.assert_array_equal(moved.points, same.points)
        assert not np.array_equal(moved.points, elsewhere.points)
        assert moved.time == frame.time


def test_the_combined_row_holds_each_scores_median_and_range():
    runs = [
        {"chamfer": c, "jitter": j, "per_frame": [c] * 2, "closed": flag, "frames": 20,
         "timing": {"seconds_per_frame": s, "seconds": [s * 4], "peak_memory_mb": m}}
        for c, j, flag, s, m in [
            (0.003, 0.7, True, 2.0, 900.0), (0.005, 0.9, False, 3.0, 950.0),
            (0.004, float("nan"), True, 1.0, 800.0),
        ]
    ]
    row = combined_metrics(runs)
    assert row["chamfer"] == pytest.approx(0.004) and row["spread"]["chamfer"] == [0.003, 0.005]
    # a run without a value leaves it out of the median
    assert row["jitter"] == pytest.approx(0.8) and row["spread"]["jitter"] == [0.7, 0.9]
    # the curves, flags and numbers that do not move are the unmoved run's
    assert row["per_frame"] == [0.003, 0.003] and row["closed"] is True
    assert row["frames"] == 20 and isinstance(row["frames"], int) and "frames" not in row["spread"]
    assert row["timing"]["seconds_per_frame"] == 2.0 and row["timing"]["peak_memory_mb"] == 950.0
    assert row["timing"]["seconds"] == [8.0, 12.0, 4.0]
    assert row["timing"]["peak_memory_all_runs_mb"] == 950.0
    assert row["spread"]["seconds_per_frame"] == [1.0, 3.0] and row["runs"] == 3


def test_a_spread_row_is_the_median_of_runs_on_moved_scans(tmp_path, monkeypatch):
    import fourd.methods

    first_points = []
    real = fourd.methods.reconstruct_with_diagnostics

    def recording(scans, method=None, **values):
        first_points.append(scans.frames[0].points[0].copy())
        return real(scans, method=method, **values)

    monkeypatch.setattr(fourd.methods, "reconstruct_with_diagnostics", recording)
    output = tmp_path / "spread.md"
    report = runner.run_bench(quick=True, scenes=["squash-ball"], methods=["perframe"],
                              spread=3, output=output, isolate=False)
    assert len(first_points) == 3
    # the first run on the scans as they are, the others moved by far less than the noise
    moves = [np.abs(p - first_points[0]).max() for p in first_points[1:]]
    assert all(0.0 < move < 1e-6 for move in moves)
    row = report["scenes"]["squash-ball"]["rows"]["perframe"]
    low, high = row["metrics"]["spread"]["chamfer"]
    assert low <= row["metrics"]["chamfer"] <= high and row["metrics"]["runs"] == 3
    assert row["made"]["spread"] == 3
    text = output.read_text()
    assert "median of 3 moved runs" in text and "- perframe over 3 moved runs: " in text
    assert json.loads(output.with_suffix(".json").read_text())["settings"]["spread"] == 3
    with pytest.raises(InputError, match="spread"):
        runner.run_bench(spread=0, output=tmp_path / "b.md")
