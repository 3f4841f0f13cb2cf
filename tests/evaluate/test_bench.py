"""The benchmark runner: the quick path end to end, failures recorded, the report format."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fourd.errors import InputError
from fourd.evaluate import bench
from fourd.methods import available_methods


@pytest.mark.slow
@pytest.mark.skipif("perframe" not in available_methods(), reason="the perframe method is not there yet")
def test_quick_bench_writes_markdown_json_and_plots(tmp_path):
    output = tmp_path / "BENCHMARKS.md"
    report = bench.run_bench(quick=True, scenes=["squash-ball"], output=output)
    text = output.read_text()
    assert "## squash-ball" in text and "| floor (truth vs itself) |" in text and "| perframe |" in text
    assert "cores" in text and "commit" in text
    data = json.loads(output.with_suffix(".json").read_text())
    row = data["scenes"]["squash-ball"]["rows"]["perframe"]
    floor = data["scenes"]["squash-ball"]["floor"]
    assert "error" not in row, row.get("error")
    metrics = row["metrics"]
    # A reconstruction from noisy partial scans cannot beat the truth scored against itself.
    assert metrics["chamfer"] >= 0.95 * floor["chamfer"]
    assert metrics["chamfer"] < 0.05  # and the quick path produces a sensible surface
    assert metrics["timing"]["seconds_per_frame"] > 0 and metrics["timing"]["peak_memory_mb"] > 10
    plot = tmp_path / "plots" / "squash-ball.png"
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert report["paths"]["plots"] == [str(plot)]


@pytest.mark.slow
def test_a_failing_method_is_recorded_and_the_run_goes_on(tmp_path, monkeypatch):
    calls = []

    def broken(kind, name, scans, log_level):  # same signature as bench._reconstruct
        calls.append(name)
        raise RuntimeError("no surface today")

    monkeypatch.setattr(bench, "_reconstruct", broken)
    output = tmp_path / "quick.md"
    report = bench.run_bench(quick=True, methods=["perframe"], output=output, isolate=False)
    assert calls == ["perframe", "perframe"]  # both quick scenes were attempted
    for entry in report["scenes"].values():
        assert entry["rows"]["perframe"]["error"] == "RuntimeError: no surface today"
        assert entry["floor"]["chamfer"] > 0
    text = output.read_text()
    assert text.count("failed: RuntimeError: no surface today") == 2
    assert (tmp_path / "quick.json").exists()
    assert len(list((tmp_path / "quick-plots").glob("*.png"))) == 2


def test_an_unknown_peer_is_an_error_row_not_a_crash():
    from fourd import synth

    scans = synth.scan(synth.scene("squash-ball", frames=2), resolution=48)
    case = bench.run_case("baseline", "no_such_peer", scans, isolate=False)
    assert "AttributeError" in case["error"]


def test_bad_selections_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="scene"):
        bench.run_bench(scenes=["no-such-scene"], output=tmp_path / "b.md")
    with pytest.raises(InputError, match="method"):
        bench.run_bench(methods=["no-such-method"], output=tmp_path / "b.md")
    with pytest.raises(InputError, match="repeats"):
        bench.run_bench(repeats=0, output=tmp_path / "b.md")


def test_held_out_stretches_of_a_capture_are_named_scenes():
    """``crane-90``: the crane capture from frame 90, same length and step as the standard
    crane scene, selectable by its label and not run by default."""
    (chosen,) = bench._select_scenes(["crane-90"], quick=False)
    standard = {s.key: s for s in bench.STANDARD_SCENES}["crane"]
    assert chosen.key == "crane-90" and chosen.name == "crane"
    assert chosen.options == {**standard.options, "start": 90}
    assert chosen.frames == standard.frames and chosen.resolution == standard.resolution
    assert "crane-90" not in {s.key for s in bench._select_scenes(None, quick=False)}
    assert "From frame 90 on." in bench._describe("crane", chosen.options)


def test_a_held_still_pose_is_a_named_scene():
    """``crane-still``: the first crane pose 20 times (each frame scanned anew), not run by
    default."""
    (chosen,) = bench._select_scenes(["crane-still"], quick=False)
    assert chosen.name == "crane" and chosen.options == {"start": 0, "step": 0}
    assert "crane-still" not in {s.key for s in bench._select_scenes(None, quick=False)}
    assert "held still" in bench._describe("crane", chosen.options)


def test_a_clean_scan_is_a_named_scene_and_reaches_the_scanner():
    """``crane-clean``: the standard crane stretch through 8 cameras without noise or outliers
    (what is left of a method's error is its own); the override reaches ``synth.scan``."""
    (chosen,) = bench._select_scenes(["crane-clean"], quick=False)
    standard = next(s for s in bench.STANDARD_SCENES if s.key == "crane")
    assert chosen.name == "crane" and chosen.options == standard.options
    assert chosen.scan == {"cameras": 8, "noise": 0.0, "outliers": 0.0}
    assert "crane-clean" not in {s.key for s in bench._select_scenes(None, quick=False)}
    assert bench._scanner(chosen.scan) == "8 cameras, noise 0, outliers 0"
    clean = bench.BenchScene("rigid-turn", frames=2, resolution=48, scan=chosen.scan)
    plain = bench.BenchScene("rigid-turn", frames=2, resolution=48)
    counts = {}
    for scene in (clean, plain):
        entry = bench._run_scene(scene, [], {}, samples=500, seed=0, repeats=1, timeout=None,
                                 isolate=False, bar=bench.progress(total=0))
        counts[scene.scan == {}] = entry["points_per_frame"]
    assert counts[False] > counts[True]  # 8 cameras see more than 3


def test_machine_info_names_the_machine():
    info = bench.machine_info()
    assert info["cores"] >= 1 and info["cpu"] and info["date"].endswith("UTC")


@pytest.mark.slow
def test_runs_made_side_by_side_merge_into_one_report(tmp_path):
    from fourd.evaluate.bench import merge_reports, run_bench

    first = run_bench(quick=True, scenes=["squash-ball"], output=tmp_path / "a" / "a.md")
    second = run_bench(quick=True, scenes=["waving-sheet"], output=tmp_path / "b" / "b.md")
    merged = merge_reports([first["paths"]["json"], second["paths"]["json"]], tmp_path / "m" / "BENCHMARKS.md")
    assert list(merged["scenes"]) == ["squash-ball", "waving-sheet"]
    text = (tmp_path / "m" / "BENCHMARKS.md").read_text()
    assert "## squash-ball" in text and "## waving-sheet" in text
    sheets = sorted(p.name for p in (tmp_path / "m" / "plots").glob("*-perframe.png"))
    assert sheets == ["squash-ball-perframe.png", "waving-sheet-perframe.png"]


@pytest.mark.slow
def test_a_methods_own_figures_reach_the_row_and_the_table(tmp_path, monkeypatch):
    real = bench._reconstruct

    def with_figure(kind, name, scans, log_level):
        result, diagnostics = real(kind, name, scans, log_level)
        assert diagnostics == {}  # perframe has none of its own
        return result, {"mass_conservation_error": 0.0123}

    monkeypatch.setattr(bench, "_reconstruct", with_figure)
    output = tmp_path / "mass.md"
    report = bench.run_bench(quick=True, scenes=["squash-ball"], methods=["perframe"], output=output,
                             isolate=False)
    metrics = report["scenes"]["squash-ball"]["rows"]["perframe"]["metrics"]
    assert metrics["mass_conservation_error"] == 0.0123
    assert "mass err." in output.read_text() and "| 1.2% |" in output.read_text()


def test_method_specs_carry_options():
    assert bench.parse_method_spec("flow:coherent=true, resolution=40") == (
        "flow",
        {"coherent": "true", "resolution": "40"},
    )
    assert bench.parse_method_spec("perframe") == ("perframe", {})
    with pytest.raises(InputError, match="expected key=value"):
        bench.parse_method_spec("flow:coherent")
    with pytest.raises(InputError, match="valid keys"):
        bench._select_methods(["perframe:no_such_option=1"], quick=False)
    with pytest.raises(InputError, match="unknown method"):
        bench._select_methods(["nope:x=1"], quick=False)


def test_a_method_spec_is_its_own_row_with_its_options(tmp_path, monkeypatch):
    import fourd.methods

    seen = []
    real = fourd.methods.reconstruct_with_diagnostics

    def recording(scans, method=None, **values):
        seen.append((method, values))
        return real(scans, method=method, **values)

    monkeypatch.setattr(fourd.methods, "reconstruct_with_diagnostics", recording)
    spec = "perframe:outlier_z=6"
    report = bench.run_bench(quick=True, scenes=["squash-ball"], methods=["perframe", spec],
                             output=tmp_path / "spec.md", isolate=False)
    assert seen == [("perframe", {}), ("perframe", {"outlier_z": "6"})]
    rows = report["scenes"]["squash-ball"]["rows"]
    assert "metrics" in rows[spec] and "metrics" in rows["perframe"]
    assert f"| {spec} |" in (tmp_path / "spec.md").read_text()
    sheet = rows[spec]["sheet"]
    assert sheet and sheet.endswith("squash-ball-perframe-outlier_z-6.png") and Path(sheet).exists()


def test_peak_memory_is_the_first_runs_and_the_peak_over_all_runs_is_kept(monkeypatch):
    # ru_maxrss only grows: read after each run, the first reading is the first run's peak
    readings = iter([300.0, 3674.0, 3700.0, 3820.0])
    monkeypatch.setattr(bench, "_peak_mb", lambda: next(readings))
    monkeypatch.setattr(bench, "_reconstruct", lambda kind, name, scans, level: ("mesh", {}))
    case = bench._timed_runs("method", "flow", None, repeats=3, log_level=0)
    assert case["start_mb"] == 300.0 and case["peak_mb"] == 3674.0 and case["peak_all_mb"] == 3820.0
    assert len(case["seconds"]) == 3 and case["result"] == "mesh"


def _report(scenes: dict, notes: list[str]) -> dict:
    machine = {"date": "2026-01-01 00:00 UTC", "commit": "abc1234", "cpu": "cpu", "cores": 2,
               "memory_gb": 8.0, "python": "3.11", "load_average": [0.0, 0.0, 0.0]}
    settings = {"quick": False, "protocol": {"cameras": 3, "noise": 0.002, "outliers": 0.02},
                "seed": 0, "samples": 1000, "repeats": 1}
    return {"machine": machine, "settings": settings, "scenes": scenes, "notes": notes}


def test_the_run_history_follows_the_tables():
    report = _report({}, ["rerun at abc1234"])
    text = bench.format_markdown(report)
    assert text.index("## Summary") < text.index("## Run history") < text.index("- rerun at abc1234")
    assert "## Run history" not in bench.format_markdown({**report, "notes": []})


def test_each_row_says_at_which_commit_and_with_how_many_runs_it_was_measured():
    metrics = {"chamfer": 0.002, "completeness_95": 0.01, "correspondence_mean": None,
               "correspondence_last": None, "timing": {"seconds_per_frame": 0.5}}
    entry = {"settings": {"name": "squash-ball", "options": {}, "resolution": 64}, "frames": 4,
             "truth_kind": "AnimatedMesh", "points_per_frame": 1000.0, "floor": {"chamfer": 0.001},
             "rows": {"new": {"metrics": metrics, "made": {"commit": "def5678", "date": "d", "repeats": 3}},
                      "old": {"metrics": metrics},
                      "broken": {"error": "boom", "made": {"commit": "def5678", "date": "d", "repeats": 1}}}}
    text = bench.format_markdown(_report({"squash-ball": entry}, []))
    table = text[text.index("\n| method |") + 1:].split("\n\n")[0].splitlines()
    assert table[0].endswith("| measured at |")
    row = {line.split(" | ")[0][2:]: line for line in table[2:]}
    assert row["new"].endswith("| def5678, 3 runs |") and row["old"].endswith("| — |")
    assert row["broken"].endswith("| def5678, 1 run |")
    assert {line.count("|") for line in table} == {table[0].count("|")}
    summary = text[text.index("## Summary"):text.index("\n## squash-ball")].strip().splitlines()[2:]
    assert summary[0].endswith("| measured at |") and summary[2].endswith("| def5678, 3 runs |")
    assert {line.count("|") for line in summary} == {summary[0].count("|")}
