"""Checks before the work: what the options, the output path and the loaded data tell before a
method starts, so that a mistake costs a second instead of a long run.

- :func:`check_output` (``fourd reconstruct``, before it loads the input): the output can be
  written (:func:`fourd.io.results.check_output`) and its format can hold the method's result
  (:func:`check_result_format`).
- :func:`check_input` (every :func:`fourd.reconstruct`, before it calls the method): frames
  with too few points (:func:`check_frame_sizes`), output times outside the input's
  (:func:`check_times`), and the memory the method will need against what the machine has
  (:func:`check_memory`, through the method's optional ``estimate_peak_bytes``, see
  :mod:`fourd.methods.base`).

A problem that spoils the run is an :class:`~fourd.errors.InputError` (one line; exit status 2
on the command line); one the run survives is a warning.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from pathlib import Path
from types import ModuleType

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.preflight")

__all__ = [
    "MIN_FRAME_POINTS",
    "available_memory",
    "check_frame_sizes",
    "check_input",
    "check_memory",
    "check_output",
    "check_result_format",
    "check_times",
]

#: Fewest points a frame needs for a surface of its own: the per-point normals and outlier
#: tests look at 16 and 8 neighbours (``perframe`` leaves a frame under
#: ``max(outlier_k, normals_k) + 2 = 18`` points empty; ``kinematic`` asks every point for 20
#: neighbours).
MIN_FRAME_POINTS = 20
#: Frames with too few points named one a line; the rest are counted in one more line.
LISTED_FRAMES = 10
#: Where :func:`available_memory` reads the machine's and the cgroup's memory.
MEMINFO = Path("/proc/meminfo")
CGROUP = Path("/sys/fs/cgroup")


def check_output(
    path: str | os.PathLike, method: str, module: ModuleType, *, create_parents: bool = False
) -> str:
    """Check that ``path`` can be written and that its format holds what ``method`` gives;
    returns the output kind (:func:`fourd.io.results.output_kind`). See
    :func:`fourd.io.results.check_output` for ``create_parents`` and the path's checks."""
    from fourd.io.results import check_output as check_path

    kind = check_path(path, create_parents=create_parents)
    check_result_format(method, module, kind, path)
    return kind


def check_result_format(
    method: str, module: ModuleType, kind: str, path: str | os.PathLike | None = None
) -> None:
    """Refuse an output ``kind`` that holds one connectivity
    (:data:`fourd.io.results.ONE_CONNECTIVITY_KINDS`, ``.pc2``) for a method whose ``RESULT``
    is only a :class:`~fourd.MeshSequence` (a mesh per frame, each with its own connectivity:
    baked into one, the cache would hold every frame's mesh in every frame). A method that may
    give either (``auto``) passes; :func:`fourd.io.pc2.write_pc2` bakes its MeshSequence."""
    from fourd.io.results import ONE_CONNECTIVITY_KINDS

    kinds = module.RESULT if isinstance(module.RESULT, tuple) else (module.RESULT,)
    if kind not in ONE_CONNECTIVITY_KINDS or AnimatedMesh in kinds:
        return
    others = [name for name in _methods_with_one_connectivity() if name != method]
    choice = f"--method {_either(others)}, or " if others else ""
    raise InputError(
        f"a .{kind} file holds one mesh connectivity for all frames, but method {method!r} "
        f"gives a mesh per frame, each with its own: use {choice}write .npz, .glb, .usd, .abc "
        "or a folder",
        path,
    )


def check_input(
    seq: PointCloudSequence, method: str, module: ModuleType, options, *, memory: bool = True
) -> None:
    """Every check of the loaded input (module docstring) before ``module.reconstruct`` runs;
    ``memory=False`` leaves out :func:`check_memory`."""
    check_frame_sizes(seq, per_frame=getattr(module, "MIN_FRAMES", 1) < 2)
    check_times(seq, options)
    if memory:
        check_memory(seq, method, module, options)


def check_frame_sizes(
    seq: PointCloudSequence, *, minimum: int = MIN_FRAME_POINTS, per_frame: bool = False
) -> list[int]:
    """Warn about each frame with fewer than ``minimum`` points, naming it (index and file);
    InputError when every frame has that few. Returns the indices of those frames.

    ``per_frame``: the method meshes each frame on its own, so such a frame comes out empty
    (else the sequence methods take its shape from the neighbouring frames)."""
    counts = np.array([len(frame) for frame in seq.frames])
    small = np.flatnonzero(counts < minimum).tolist()
    if not small:
        return small
    if len(small) == len(seq):
        most = int(np.argmax(counts))
        raise InputError(
            f"every frame has fewer than {minimum} points (the most, {counts[most]}, in frame "
            f"{most}, {seq.names[most]}): too few to reconstruct a surface from"
        )
    fate = "its mesh will be empty" if per_frame else "its shape will come from the other frames"
    for i in small[:LISTED_FRAMES]:
        log.warning(
            "frame %d (%s, time %g) has %d points, fewer than the %d a surface needs: %s",
            i,
            seq.names[i],
            seq.frames[i].time,
            counts[i],
            minimum,
            fate,
        )
    if len(small) > LISTED_FRAMES:
        log.warning(
            "and %d more frames with fewer than %d points (%s)",
            len(small) - LISTED_FRAMES,
            minimum,
            _frame_list(small[LISTED_FRAMES:]),
        )
    return small


def check_times(seq: PointCloudSequence, options) -> list[float]:
    """Warn when the options ask for output ``times`` (``--times``) outside the input's time
    range: there the result is extrapolated, no frame constrains it. Returns those times."""
    times = getattr(options, "times", None) or ()
    first, last = float(seq.times[0]), float(seq.times[-1])
    slack = 1e-9 * max(last - first, 1.0)
    outside = [float(t) for t in times if t < first - slack or t > last + slack]
    if outside:
        log.warning(
            "output times %s lie outside the input's time range %g to %g: the result there is "
            "extrapolated, no input frame constrains it",
            ", ".join(f"{t:g}" for t in outside[:LISTED_FRAMES])
            + (
                f" (and {len(outside) - LISTED_FRAMES} more)"
                if len(outside) > LISTED_FRAMES
                else ""
            ),
            first,
            last,
        )
    return outside


def check_memory(seq: PointCloudSequence, method: str, module: ModuleType, options) -> int | None:
    """Refuse a run whose estimated peak memory (the method's ``estimate_peak_bytes``)
    exceeds the memory available (:func:`available_memory`), naming the option to lower
    (the first of the method's ``MEMORY_OPTIONS``, with the others set away from their
    defaults), and suggesting windows where the method streams and they would fit. Returns
    the estimate; None (no check) for a method without the hook or when
    the available memory cannot be read."""
    estimate = getattr(module, "estimate_peak_bytes", None)
    if estimate is None:
        return None
    available = available_memory()
    if available is None:
        log.debug("available memory unknown: no memory check")
        return None
    needed = int(estimate(seq, options))
    log.debug(
        "%s: about %s of memory needed, %s available", method, _size(needed), _size(available)
    )
    if needed <= available:
        return needed
    names = tuple(getattr(module, "MEMORY_OPTIONS", ()))
    settings = _settings(options, names)
    lower = f"lower {names[0]} or" if names else "use"
    raise InputError(
        f"method {method!r} would need about {_size(needed)} of memory "
        f"({settings + ', ' if settings else ''}{len(seq)} frames; an estimate) but "
        f"{_size(available)} is available: {lower} reconstruct fewer frames"
        + (_windowed_hint(seq, estimate, options, available)
           if hasattr(module, "reconstruct_streamed") else "")
    )


#: The window :func:`check_memory` suggests: the streamed runs' default (``--stream``).
SUGGESTED_WINDOW = 20


def _windowed_hint(seq, estimate, options, available: int) -> str:
    """``, or run it window by window (...)`` for a method that streams, when its option
    ``window`` is unset and windows of :data:`SUGGESTED_WINDOW` frames would fit; else
    nothing."""
    fields = {f.name for f in dataclasses.fields(options)} if dataclasses.is_dataclass(options) else set()
    if "window" not in fields or options.window or len(seq) <= SUGGESTED_WINDOW:
        return ""
    try:
        windowed = int(estimate(seq, dataclasses.replace(options, window=SUGGESTED_WINDOW)))
    except ValueError:  # the method's other options do not allow that window
        return ""
    if windowed > available:
        return ""
    return (f", or run it window by window (--stream, or --set window={SUGGESTED_WINDOW}: "
            f"about {_size(windowed)})")


def available_memory() -> int | None:
    """Bytes this process can still allocate: ``MemAvailable`` of ``/proc/meminfo``, or less
    where a cgroup (v2) limit leaves less; psutil's figure where ``/proc`` cannot be read;
    None when neither tells."""
    available = None
    try:
        for line in MEMINFO.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
                break
    except (OSError, ValueError, IndexError):
        available = None
    if available is None:
        try:
            import psutil
        except ImportError:
            return None
        return int(psutil.virtual_memory().available)
    room = _cgroup_room()
    return available if room is None else min(available, room)


def _cgroup_room() -> int | None:
    """What this process's cgroup (v2) limit still allows: ``memory.max - memory.current``
    plus the page cache it may reclaim (``inactive_file``); None without a limit."""
    try:
        limit = (CGROUP / "memory.max").read_text().strip()
        if limit == "max":
            return None
        used = int((CGROUP / "memory.current").read_text().strip())
    except (OSError, ValueError):
        return None
    reclaimable = 0
    try:
        for line in (CGROUP / "memory.stat").read_text().splitlines():
            if line.startswith("inactive_file "):
                reclaimable = int(line.split()[1])
                break
    except (OSError, ValueError, IndexError):
        pass
    return max(int(limit) - used + reclaimable, 0)


def _settings(options, names: tuple[str, ...]) -> str:
    """``resolution=100000`` and the other ``names`` whose value is not the default."""
    defaults = {f.name: f.default for f in dataclasses.fields(options)}
    shown = [
        f"{name}={getattr(options, name)}"
        for k, name in enumerate(names)
        if hasattr(options, name) and (k == 0 or getattr(options, name) != defaults.get(name))
    ]
    return ", ".join(shown)


def _size(count: int) -> str:
    gib = count / 2**30
    if gib < 1:
        return f"{count / 2**20:.0f} MiB"
    return f"{gib:.1f} GiB" if gib < 1000 else f"{gib:.3g} GiB"


def _either(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]


def _frame_list(indices: list[int]) -> str:
    text = ", ".join(map(str, indices[:20]))
    return text + ", ..." if len(indices) > 20 else text


def _methods_with_one_connectivity() -> list[str]:
    """Registered methods whose result may be an AnimatedMesh (import on demand)."""
    from fourd.methods import METHODS, method_module

    names = []
    for name in METHODS:
        try:
            kinds = method_module(name).RESULT
        except InputError:
            continue
        if AnimatedMesh in (kinds if isinstance(kinds, tuple) else (kinds,)):
            names.append(name)
    return names
