"""The human-readable table of a metrics report (what ``fourd evaluate`` prints)."""

from __future__ import annotations

#: (key, label) of the scalars :func:`format_report` shows, in order.
REPORT_ROWS = (
    ("accuracy", "accuracy (result -> truth), mean"),
    ("accuracy_95", "accuracy, 95th percentile"),
    ("completeness", "completeness (truth -> result), mean"),
    ("completeness_95", "completeness, 95th percentile"),
    ("chamfer", "Chamfer (mean of the two means)"),
    ("completeness_observed", "completeness near observed output"),
    ("completeness_filled", "completeness near filled-in output"),
    ("filled_fraction", "truth covered by filled-in output"),
    ("correspondence_mean", "correspondence error, mean"),
    ("correspondence_first", "correspondence error, first frame"),
    ("correspondence_last", "correspondence error, last frame"),
    ("correspondence_slope", "correspondence trend, per 100 frames"),
    ("jitter", "jitter (output / truth, 1 = as smooth)"),
    ("volume_change", "relative volume change"),
    ("truth_volume_change", "truth's relative volume change"),
    ("closed_manifold", "frames closed and manifold"),
    ("components_max", "connected components (max)"),
    ("boundary_loops_max", "boundary loops (max)"),
    ("nonmanifold_edges_max", "non-manifold edges (max)"),
    ("pinched_vertices_max", "pinched vertices (max)"),
    ("fold_recall", "truth folds found"),
)


def _fmt(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    return f"{value:.4f}" if abs(value) < 1000 else f"{value:.4g}"


def format_report(metrics: dict) -> str:
    """A short human-readable table of :func:`evaluate`'s scalars (and the floor, if present)."""
    floor = metrics.get("floor")
    lines = [
        f"{metrics.get('frames')} frames, {metrics.get('result_kind')}; distances as fractions of "
        f"the truth's diagonal ({_fmt(metrics.get('diagonal'))} units)"
    ]
    width = max(len(label) for _, label in REPORT_ROWS)
    header = f"{'metric':<{width}}  {'value':>10}" + (f"  {'floor':>10}" if floor else "")
    lines += [header, "-" * len(header)]
    for key, label in REPORT_ROWS:
        row = f"{label:<{width}}  {_fmt(metrics.get(key)):>10}"
        if floor:
            row += f"  {_fmt(floor.get(key)):>10}"
        lines.append(row)
    timing = metrics.get("timing") or {}
    for key, value in timing.items():
        lines.append(f"{key:<{width}}  {_fmt(value):>10}")
    return "\n".join(lines)
