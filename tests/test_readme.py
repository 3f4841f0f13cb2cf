"""The README's table of measured figures is the benchmark's: every cell equals the row of
``benchmarks/BENCHMARKS.json`` it names, so the two cannot drift apart."""

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_rows() -> list[list[str]]:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("### How they measure"):text.index("### Where they fall short")]
    return [[cell.strip() for cell in line.strip().strip("|").split("|")]
            for line in section.splitlines() if re.match(r"^\| [\w-]+ \| `", line)]


def _cells(metrics: dict) -> list[str]:
    if metrics.get("correspondence_mean") is None:
        correspondence = "—"
    else:
        correspondence = f"{metrics['correspondence_mean']:.4f} / {metrics['correspondence_last']:.4f}"
    return [f"{metrics['chamfer']:.4f}", f"{metrics['completeness_95']:.4f}", correspondence,
            f"{metrics['closed_manifold']:.0%}", f"{metrics['timing']['seconds_per_frame']:.2f}"]


def test_the_readme_table_is_the_benchmarks():
    report = json.loads((ROOT / "benchmarks" / "BENCHMARKS.json").read_text())
    rows = _readme_rows()
    assert len(rows) >= 20
    for scene, method, *cells in rows:
        metrics = report["scenes"][scene]["rows"][method.strip("`")]["metrics"]
        assert cells == _cells(metrics), f"README row {scene} / {method} is not the bench's"
