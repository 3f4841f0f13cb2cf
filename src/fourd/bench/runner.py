"""``fourd bench``: methods x scenes on the standard scan protocol, written up with the machine.

For every scene the ground truth is built with the standard settings (:data:`STANDARD_SCENES`),
scanned with the benchmark protocol (3 cameras, noise 0.2% of the diagonal, 2% outliers, fixed
seed; :mod:`fourd.synth.scanner`), reconstructed by every method and scored by
:func:`fourd.metrics.evaluate`; the truth scored against itself (the floor) is the
first row of every table. Each reconstruction runs in a fresh child process (``spawn``) so that
its peak resident memory is its own and a crash or a hang (``timeout``) costs one row, not the
run; the wall time per frame is the median over ``repeats`` runs of the reconstruction call.

Outputs: ``BENCHMARKS.md`` (one table per scene, the machine, the commit), ``BENCHMARKS.json``
beside it (every metric and per-frame curve), and one PNG per scene (accuracy and
completeness and correspondence error per frame) in ``plots/`` beside it. By default they go
to the git-ignored ``benchmarks/out/`` (:data:`DEFAULT_OUTPUT`, :data:`QUICK_OUTPUT`), so a
run never overwrites the tracked record, ``benchmarks/BENCHMARKS.md`` (:data:`RECORD`), which
only an explicit ``output`` (``fourd bench -o benchmarks/BENCHMARKS.md``) rewrites.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import statistics
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from fourd.bench.case import run_case
from fourd.bench.machine import machine_info
from fourd.bench.report import plots_dir, portable_name, write_report
from fourd.bench.spread import combined_metrics, moved_scans
from fourd.bench.suite import (
    PEERS,
    PROTOCOL,
    QUICK_SAMPLES,
    SAMPLES,
    BenchScene,
    scan_scene,
    select_methods,
    select_scenes,
)
from fourd.errors import InputError
from fourd.metrics import evaluate, metric_floor
from fourd.progress import progress
from fourd.synth.garments import GARMENT_SCENES, pattern_outline
from fourd.synth.write import write_pattern_photo

log = logging.getLogger("fourd.bench")

#: In a method spec, ``photo=scene`` stands for the scene's own photo of the garment laid out
#: flat (``garment:boundaries=4,photo=scene``; issue 54, the thesis' template of 3.7), which the
#: bench writes for the run; the row keeps the spec as its label.
SCENE_PHOTO = "photo=scene"


#: Where a run writes its report unless told otherwise (git-ignored).
DEFAULT_OUTPUT = Path("benchmarks/out/BENCHMARKS.md")

#: The same for a ``quick`` run.
QUICK_OUTPUT = Path("benchmarks/out/BENCHMARKS-quick.md")

#: The tracked benchmark record (the README's table is read from its ``.json``).
RECORD = Path("benchmarks/BENCHMARKS.md")


def default_output(quick: bool = False) -> Path:
    """The report a run writes when no output is named: :data:`QUICK_OUTPUT` for a quick run,
    else :data:`DEFAULT_OUTPUT`; never the tracked :data:`RECORD`."""
    return QUICK_OUTPUT if quick else DEFAULT_OUTPUT


#: Frames shown in each bench contact sheet (evenly spaced, first and last included).
SHEET_FRAMES = 4


def run_bench(
    *,
    methods=None,
    scenes=None,
    quick: bool = False,
    repeats: int = 1,
    spread: int = 1,
    output: str | os.PathLike | None = None,
    baselines: bool = False,
    seed: int = 0,
    timeout: float | None = None,
    isolate: bool = True,
    appearance: str | None = None,
    video: bool = False,
) -> dict:
    """Run methods x scenes, score them against the truth, write the report.

    Parameters
    ----------
    methods : list of str, optional
        Method names (default: every available method; ``quick``: ``perframe``).
    scenes : list of str, optional
        Scene names (default: :data:`STANDARD_SCENES`, or :data:`QUICK_SCENES` with ``quick``).
    quick : bool
        A CI-sized run: 4 frames, coarse cameras, fewer metric samples.
    repeats : int
        Reconstructions per case; the wall time is their median.
    spread : int
        Runs per case on scans moved far below their noise (:mod:`fourd.bench.spread`; run
        0 unmoved): every score the median over them, with its range (``spread`` in the
        row's metrics); 1: the scans as they are, once.
    output : path, optional
        The Markdown report; ``.json`` beside it and PNG plots in ``plots/`` beside it
        (``<stem>-plots/`` when the file is not named ``BENCHMARKS.md``). Default:
        :func:`default_output` (``benchmarks/out/``, git-ignored).
    baselines : bool
        Add the peers of BASELINES.md (:mod:`fourd.bench.peers`; needs ``open3d``).
    seed : int
        Seed of the scans and the metric sampling.
    timeout : float, optional
        Seconds one reconstruction case may take (isolated runs only).
    isolate : bool
        Run each reconstruction in a fresh child process (own peak memory, crash-safe).
    appearance : {None, "skin", "cloth", "uniform"}
        Scan every scene with this surface colour (replaces each :class:`BenchScene`'s).
    video : bool
        Give the methods the rig's video too (needs an appearance).

    Returns
    -------
    dict
        What ``BENCHMARKS.json`` holds: ``machine``, ``settings``, ``scenes`` (per scene:
        ``frames``, ``floor``, ``rows`` with per method ``metrics`` or ``error``), ``notes``,
        ``wall_seconds``, and ``paths`` (the files written).
    """
    repeats = int(repeats)
    spread = int(spread)
    if repeats < 1 or spread < 1:
        raise InputError(f"repeats and spread must be at least 1, got {repeats} and {spread}")
    chosen_scenes = select_scenes(scenes, quick)
    if appearance is not None or video:
        chosen_scenes = [
            replace(s, appearance=appearance or s.appearance, video=video or s.video)
            for s in chosen_scenes
        ]
    chosen_methods = select_methods(methods, quick)
    output = default_output(quick) if output is None else Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    samples = QUICK_SAMPLES if quick else SAMPLES
    notes = []
    peers = {}
    if baselines:
        if importlib.util.find_spec("open3d") is None:
            notes.append("open3d is not installed (pip install 'fourd[baselines]'): the peer rows are skipped.")
            log.warning(notes[-1])
        else:
            peers = dict(PEERS)
    started = time.perf_counter()
    machine = machine_info()
    report = {
        "machine": machine,
        "settings": {
            "methods": chosen_methods,
            "peers": list(peers),
            "quick": quick,
            "repeats": repeats,
            "spread": spread,
            "seed": seed,
            "samples": samples,
            "protocol": PROTOCOL,
            "scenes": [asdict(s) for s in chosen_scenes],
        },
        "scenes": {},
        "notes": notes,
    }
    cases = [(s, kind, name, label) for s in chosen_scenes
             for kind, name, label in [("method", m, m) for m in chosen_methods]
             + [("baseline", fn, label) for label, fn in peers.items()]]
    bar = progress(total=len(cases), desc="bench", unit="case")
    for bench_scene in chosen_scenes:
        made = {"commit": machine["commit"], "date": machine["date"], "repeats": repeats}
        if spread > 1:
            made["spread"] = spread
        entry = _run_scene(bench_scene, chosen_methods, peers, samples=samples, seed=seed,
                           repeats=repeats, spread=spread, timeout=timeout, isolate=isolate,
                           bar=bar, sheets=plots_dir(output), made=made)
        report["scenes"][bench_scene.key] = entry
    bar.close()
    report["wall_seconds"] = time.perf_counter() - started
    report["paths"] = write_report(report, output)
    return report


def _run_scene(bench_scene: BenchScene, methods, peers, *, samples, seed, repeats, timeout, isolate, bar,
               sheets: Path | None = None, made: dict | None = None, spread: int = 1) -> dict:
    """Scan one scene and run every method and peer on it. ``made`` (commit, date, repeats,
    spread) is kept with each row, so a row merged into another report still says where it
    came from."""
    entry = {"settings": asdict(bench_scene), "rows": {}}
    try:
        truth, scans = scan_scene(bench_scene, seed)
    except Exception as error:  # noqa: BLE001 - a missing data file costs one scene
        entry["error"] = f"{type(error).__name__}: {error}"
        log.warning("scene %s: %s", bench_scene.key, entry["error"])
        bar.update(len(methods) + len(peers))
        return entry
    entry["frames"] = truth.frame_count
    entry["truth_kind"] = type(truth).__name__
    entry["points_per_frame"] = round(sum(len(f) for f in scans.frames) / len(scans), 1)
    entry["floor"] = metric_floor(truth, samples=samples, seed=seed)
    with tempfile.TemporaryDirectory(prefix="fourd-bench-") as scene_files:
        for kind, name, label in [("method", m, m) for m in methods] + [("baseline", fn, lb) for lb, fn in peers.items()]:
            bar.set_postfix_str(f"{bench_scene.key} / {label}")
            _run_row(entry, bench_scene, truth, scans, kind, name, label, Path(scene_files), samples=samples, seed=seed,
                     repeats=repeats, spread=spread, timeout=timeout, isolate=isolate, sheets=sheets,
                     made=made)
            bar.update(1)
    return entry


def _with_scene_files(spec: str, bench_scene: BenchScene, folder: Path) -> str:
    """``spec`` with :data:`SCENE_PHOTO` replaced by the path of the scene's photo, written
    into ``folder`` the first time."""
    if SCENE_PHOTO not in spec:
        return spec
    if bench_scene.name not in GARMENT_SCENES:
        raise InputError(f"{spec}: scene {bench_scene.key} has no photo of a garment ({SCENE_PHOTO})")
    photo = folder / "pattern.png"
    if not photo.exists():
        photo = write_pattern_photo(pattern_outline(bench_scene.name, with_openings=True), folder)
    return spec.replace(SCENE_PHOTO, f"photo={photo}")


def _run_row(entry, bench_scene, truth, scans, kind, name, label, scene_files, *, samples, seed, repeats, timeout,
             isolate, sheets, made, spread: int = 1) -> None:
    """One method's (or peer's) row of the scene, into ``entry["rows"][label]``: with
    ``spread`` > 1 the median of as many runs on moved scans (:mod:`fourd.bench.spread`), the
    contact sheet of the unmoved one."""
    log.info("bench: %s on %s (%d frames)", label, bench_scene.key, len(scans))
    try:
        name = _with_scene_files(name, bench_scene, scene_files) if kind == "method" else name
    except InputError as error:
        log.warning("bench: %s", error)
        entry["rows"][label] = {"error": str(error), "made": made}
        return
    runs, first = [], None
    for run in range(spread):
        if spread > 1:
            log.info("bench: %s on %s, run %d of %d", label, bench_scene.key, run + 1, spread)
        case = run_case(kind, name, moved_scans(scans, run), repeats=repeats, timeout=timeout,
                        isolate=isolate)
        if "error" in case:
            log.warning("bench: %s failed on %s: %s", label, bench_scene.key, case["error"])
            entry["rows"][label] = {"error": case["error"], "made": made}
            return
        per_frame = statistics.median(case["seconds"]) / len(scans)
        timing = {"seconds_per_frame": per_frame, "seconds": case["seconds"],
                  "peak_memory_mb": case["peak_mb"], "start_memory_mb": case["start_mb"],
                  "peak_memory_all_runs_mb": case.get("peak_all_mb", case["peak_mb"])}
        try:
            metrics = evaluate(case["result"], truth, samples=samples, seed=seed, timing=timing,
                               folds=bench_scene.name in GARMENT_SCENES)
            metrics.update(case.get("diagnostics") or {})
        except Exception as error:  # noqa: BLE001
            entry["rows"][label] = {"error": f"evaluation failed: {type(error).__name__}: {error}", "made": made}
            return
        runs.append(metrics)
        first = case["result"] if first is None else first
    entry["rows"][label] = {"metrics": runs[0] if spread == 1 else combined_metrics(runs), "made": made}
    if sheets is not None:
        entry["rows"][label]["sheet"] = _contact_sheet(first, truth, sheets, bench_scene.key, label)


def _contact_sheet(result, truth, folder: Path, scene: str, label: str) -> str | None:
    """The (scene, method) contact sheet with the first-frame checker; its path, or None."""
    from fourd.viz.render import bench_sheet

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / portable_name(f"{scene}-{label}.png")
    try:
        count = len(result.meshes) if hasattr(result, "meshes") else result.frame_count
        frames = sorted({int(round(i)) for i in np.linspace(0, count - 1, SHEET_FRAMES)})
        bench_sheet(result, truth, path, title=f"{scene} / {label}", frames=frames)
    except Exception as error:  # noqa: BLE001 - a picture must not cost the numbers
        log.warning("bench: no contact sheet for %s on %s: %s", label, scene, error)
        return None
    return str(path)
