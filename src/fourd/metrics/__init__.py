"""Metrics of a reconstruction against ground truth (:func:`fourd.evaluate` is the public function).

One concept per module: :mod:`~fourd.metrics.scores` (the metrics, see its docstring),
:mod:`~fourd.metrics.sampling` (surface samples and exact closest points),
:mod:`~fourd.metrics.topology` (components, boundaries, volume), :mod:`~fourd.metrics.files`
(results and truths read from disk), :mod:`~fourd.metrics.match` (whether a truth belongs to a
result) and :mod:`~fourd.metrics.text` (the printed table).
"""

from fourd.metrics.files import evaluate_files, load_truth
from fourd.metrics.match import check_truth, truth_mismatch
from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface
from fourd.metrics.scores import evaluate, metric_floor
from fourd.metrics.text import REPORT_ROWS, format_report
from fourd.metrics.topology import Topology, enclosed_volume, topology

__all__ = [
    "REPORT_ROWS",
    "Topology",
    "bind_to_surface",
    "bound_positions",
    "check_truth",
    "enclosed_volume",
    "evaluate",
    "evaluate_files",
    "format_report",
    "load_truth",
    "metric_floor",
    "sample_surface",
    "topology",
    "truth_mismatch",
]
