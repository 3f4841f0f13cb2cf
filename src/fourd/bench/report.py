"""The bench report: ``BENCHMARKS.md`` (summary, one table per scene, run history) and
``BENCHMARKS.json`` beside it, with the plots in ``plots/`` beside them."""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

from fourd.bench.plots import plot_scene
from fourd.io.atomic import atomic_path

#: Table columns: (label, metric key, kind).
COLUMNS = (
    ("accuracy", "accuracy", "d"),
    ("completeness", "completeness", "d"),
    ("Chamfer", "chamfer", "d"),
    ("compl. 95%", "completeness_95", "d"),
    ("corr mean", "correspondence_mean", "d"),
    ("corr first", "correspondence_first", "d"),
    ("corr last", "correspondence_last", "d"),
    ("jitter", "jitter", "r"),
    ("vol. change", "volume_change", "r"),
    ("closed & manifold", "closed_manifold", "%"),
    ("mass err.", "mass_conservation_error", "%1"),
    ("fold recall", "fold_recall", "%"),
)


def portable_name(file_name: str) -> str:
    """``file_name`` with characters other than letters, digits, ``.``, ``_``, ``-`` replaced
    by ``-`` (a method spec such as ``flow:coherent=true`` is no file name on every system)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", file_name)


def format_cell(value, kind: str) -> str:
    """One table cell: ``kind`` ``"d"`` a distance (4 decimals), ``"r"`` a ratio (2), ``"%"``
    and ``"%1"`` a percentage (0 and 1 decimals); ``"—"`` for a missing or non-finite value.

    >>> format_cell(0.01234, "d"), format_cell(0.5, "%"), format_cell(None, "r")
    ('0.0123', '50%', '—')
    """
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if kind == "%":
        return f"{100 * value:.0f}%"
    if kind == "%1":
        return f"{100 * value:.1f}%"
    if kind == "r":
        return f"{value:.2f}"
    return f"{value:.4f}"


def _row(label: str, metrics: dict, made: dict | None = None) -> str:
    cells = [format_cell(metrics.get(key), kind) for _, key, kind in COLUMNS]
    timing = metrics.get("timing") or {}
    seconds = timing.get("seconds_per_frame")
    peak = timing.get("peak_memory_mb")
    cells.append("—" if seconds is None else f"{seconds:.2f}")
    cells.append("—" if peak is None else f"{peak:.0f}")
    cells.append(_made(made))
    return f"| {label} | " + " | ".join(cells) + " |"


def _spread_line(label: str, metrics: dict) -> str:
    """``"- surfels over 5 moved runs: Chamfer 0.0034-0.0038, ..."``: the ranges of a row's
    scores (:func:`fourd.bench.spread.combined_metrics`)."""
    ranges = [
        f"{title} {format_cell(low, kind)}-{format_cell(high, kind)}"
        for title, key, kind in COLUMNS
        if key in metrics["spread"]
        for low, high in [metrics["spread"][key]]
    ]
    seconds = metrics["spread"].get("seconds_per_frame")
    return (f"- {label} over {metrics.get('runs', '?')} moved runs: " + ", ".join(ranges)
            + ("" if seconds is None else f"; s/frame {seconds[0]:.2f}-{seconds[1]:.2f}") + ".")


def _made(made: dict | None) -> str:
    """``"abc1234, 3 runs"``: the commit and repeats a row was measured with (``"abc1234,
    median of 5 moved runs"``: its scores the medians of ``fourd bench --spread 5``); ``"—"``
    for rows from before rows kept it (the run history names their commits)."""
    if not made:
        return "—"
    if made.get("spread", 1) > 1:
        return f"{made['commit']}, median of {made['spread']} moved runs"
    return f"{made['commit']}, {made['repeats']} run{'s' if made['repeats'] != 1 else ''}"


def plots_dir(output: Path) -> Path:
    return output.parent / ("plots" if output.stem == "BENCHMARKS" else f"{output.stem}-plots")


def format_markdown(report: dict, plots: dict[str, Path] | None = None, base: Path | None = None) -> str:
    """The Markdown of a :func:`run_bench` report."""
    machine, settings = report["machine"], report["settings"]
    lines = [
        "# fourd benchmark",
        "",
        f"Written by `fourd bench{' --quick' if settings['quick'] else ''}` on {machine['date']}; "
        f"fourd commit {machine['commit']}.",
        "",
        f"- Machine: {machine['cpu']}, {machine['cores']} cores, {machine['memory_gb']} GB memory, "
        f"Python {machine['python']}; load average at the start {machine['load_average']} "
        "(the machine may be shared: timings are indicative).",
        f"- Scan protocol: {settings['protocol']['cameras']} cameras, noise "
        f"{settings['protocol']['noise']:.1%} of the diagonal along the ray, "
        f"{settings['protocol']['outliers']:.0%} uniform outliers, seed {settings['seed']}.",
        f"- Metrics: distances as fractions of the truth's bounding-box diagonal, "
        f"{settings['samples']:,} surface samples per surface and frame; the floor row is the truth "
        "scored against itself with independent samples. Correspondence and jitter need an "
        "AnimatedMesh result (— otherwise); jitter 1 = as smooth as the truth; volume change "
        "(max-min)/mean only when every frame is closed; mass err.: the method's own mass "
        "conservation error (flow: standard deviation of the total mass over frames relative "
        "to its mean). s/frame: median wall time of the "
        f"reconstruction over {settings['repeats']} run(s) per frame; peak MB: peak resident "
        "memory of the process that ran it, at the end of its first run.",
        f"- Total wall time of this run: {report.get('wall_seconds', 0):.0f} s.",
    ]
    if any((row.get("made") or {}).get("spread", 1) > 1
           for entry in report["scenes"].values() for row in entry.get("rows", {}).values()):
        lines.append("- Rows \"median of N moved runs\" (`fourd bench --spread N`): each score the "
                     "median of N runs on the scans moved by seeded offsets of 1e-9 of their "
                     "diagonal, the first unmoved (how far rounding alone moves them); their "
                     "ranges under the scene's table.")
    if report.get("notes"):
        lines.append("- How each row was made (commit, repeats, what changed): the run history at the end.")
    lines += ["", "## Summary", "",
              "| scene | method | Chamfer | floor | compl. 95% | corr mean | corr last | s/frame | measured at |",
              "|---|---|---|---|---|---|---|---|---|"]
    for name, entry in report["scenes"].items():
        for label, row in entry.get("rows", {}).items():
            if "error" in row:
                lines.append(f"| {name} | {label} | failed | | | | | | {_made(row.get('made'))} |")
                continue
            m = row["metrics"]
            seconds = (m.get("timing") or {}).get("seconds_per_frame")
            lines.append(
                f"| {name} | {label} | {format_cell(m['chamfer'], 'd')} | {format_cell(entry['floor']['chamfer'], 'd')} | "
                f"{format_cell(m['completeness_95'], 'd')} | {format_cell(m['correspondence_mean'], 'd')} | "
                f"{format_cell(m['correspondence_last'], 'd')} | {'—' if seconds is None else f'{seconds:.2f}'} | "
                f"{_made(row.get('made'))} |"
            )
    header = "| method | " + " | ".join(c[0] for c in COLUMNS) + " | s/frame | peak MB | measured at |"
    rule = "|" + "---|" * (len(COLUMNS) + 4)
    for name, entry in report["scenes"].items():
        lines += ["", f"## {name}", ""]
        if "error" in entry:
            lines.append(f"Not run: {entry['error']}")
            continue
        s = entry["settings"]
        lines.append(
            f"{_describe(s.get('name', name), s.get('options'))}{entry['frames']} frames "
            f"({entry['truth_kind']}), scanned at "
            f"{s['resolution']}² rays per camera, {entry['points_per_frame']:,.0f} points per frame"
            + (f" (scanner: {_scanner(s['scan'])})." if s.get("scan") else ".")
        )
        lines += ["", header, rule, _row("floor (truth vs itself)", entry["floor"])]
        for label, row in entry["rows"].items():
            if "error" in row:
                message = row["error"].replace("|", "/").replace("\n", " ")[:200]
                lines.append(f"| {label} | failed: {message} |" + " |" * (len(COLUMNS) + 1)
                             + f" {_made(row.get('made'))} |")
            else:
                lines.append(_row(label, row["metrics"], row.get("made")))
        for label, row in entry["rows"].items():
            if (row.get("metrics") or {}).get("spread"):
                lines += ["", _spread_line(label, row["metrics"])]
        if plots and name in plots:
            relative = os.path.relpath(plots[name], base) if base else plots[name]
            lines += ["", f"![{name}: accuracy, completeness and correspondence error per frame]({relative})"]
        for label, row in entry["rows"].items():
            if row.get("sheet"):
                relative = os.path.relpath(row["sheet"], base) if base else row["sheet"]
                lines += ["", f"{label}, checker painted on the first frame (drift swims, filled-in regions blue):",
                          "", f"![{name} / {label}]({relative})"]
    if report.get("notes"):
        lines += ["", "## Run history", ""] + [f"- {note}" for note in report["notes"]]
    return "\n".join(lines) + "\n"


def _scanner(scan: dict) -> str:
    """A scene's scanner overrides, ``{"cameras": 8, "noise": 0.0}`` -> ``"8 cameras, noise 0"``;
    ``{"mode": "remeshed"}`` -> ``"per-frame meshes of the true surface, remeshed ..."``."""
    def one(key, value):
        if key == "cameras":
            return f"{value} cameras"
        if key == "mode" and value == "remeshed":
            return ("per-frame meshes of the true surface, each frame remeshed on its own at "
                    "the rays' spacing, without noise or outliers")
        return f"{key} {value:g}" if isinstance(value, (int, float)) else f"{key} {value}"

    return ", ".join(one(key, value) for key, value in scan.items())


def _describe(name: str, options: dict | None = None) -> str:
    try:
        from fourd.synth.scenes import SCENES
    except ImportError:
        return ""
    if name not in SCENES:
        return ""
    text = f"{SCENES[name][0].upper()}{SCENES[name][1:]}. "
    if options and options.get("step") == 0:
        text += f"Frame {options.get('start', 0)} held still (each frame scanned anew). "
    elif options and options.get("start"):
        text += f"From frame {options['start']} on. "
    return text


def write_report(report: dict, output: str | os.PathLike) -> dict[str, str]:
    """Write the Markdown, the JSON and the plots of ``report``; returns their paths."""
    output = Path(output)
    folder = plots_dir(output)
    plots = {}
    for name, entry in report["scenes"].items():
        if "floor" not in entry:
            continue
        folder.mkdir(parents=True, exist_ok=True)
        plots[name] = folder / f"{name}.png"
        plot_scene(name, entry, plots[name])
    paths = {"markdown": str(output), "json": str(output.with_suffix(".json")),
             "plots": [str(p) for p in plots.values()]}
    report = {**report, "paths": paths}
    with atomic_path(output.with_suffix(".json")) as tmp:
        tmp.write_text(json.dumps(_record(report), separators=(",", ":")))
    with atomic_path(output) as tmp:
        tmp.write_text(format_markdown(report, plots, output.parent))
    return paths


#: The per-frame curves the report keeps (those :func:`~.plots.plot_scene` draws), and their
#: significant digits: the rest of ``evaluate``'s per-frame lists stay out of the record, whose
#: scalars are all the tables read.
RECORD_CURVES = ("accuracy", "completeness", "correspondence")
RECORD_DIGITS = 4


def _record(value):
    """``value`` (a report or a part of one) with every ``per_frame`` table cut to
    :data:`RECORD_CURVES` at :data:`RECORD_DIGITS` significant digits."""
    if isinstance(value, list):
        return [_record(item) for item in value]
    if not isinstance(value, dict):
        return value
    out = {}
    for key, item in value.items():
        if key == "per_frame" and isinstance(item, dict):
            out[key] = {
                name: None if item[name] is None
                else [None if x is None else float(f"{x:.{RECORD_DIGITS}g}") for x in item[name]]
                for name in RECORD_CURVES if name in item
            }
        else:
            out[key] = _record(item)
    return out
