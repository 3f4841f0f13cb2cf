"""One bench case: errors become rows, peak memory is the first run's."""

from __future__ import annotations

from fourd.bench import case as bench_case


def test_an_unknown_peer_is_an_error_row_not_a_crash():
    from fourd import synth

    scans = synth.scan(synth.scene("squash-ball", frames=2), resolution=48)
    result = bench_case.run_case("baseline", "no_such_peer", scans, isolate=False)
    assert "AttributeError" in result["error"]


def test_peak_memory_is_the_first_runs_and_the_peak_over_all_runs_is_kept(monkeypatch):
    # ru_maxrss only grows: read after each run, the first reading is the first run's peak
    readings = iter([300.0, 3674.0, 3700.0, 3820.0])
    monkeypatch.setattr(bench_case, "_peak_mb", lambda: next(readings))
    monkeypatch.setattr(bench_case, "_reconstruct", lambda kind, name, scans, level: ("mesh", {}))
    result = bench_case._timed_runs("method", "flow", None, repeats=3, log_level=0)
    assert result["start_mb"] == 300.0 and result["peak_mb"] == 3674.0 and result["peak_all_mb"] == 3820.0
    assert len(result["seconds"]) == 3 and result["result"] == "mesh"
