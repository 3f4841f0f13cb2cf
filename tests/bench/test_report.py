"""The bench report's Markdown: the run history, the commit and repeats of every row; its JSON
record: the plotted curves only."""

from __future__ import annotations

import json

from fourd.bench.report import format_markdown, write_report


def _report(scenes: dict, notes: list[str]) -> dict:
    machine = {"date": "2026-01-01 00:00 UTC", "commit": "abc1234", "cpu": "cpu", "cores": 2,
               "memory_gb": 8.0, "python": "3.11", "load_average": [0.0, 0.0, 0.0]}
    settings = {"quick": False, "protocol": {"cameras": 3, "noise": 0.002, "outliers": 0.02},
                "seed": 0, "samples": 1000, "repeats": 1}
    return {"machine": machine, "settings": settings, "scenes": scenes, "notes": notes}


def test_the_run_history_follows_the_tables():
    report = _report({}, ["rerun at abc1234"])
    text = format_markdown(report)
    assert text.index("## Summary") < text.index("## Run history") < text.index("- rerun at abc1234")
    assert "## Run history" not in format_markdown({**report, "notes": []})


def test_each_row_says_at_which_commit_and_with_how_many_runs_it_was_measured():
    metrics = {"chamfer": 0.002, "completeness_95": 0.01, "correspondence_mean": None,
               "correspondence_last": None, "timing": {"seconds_per_frame": 0.5}}
    entry = {"settings": {"name": "squash-ball", "options": {}, "resolution": 64}, "frames": 4,
             "truth_kind": "AnimatedMesh", "points_per_frame": 1000.0, "floor": {"chamfer": 0.001},
             "rows": {"new": {"metrics": metrics, "made": {"commit": "def5678", "date": "d", "repeats": 3}},
                      "old": {"metrics": metrics},
                      "broken": {"error": "boom", "made": {"commit": "def5678", "date": "d", "repeats": 1}}}}
    text = format_markdown(_report({"squash-ball": entry}, []))
    table = text[text.index("\n| method |") + 1:].split("\n\n")[0].splitlines()
    assert table[0].endswith("| measured at |")
    row = {line.split(" | ")[0][2:]: line for line in table[2:]}
    assert row["new"].endswith("| def5678, 3 runs |") and row["old"].endswith("| — |")
    assert row["broken"].endswith("| def5678, 1 run |")
    assert {line.count("|") for line in table} == {table[0].count("|")}
    summary = text[text.index("## Summary"):text.index("\n## squash-ball")].strip().splitlines()[2:]
    assert summary[0].endswith("| measured at |") and summary[2].endswith("| def5678, 3 runs |")
    assert {line.count("|") for line in summary} == {summary[0].count("|")}


def test_the_json_record_keeps_the_plotted_curves_at_four_digits(tmp_path):
    curves = {"accuracy": [0.00123456, 0.002], "completeness": [0.00312345, 0.001],
              "correspondence": None, "volume": [1.0, 1.1], "euler": [2, 2]}
    metrics = {"chamfer": 0.00123456, "completeness_95": 0.01, "correspondence_mean": None,
               "correspondence_last": None, "per_frame": curves, "timing": {"seconds_per_frame": 0.5}}
    entry = {"settings": {"name": "squash-ball", "options": {}, "resolution": 64}, "frames": 2,
             "truth_kind": "AnimatedMesh", "points_per_frame": 1000.0,
             "floor": {"chamfer": 0.001, "per_frame": curves}, "rows": {"m": {"metrics": metrics}}}
    write_report(_report({"squash-ball": entry}, []), tmp_path / "r.md")
    written = json.loads((tmp_path / "r.json").read_text())["scenes"]["squash-ball"]
    kept = {"accuracy": [0.001235, 0.002], "completeness": [0.003123, 0.001], "correspondence": None}
    assert written["rows"]["m"]["metrics"]["per_frame"] == kept
    assert written["floor"]["per_frame"] == kept
    assert written["rows"]["m"]["metrics"]["chamfer"] == 0.00123456  # scalars as measured
