"""Merging bench reports made side by side (one per scene or method) into one report."""

from __future__ import annotations

import json
import os
from pathlib import Path

from fourd.bench.report import plots_dir, portable_name, write_report
from fourd.errors import InputError

_MERGE_NOTES = ("Merged from", "Not run:", "Run by")


def merge_reports(parts: list[str | os.PathLike], output: str | os.PathLike, *, notes=()) -> dict:
    """Merge the ``.json`` reports of several bench runs (e.g. one per scene, run side by side)
    into one report at ``output``; contact sheets are copied beside it. Rows of a scene that
    several parts ran (e.g. one method each) are combined; for the same method the later part
    wins. Returns the merged report."""
    import shutil

    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    merged = None
    for part in parts:
        try:
            report = json.loads(Path(part).read_text())
        except (OSError, ValueError) as error:
            raise InputError(f"cannot read bench report ({error})", part) from None
        if merged is None:
            merged = {**report, "scenes": {}, "notes": [], "wall_seconds": 0.0}
            merged["settings"] = {**report["settings"], "methods": [], "scenes": []}
        settings = merged["settings"]
        settings["methods"] += [m for m in report["settings"]["methods"] if m not in settings["methods"]]
        settings["scenes"] += [x for x in report["settings"]["scenes"] if x not in settings["scenes"]]
        merged["notes"] += [n for n in report.get("notes", []) if n not in merged["notes"]]
        merged["wall_seconds"] += report.get("wall_seconds", 0.0)
        for name, entry in report["scenes"].items():
            for row in entry.get("rows", {}).values():
                if row.get("sheet") and not Path(row["sheet"]).exists():
                    # The part was moved (e.g. copied from another machine): look beside it.
                    beside = plots_dir(Path(part)) / Path(row["sheet"]).name
                    row["sheet"] = str(beside) if beside.exists() else None
                if row.get("sheet"):
                    target = plots_dir(output) / portable_name(Path(row["sheet"]).name)
                    target.parent.mkdir(parents=True, exist_ok=True)
                    if Path(row["sheet"]).resolve() != target.resolve():
                        shutil.copyfile(row["sheet"], target)
                    row["sheet"] = str(target)
            if name in merged["scenes"] and "rows" in merged["scenes"][name] and "rows" in entry:
                merged["scenes"][name]["rows"].update(entry["rows"])
            else:
                merged["scenes"][name] = entry
    if merged is None:
        raise InputError("no bench reports to merge")
    # Notes that describe how a part was put together are replaced by ones for the whole.
    merged["notes"] = [n for n in merged["notes"] if not n.startswith(_MERGE_NOTES)]
    merged["notes"].append(f"Merged from {len(parts)} reports; total wall time is the sum of theirs.")
    missing = [f"{name}/{method}" for name, entry in merged["scenes"].items() if "rows" in entry
               for method in merged["settings"]["methods"] if method not in entry["rows"]]
    if missing:
        merged["notes"].append(f"Not run: {', '.join(missing)}.")
    merged["notes"] += list(notes)
    merged["paths"] = write_report(merged, output)
    return merged
