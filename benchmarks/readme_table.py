"""Rewrite the cells of the README's table of measured figures from ``BENCHMARKS.json``.

Each row of that table (under "### How they measure") names a scene and a bench row label;
its cells are recomputed from the report, so after a bench merge the README follows with

    python benchmarks/readme_table.py            # rewrites README.md in place
    python benchmarks/readme_table.py --check    # exit status 1 if a cell differs

``tests/test_readme.py`` runs the check.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from fourd.bench import format_cell

ROOT = Path(__file__).resolve().parents[1]
ROW = re.compile(r"^\| ([\w-]+) \| `([^`]+)` \|.*\|$")


def cells(metrics: dict) -> list[str]:
    """Chamfer, completeness-95, correspondence mean / last, closed frames, s/frame, formatted
    as the bench's own tables format them."""
    if metrics.get("correspondence_mean") is None:
        correspondence = "—"
    else:
        correspondence = f"{format_cell(metrics['correspondence_mean'], 'd')} / {format_cell(metrics['correspondence_last'], 'd')}"
    return [format_cell(metrics["chamfer"], "d"), format_cell(metrics["completeness_95"], "d"), correspondence,
            format_cell(metrics["closed_manifold"], "%"), format_cell(metrics["timing"]["seconds_per_frame"], "r")]


def rewrite(readme: str, report: dict) -> str:
    """``readme`` with every table row of its "How they measure" section recomputed."""
    start = readme.index("### How they measure")
    end = readme.index("\n### ", start + 1)
    lines = readme[start:end].split("\n")
    for i, line in enumerate(lines):
        match = ROW.match(line)
        if match:
            scene, label = match.groups()
            metrics = report["scenes"][scene]["rows"][label]["metrics"]
            lines[i] = "| " + " | ".join([scene, f"`{label}`", *cells(metrics)]) + " |"
    return readme[:start] + "\n".join(lines) + readme[end:]


def main(argv: list[str]) -> int:
    readme_path = ROOT / "README.md"
    readme = readme_path.read_text()
    report = json.loads((ROOT / "benchmarks" / "BENCHMARKS.json").read_text())
    updated = rewrite(readme, report)
    if "--check" in argv:
        if updated != readme:
            print("README.md's table differs from benchmarks/BENCHMARKS.json; run "
                  "python benchmarks/readme_table.py", file=sys.stderr)
            return 1
        return 0
    readme_path.write_text(updated)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
