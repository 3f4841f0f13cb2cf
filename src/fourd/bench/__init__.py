"""``fourd bench``: methods x scenes on the standard scan protocol, written up with the machine.

One concept per module: :mod:`~fourd.bench.suite` (scenes, protocol, method specs, peers),
:mod:`~fourd.bench.case` (one reconstruction in a child process), :mod:`~fourd.bench.runner`
(the run), :mod:`~fourd.bench.machine`, :mod:`~fourd.bench.report` (BENCHMARKS.md and .json),
:mod:`~fourd.bench.plots`, :mod:`~fourd.bench.merge` (reports made side by side) and
:mod:`~fourd.bench.peers` (the peers of BASELINES.md).
"""

from fourd.bench.case import run_case
from fourd.bench.machine import machine_info
from fourd.bench.merge import merge_reports
from fourd.bench.report import COLUMNS, format_cell, format_markdown, write_report
from fourd.bench.runner import DEFAULT_OUTPUT, QUICK_OUTPUT, RECORD, default_output, run_bench
from fourd.bench.suite import (
    APPEARANCE_SCENES,
    GARMENT_BENCH_SCENES,
    GARMENT_HELD_OUT_SCENES,
    HELD_OUT_SCENES,
    PEERS,
    PROTOCOL,
    QUICK_SAMPLES,
    QUICK_SCENES,
    SAMPLES,
    STANDARD_SCENES,
    BenchScene,
    parse_method_spec,
)

__all__ = [
    "COLUMNS",
    "DEFAULT_OUTPUT",
    "QUICK_OUTPUT",
    "RECORD",
    "APPEARANCE_SCENES",
    "GARMENT_BENCH_SCENES",
    "GARMENT_HELD_OUT_SCENES",
    "HELD_OUT_SCENES",
    "PEERS",
    "PROTOCOL",
    "QUICK_SAMPLES",
    "QUICK_SCENES",
    "SAMPLES",
    "STANDARD_SCENES",
    "BenchScene",
    "default_output",
    "format_cell",
    "format_markdown",
    "machine_info",
    "merge_reports",
    "parse_method_spec",
    "run_bench",
    "run_case",
    "write_report",
]
