"""The plot of one bench scene: accuracy, completeness and correspondence error per frame."""

from __future__ import annotations

from pathlib import Path

from fourd.io.atomic import atomic_path


def plot_scene(name: str, entry: dict, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    figure = Figure(figsize=(15, 3.8), dpi=100)
    FigureCanvasAgg(figure)
    accuracy_axes, completeness_axes, correspondence_axes = figure.subplots(1, 3)
    floor = entry["floor"]["per_frame"]
    accuracy_axes.plot(floor["accuracy"], "k--", label="floor", linewidth=1)
    completeness_axes.plot(floor["completeness"], "k--", label="floor", linewidth=1)
    plotted = False
    for index, (label, row) in enumerate(entry["rows"].items()):
        if "metrics" not in row:
            continue
        style = {"marker": ".", "label": label, "color": f"C{index % 10}"}  # one colour per method
        curves = row["metrics"]["per_frame"]
        accuracy_axes.plot(curves["accuracy"], **style)
        completeness_axes.plot(curves["completeness"], **style)
        if curves["correspondence"] is not None:
            correspondence_axes.plot(curves["correspondence"], **style)
            plotted = True
    accuracy_axes.set(title=f"{name}: accuracy (result to truth)", xlabel="frame",
                      ylabel="fraction of diagonal")
    completeness_axes.set(title=f"{name}: completeness (truth to result)", xlabel="frame")
    correspondence_axes.set(title=f"{name}: correspondence error", xlabel="frame")
    accuracy_axes.legend(fontsize=8)
    if plotted:
        correspondence_axes.legend(fontsize=8)
    else:
        correspondence_axes.text(0.5, 0.5, "no AnimatedMesh result", ha="center", va="center",
                                 transform=correspondence_axes.transAxes)
    for axes in (accuracy_axes, completeness_axes, correspondence_axes):
        axes.xaxis.set_major_locator(MaxNLocator(integer=True))
        axes.set_ylim(bottom=0)
        axes.grid(alpha=0.3)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
