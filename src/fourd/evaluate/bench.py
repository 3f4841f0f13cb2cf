"""``fourd bench``: methods x scenes on the standard scan protocol, written up with the machine.

For every scene the ground truth is built with the standard settings (:data:`STANDARD_SCENES`),
scanned with the benchmark protocol (3 cameras, noise 0.2% of the diagonal, 2% outliers, fixed
seed; :mod:`fourd.synth.scanner`), reconstructed by every method and scored by
:func:`fourd.evaluate.metrics.evaluate`; the truth scored against itself (the floor) is the
first row of every table. Each reconstruction runs in a fresh child process (``spawn``) so that
its peak resident memory is its own and a crash or a hang (``timeout``) costs one row, not the
run; the wall time per frame is the median over ``repeats`` runs of the reconstruction call.

Outputs: ``BENCHMARKS.md`` (one table per scene, the machine, the commit), ``BENCHMARKS.json``
beside it (every metric and per-frame curve), and one PNG per scene (accuracy and
completeness and correspondence error per frame) in ``plots/`` beside it.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import math
import multiprocessing
import os
import platform
import re
import resource
import statistics
import subprocess
import time
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from fourd.errors import InputError
from fourd.evaluate.metrics import evaluate, metric_floor
from fourd.io.atomic import atomic_path
from fourd.progress import progress

log = logging.getLogger("fourd.evaluate.bench")


@dataclass(frozen=True)
class BenchScene:
    """One benchmark scene: the truth ``fourd.synth.scene(name, frames=frames, **options)``,
    scanned at ``resolution`` rays per camera side with :data:`PROTOCOL`, whose entries
    ``scan`` replaces (another scanner). ``label`` names it in the report and on the command
    line when it is not the scene's own name (another stretch of a capture)."""

    name: str
    frames: int | None = None
    options: dict = field(default_factory=dict)
    resolution: int = 256
    label: str = ""
    scan: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        """The scene's name in the report and in ``--scenes``."""
        return self.label or self.name


#: The standard settings: procedural scenes at their default 20 frames; ``crane`` frames
#: 0, 2, ..., 38; the other shared scenes all their frames (BASELINES.md protocol).
STANDARD_SCENES: tuple[BenchScene, ...] = (
    BenchScene("rigid-turn"),
    BenchScene("bending-arm"),
    BenchScene("touching-spheres"),
    BenchScene("waving-sheet"),
    BenchScene("splitting-blob"),
    BenchScene("squash-ball"),
    BenchScene("crane", frames=20, options={"start": 0, "step": 2}),
    BenchScene("horse-gallop"),
    BenchScene("elephant-gallop"),
    BenchScene("dfaust-hopping", frames=17),
)

#: Held-out motion, not run by default (``--scenes crane-50 crane-90 crane-130``): other
#: stretches of the crane capture, same step and length as the standard one, which no
#: default was tuned on (issue: "the same figures must hold on motion the project has not
#: seen"); and ``crane-still``, the first pose held still, on which the correspondence must
#: not grow.
HELD_OUT_SCENES: tuple[BenchScene, ...] = tuple(
    BenchScene("crane", frames=20, options={"start": start, "step": 2}, label=f"crane-{start}")
    for start in (50, 90, 130)
) + (
    # the first crane pose held still, scanned 20 times: nothing may drift
    BenchScene("crane", frames=20, options={"start": 0, "step": 0}, label="crane-still"),
    # the standard crane stretch seen by 8 cameras without noise or outliers: what is left
    # of a method's error is its own (its motion prior), not the scanner's
    BenchScene(
        "crane", frames=20, options={"start": 0, "step": 2}, label="crane-clean",
        scan={"cameras": 8, "noise": 0.0, "outliers": 0.0},
    ),
)

#: ``--quick``: two small procedural scenes, 4 frames, coarse cameras (CI-sized).
QUICK_SCENES: tuple[BenchScene, ...] = (
    BenchScene("squash-ball", frames=4, resolution=96),
    BenchScene("waving-sheet", frames=4, resolution=96),
)

#: The scan protocol shared by every scene (fractions of the truth's diagonal).
PROTOCOL = {"cameras": 3, "noise": 0.002, "outliers": 0.02}

#: Surface samples per surface and frame: full and quick runs.
SAMPLES, QUICK_SAMPLES = 60000, 10000

#: Peer rows (``baselines=True``): label -> function name in :mod:`fourd.evaluate.baselines`.
PEERS = {
    "poisson (open3d)": "poisson_per_frame",
    "template + nicp-amberg": "template_nicp",
    "template + nicp-sumner": "template_nicp_sumner",
}

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
)


# --------------------------------------------------------------------------------------------
# one case in a child process


#: Frames shown in each bench contact sheet (evenly spaced, first and last included).
SHEET_FRAMES = 4


def _reconstruct(kind: str, name: str, scans, log_level: int):
    """``(result, diagnostics)``: the method's own figures (:func:`fourd.methods.reconstruct_with_diagnostics`); none for peers."""
    logging.getLogger("fourd").setLevel(log_level)
    if kind == "method":
        from fourd.methods import reconstruct_with_diagnostics
        from fourd.methods.base import diagnostic_figures

        method, values = parse_method_spec(name)
        result, diagnostics = reconstruct_with_diagnostics(scans, method=method, **values)
        return result, diagnostic_figures(diagnostics)
    from fourd.evaluate import baselines

    return getattr(baselines, name)(scans), {}


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _timed_runs(kind: str, name: str, scans, repeats: int, log_level: int) -> dict:
    """Reconstruct ``repeats`` times here: ``result`` and ``diagnostics`` of the last run,
    ``seconds`` per run, ``start_mb``, ``peak_mb`` (this process's peak when the first run
    ended) and ``peak_all_mb`` (when the last ended).

    The first run's peak is what one reconstruction needs; later runs in the same process
    can raise the peak with heap the allocator kept from the earlier ones (squash-ball with
    flow at resolution 64: 3674 MiB in a single run, 3820 over three)."""
    start_mb = _peak_mb()
    seconds, peaks, result, diagnostics = [], [], None, {}
    for _ in range(repeats):
        started = time.perf_counter()
        result, diagnostics = _reconstruct(kind, name, scans, log_level)
        seconds.append(time.perf_counter() - started)
        peaks.append(_peak_mb())
    return {"result": result, "diagnostics": diagnostics, "seconds": seconds,
            "peak_mb": peaks[0] if peaks else start_mb,
            "peak_all_mb": peaks[-1] if peaks else start_mb, "start_mb": start_mb}


def _case(connection, kind: str, name: str, scans, repeats: int, log_level: int) -> None:
    """Child process body: reconstruct ``repeats`` times, send back result and measurements."""
    try:
        if not logging.getLogger().handlers:
            logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
        connection.send(_timed_runs(kind, name, scans, repeats, log_level))
    except BaseException as error:  # reported as the row's error
        connection.send({"error": f"{type(error).__name__}: {error}"})
    finally:
        connection.close()


def run_case(kind: str, name: str, scans, *, repeats: int = 1, timeout: float | None = None,
             isolate: bool = True) -> dict:
    """Reconstruct ``scans`` with method (``kind="method"``) or peer (``kind="baseline"``)
    ``name``; returns ``result``, ``diagnostics`` (the method's own figures, of the last
    repeat), ``seconds`` (per repeat), ``peak_mb`` or ``error``.

    With ``isolate`` the work runs in a fresh ``spawn`` child: ``peak_mb`` is that process's
    peak resident memory (interpreter, input and method together) over the first run
    (``peak_all_mb`` over all, see :func:`_timed_runs`) and ``timeout`` (seconds) stops it.
    Without, it runs here and the peaks are this process's so far.
    """
    level = logging.getLogger("fourd").getEffectiveLevel()
    if not isolate:
        try:
            return _timed_runs(kind, name, scans, repeats, level)
        except Exception as error:  # noqa: BLE001 - one failing case must not stop the run
            return {"error": f"{type(error).__name__}: {error}"}
    context = multiprocessing.get_context("spawn")
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(target=_case, args=(sender, kind, name, scans, repeats, level), daemon=True)
    process.start()
    sender.close()
    try:
        if not receiver.poll(timeout):
            process.kill()
            return {"error": f"timed out after {timeout:g} s"}
        try:
            answer = receiver.recv()
        except EOFError:
            answer = None
    finally:
        receiver.close()
        process.join(10)
        if process.is_alive():
            process.kill()
            process.join()
    if answer is None:
        return {"error": f"the child process died (exit status {process.exitcode}; out of memory?)"}
    return answer


# --------------------------------------------------------------------------------------------
# the run


def _select_scenes(scenes, quick: bool) -> list[BenchScene]:
    default = QUICK_SCENES if quick else STANDARD_SCENES
    if scenes is None:
        return list(default)
    table = {s.key: s for s in (default if quick else STANDARD_SCENES + HELD_OUT_SCENES)}
    from fourd.synth.scenes import SCENES

    chosen = []
    for name in scenes:
        if name in table:
            chosen.append(table[name])
        elif name in SCENES:
            chosen.append(BenchScene(name, frames=4, resolution=96) if quick else BenchScene(name))
        else:
            known = list(SCENES) + [h.key for h in HELD_OUT_SCENES]
            raise InputError(f"unknown scene {name!r}; known scenes: {', '.join(known)}")
    return chosen


def parse_method_spec(spec: str) -> tuple[str, dict[str, str]]:
    """``"flow:coherent=true,resolution=40"`` -> ``("flow", {"coherent": "true", ...})``: a
    bench row for a method with options (the spec is the row's label)."""
    name, _, rest = spec.partition(":")
    values = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"method spec {spec!r}: expected key=value, got {item!r}")
        values[key.strip()] = value.strip()
    return name.strip(), values


def _select_methods(methods, quick: bool) -> list[str]:
    from fourd.methods import METHODS, available_methods, method_options

    if methods is None:
        available = available_methods()
        if quick:
            return ["perframe"] if "perframe" in available else available[:1]
        return available
    specs = {spec: parse_method_spec(spec) for spec in methods}
    unknown = [spec for spec, (name, _) in specs.items() if name not in METHODS]
    if unknown:
        raise InputError(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(METHODS)}")
    for name, values in specs.values():  # a bad option fails here, not after the first scene
        if values:
            method_options(name, values)
    return list(methods)


def machine_info() -> dict:
    """CPU model, cores, memory, Python, date (UTC) and the fourd git commit."""
    info = {
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "memory_gb": None,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "load_average": None,
        "commit": "unknown",
    }
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                info["memory_gb"] = round(int(line.split()[1]) / 1024**2, 1)
                break
    except OSError:
        pass
    try:
        info["load_average"] = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        pass
    root = Path(__file__).resolve().parents[3]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
        info["commit"] = commit + (" (with uncommitted changes)" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return info


def run_bench(
    *,
    methods=None,
    scenes=None,
    quick: bool = False,
    repeats: int = 1,
    output: str | os.PathLike = "benchmarks/BENCHMARKS.md",
    baselines: bool = False,
    seed: int = 0,
    timeout: float | None = None,
    isolate: bool = True,
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
    output : path
        The Markdown report; ``.json`` beside it and PNG plots in ``plots/`` beside it
        (``<stem>-plots/`` when the file is not named ``BENCHMARKS.md``).
    baselines : bool
        Add the peers of BASELINES.md (:mod:`fourd.evaluate.baselines`; needs ``open3d``).
    seed : int
        Seed of the scans and the metric sampling.
    timeout : float, optional
        Seconds one reconstruction case may take (isolated runs only).
    isolate : bool
        Run each reconstruction in a fresh child process (own peak memory, crash-safe).

    Returns
    -------
    dict
        What ``BENCHMARKS.json`` holds: ``machine``, ``settings``, ``scenes`` (per scene:
        ``frames``, ``floor``, ``rows`` with per method ``metrics`` or ``error``), ``notes``,
        ``wall_seconds``, and ``paths`` (the files written).
    """
    repeats = int(repeats)
    if repeats < 1:
        raise InputError(f"repeats must be at least 1, got {repeats}")
    chosen_scenes = _select_scenes(scenes, quick)
    chosen_methods = _select_methods(methods, quick)
    output = Path(output)
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
        entry = _run_scene(bench_scene, chosen_methods, peers, samples=samples, seed=seed,
                           repeats=repeats, timeout=timeout, isolate=isolate, bar=bar,
                           sheets=_plots_dir(output),
                           made={"commit": machine["commit"], "date": machine["date"], "repeats": repeats})
        report["scenes"][bench_scene.key] = entry
    bar.close()
    report["wall_seconds"] = time.perf_counter() - started
    report["paths"] = write_report(report, output)
    return report


def _run_scene(bench_scene: BenchScene, methods, peers, *, samples, seed, repeats, timeout, isolate, bar,
               sheets: Path | None = None, made: dict | None = None) -> dict:
    """Scan one scene and run every method and peer on it. ``made`` (commit, date, repeats) is
    kept with each row, so a row merged into another report still says where it came from."""
    from fourd import synth

    entry = {"settings": asdict(bench_scene), "rows": {}}
    try:
        truth = synth.scene(bench_scene.name, frames=bench_scene.frames, seed=seed, **bench_scene.options)
        scans = synth.scan(
            truth, resolution=bench_scene.resolution, seed=seed, **{**PROTOCOL, **bench_scene.scan}
        )
    except Exception as error:  # noqa: BLE001 - a missing data file costs one scene
        entry["error"] = f"{type(error).__name__}: {error}"
        log.warning("scene %s: %s", bench_scene.key, entry["error"])
        bar.update(len(methods) + len(peers))
        return entry
    entry["frames"] = truth.frame_count
    entry["truth_kind"] = type(truth).__name__
    entry["points_per_frame"] = round(sum(len(f) for f in scans.frames) / len(scans), 1)
    entry["floor"] = metric_floor(truth, samples=samples, seed=seed)
    for kind, name, label in [("method", m, m) for m in methods] + [("baseline", fn, lb) for lb, fn in peers.items()]:
        bar.set_postfix_str(f"{bench_scene.key} / {label}")
        log.info("bench: %s on %s (%d frames)", label, bench_scene.key, len(scans))
        case = run_case(kind, name, scans, repeats=repeats, timeout=timeout, isolate=isolate)
        if "error" in case:
            log.warning("bench: %s failed on %s: %s", label, bench_scene.key, case["error"])
            entry["rows"][label] = {"error": case["error"], "made": made}
        else:
            per_frame = statistics.median(case["seconds"]) / len(scans)
            timing = {"seconds_per_frame": per_frame, "seconds": case["seconds"],
                      "peak_memory_mb": case["peak_mb"], "start_memory_mb": case["start_mb"],
                      "peak_memory_all_runs_mb": case.get("peak_all_mb", case["peak_mb"])}
            try:
                metrics = evaluate(case["result"], truth, samples=samples, seed=seed, timing=timing)
                metrics.update(case.get("diagnostics") or {})
                entry["rows"][label] = {"metrics": metrics, "made": made}
            except Exception as error:  # noqa: BLE001
                entry["rows"][label] = {"error": f"evaluation failed: {type(error).__name__}: {error}",
                                        "made": made}
            if sheets is not None:
                entry["rows"][label]["sheet"] = _contact_sheet(case["result"], truth, sheets, bench_scene.key, label)
        bar.update(1)
    return entry


def _portable(file_name: str) -> str:
    """``file_name`` with characters other than letters, digits, ``.``, ``_``, ``-`` replaced
    by ``-`` (a method spec such as ``flow:coherent=true`` is no file name on every system)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", file_name)


def _contact_sheet(result, truth, folder: Path, scene: str, label: str) -> str | None:
    """The (scene, method) contact sheet with the first-frame checker; its path, or None."""
    from fourd.viz.render import bench_sheet

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / _portable(f"{scene}-{label}.png")
    try:
        count = len(result.meshes) if hasattr(result, "meshes") else result.frame_count
        frames = sorted({int(round(i)) for i in np.linspace(0, count - 1, SHEET_FRAMES)})
        bench_sheet(result, truth, path, title=f"{scene} / {label}", frames=frames)
    except Exception as error:  # noqa: BLE001 - a picture must not cost the numbers
        log.warning("bench: no contact sheet for %s on %s: %s", label, scene, error)
        return None
    return str(path)


# --------------------------------------------------------------------------------------------
# the report


def _cell(value, kind: str) -> str:
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
    cells = [_cell(metrics.get(key), kind) for _, key, kind in COLUMNS]
    timing = metrics.get("timing") or {}
    seconds = timing.get("seconds_per_frame")
    peak = timing.get("peak_memory_mb")
    cells.append("—" if seconds is None else f"{seconds:.2f}")
    cells.append("—" if peak is None else f"{peak:.0f}")
    cells.append(_made(made))
    return f"| {label} | " + " | ".join(cells) + " |"


def _made(made: dict | None) -> str:
    """``"abc1234, 3 runs"``: the commit and repeats a row was measured with; ``"—"`` for rows
    from before rows kept it (the run history names their commits)."""
    if not made:
        return "—"
    return f"{made['commit']}, {made['repeats']} run{'s' if made['repeats'] != 1 else ''}"


def _plots_dir(output: Path) -> Path:
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
                f"| {name} | {label} | {_cell(m['chamfer'], 'd')} | {_cell(entry['floor']['chamfer'], 'd')} | "
                f"{_cell(m['completeness_95'], 'd')} | {_cell(m['correspondence_mean'], 'd')} | "
                f"{_cell(m['correspondence_last'], 'd')} | {'—' if seconds is None else f'{seconds:.2f}'} | "
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
    """A scene's scanner overrides, ``{"cameras": 8, "noise": 0.0}`` -> ``"8 cameras, noise 0"``."""
    return ", ".join(
        f"{value} cameras" if key == "cameras" else f"{key} {value:g}" for key, value in scan.items()
    )


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


def _plot_scene(name: str, entry: dict, path: Path) -> None:
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


def write_report(report: dict, output: str | os.PathLike) -> dict[str, str]:
    """Write the Markdown, the JSON and the plots of ``report``; returns their paths."""
    output = Path(output)
    plots_dir = _plots_dir(output)
    plots = {}
    for name, entry in report["scenes"].items():
        if "floor" not in entry:
            continue
        plots_dir.mkdir(parents=True, exist_ok=True)
        plots[name] = plots_dir / f"{name}.png"
        _plot_scene(name, entry, plots[name])
    paths = {"markdown": str(output), "json": str(output.with_suffix(".json")),
             "plots": [str(p) for p in plots.values()]}
    report = {**report, "paths": paths}
    with atomic_path(output.with_suffix(".json")) as tmp:
        tmp.write_text(json.dumps(report, indent=1))
    with atomic_path(output) as tmp:
        tmp.write_text(format_markdown(report, plots, output.parent))
    return paths


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
                    beside = _plots_dir(Path(part)) / Path(row["sheet"]).name
                    row["sheet"] = str(beside) if beside.exists() else None
                if row.get("sheet"):
                    target = _plots_dir(output) / _portable(Path(row["sheet"]).name)
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
