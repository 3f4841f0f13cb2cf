"""The benchmark runner: the quick path end to end, failures recorded, method specs as rows."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fourd.bench import case as bench_case
from fourd.bench import report, runner, suite
from fourd.errors import InputError
from fourd.methods import available_methods


@pytest.mark.slow
@pytest.mark.skipif("perframe" not in available_methods(), reason="the perframe method is not there yet")
def test_quick_bench_writes_markdown_json_and_plots(tmp_path):
    output = tmp_path / "BENCHMARKS.md"
    report = runner.run_bench(quick=True, scenes=["squash-ball"], output=output)
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

    def broken(kind, name, scans, log_level):  # same signature as fourd.bench.case._reconstruct
        calls.append(name)
        raise RuntimeError("no surface today")

    monkeypatch.setattr(bench_case, "_reconstruct", broken)
    output = tmp_path / "quick.md"
    report = runner.run_bench(quick=True, methods=["perframe"], output=output, isolate=False)
    assert calls == ["perframe", "perframe"]  # both quick scenes were attempted
    for entry in report["scenes"].values():
        assert entry["rows"]["perframe"]["error"] == "RuntimeError: no surface today"
        assert entry["floor"]["chamfer"] > 0
    text = output.read_text()
    assert text.count("failed: RuntimeError: no surface today") == 2
    assert (tmp_path / "quick.json").exists()
    assert len(list((tmp_path / "quick-plots").glob("*.png"))) == 2


def test_bad_selections_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="scene"):
        runner.run_bench(scenes=["no-such-scene"], output=tmp_path / "b.md")
    with pytest.raises(InputError, match="method"):
        runner.run_bench(methods=["no-such-method"], output=tmp_path / "b.md")
    with pytest.raises(InputError, match="repeats"):
        runner.run_bench(repeats=0, output=tmp_path / "b.md")


def test_a_clean_scan_is_a_named_scene_and_reaches_the_scanner():
    """``crane-clean``: the standard crane stretch through 8 cameras without noise or outliers
    (what is left of a method's error is its own); the override reaches ``synth.scan``."""
    (chosen,) = suite.select_scenes(["crane-clean"], quick=False)
    standard = next(s for s in suite.STANDARD_SCENES if s.key == "crane")
    assert chosen.name == "crane" and chosen.options == standard.options
    assert chosen.scan == {"cameras": 8, "noise": 0.0, "outliers": 0.0}
    assert "crane-clean" not in {s.key for s in suite.select_scenes(None, quick=False)}
    assert report._scanner(chosen.scan) == "8 cameras, noise 0, outliers 0"
    clean = suite.BenchScene("rigid-turn", frames=2, resolution=48, scan=chosen.scan)
    plain = suite.BenchScene("rigid-turn", frames=2, resolution=48)
    counts = {}
    for scene in (clean, plain):
        entry = runner._run_scene(scene, [], {}, samples=500, seed=0, repeats=1, timeout=None,
                                 isolate=False, bar=runner.progress(total=0))
        counts[scene.scan == {}] = entry["points_per_frame"]
    assert counts[False] > counts[True]  # 8 cameras see more than 3


@pytest.mark.slow
def test_a_methods_own_figures_reach_the_row_and_the_table(tmp_path, monkeypatch):
    real = bench_case._reconstruct

    def with_figure(kind, name, scans, log_level):
        result, diagnostics = real(kind, name, scans, log_level)
        assert diagnostics == {}  # perframe has none of its own
        return result, {"mass_conservation_error": 0.0123}

    monkeypatch.setattr(bench_case, "_reconstruct", with_figure)
    output = tmp_path / "mass.md"
    report = runner.run_bench(quick=True, scenes=["squash-ball"], methods=["perframe"], output=output,
                             isolate=False)
    metrics = report["scenes"]["squash-ball"]["rows"]["perframe"]["metrics"]
    assert metrics["mass_conservation_error"] == 0.0123
    assert "mass err." in output.read_text() and "| 1.2% |" in output.read_text()


def test_a_method_spec_is_its_own_row_with_its_options(tmp_path, monkeypatch):
    import fourd.methods

    seen = []
    real = fourd.methods.reconstruct_with_diagnostics

    def recording(scans, method=None, **values):
        seen.append((method, values))
        return real(scans, method=method, **values)

    monkeypatch.setattr(fourd.methods, "reconstruct_with_diagnostics", recording)
    spec = "perframe:outlier_z=6"
    report = runner.run_bench(quick=True, scenes=["squash-ball"], methods=["perframe", spec],
                             output=tmp_path / "spec.md", isolate=False)
    assert seen == [("perframe", {}), ("perframe", {"outlier_z": "6"})]
    rows = report["scenes"]["squash-ball"]["rows"]
    assert "metrics" in rows[spec] and "metrics" in rows["perframe"]
    assert f"| {spec} |" in (tmp_path / "spec.md").read_text()
    sheet = rows[spec]["sheet"]
    assert sheet and sheet.endswith("squash-ball-perframe-outlier_z-6.png") and Path(sheet).exists()


def test_a_scenes_appearance_and_video_reach_the_scanner(monkeypatch):
    from fourd import synth

    seen = {}
    real = synth.scan

    def spy(truth, **options):
        seen.update(options)
        return real(truth, **{**options, "resolution": 16})

    monkeypatch.setattr(synth, "scan", spy)
    scene = suite.BenchScene("squash-ball", frames=2, resolution=16, appearance="skin", video=True)
    entry = runner._run_scene(scene, [], {}, samples=200, seed=0, repeats=1, timeout=None,
                              isolate=False, bar=runner.progress(total=0))
    assert seen["appearance"] == "skin" and seen["video"] is True
    assert entry["settings"]["appearance"] == "skin"


def test_photo_scene_in_a_spec_is_the_garment_scenes_own_photo(tmp_path):
    from PIL import Image

    tshirt = suite.BenchScene("tshirt", label="tshirt-cloth-video")
    spec = runner._with_scene_files("garment:boundaries=4,photo=scene", tshirt, tmp_path)
    name, values = suite.parse_method_spec(spec)
    photo = Path(values["photo"])
    assert name == "garment" and values["boundaries"] == "4" and photo.parent == tmp_path
    image = np.asarray(Image.open(photo))
    calibration = json.loads((tmp_path / "pattern.json").read_text())
    assert image.max() == 255 and image.min() == 0 and len(calibration["openings"]) == 4
    assert runner._with_scene_files("garment:boundaries=4", tshirt, tmp_path) == "garment:boundaries=4"
    with pytest.raises(InputError, match="squash-ball has no photo"):
        runner._with_scene_files("garment:photo=scene", suite.BenchScene("squash-ball"), tmp_path)
