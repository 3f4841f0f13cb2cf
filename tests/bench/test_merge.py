"""Bench reports made side by side merge into one."""

from __future__ import annotations

import pytest


@pytest.mark.slow
def test_runs_made_side_by_side_merge_into_one_report(tmp_path):
    from fourd.bench import merge_reports, run_bench

    first = run_bench(quick=True, scenes=["squash-ball"], output=tmp_path / "a" / "a.md")
    second = run_bench(quick=True, scenes=["waving-sheet"], output=tmp_path / "b" / "b.md")
    merged = merge_reports([first["paths"]["json"], second["paths"]["json"]], tmp_path / "m" / "BENCHMARKS.md")
    assert list(merged["scenes"]) == ["squash-ball", "waving-sheet"]
    text = (tmp_path / "m" / "BENCHMARKS.md").read_text()
    assert "## squash-ball" in text and "## waving-sheet" in text
    sheets = sorted(p.name for p in (tmp_path / "m" / "plots").glob("*-perframe.png"))
    assert sheets == ["squash-ball-perframe.png", "waving-sheet-perframe.png"]
