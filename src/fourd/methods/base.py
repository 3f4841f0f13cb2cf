"""The method contract: what a module in :data:`fourd.methods.METHODS` provides.

A method module (or package) exposes

- ``Options``: a frozen dataclass, every field with a default and documented in the numpy
  ``Attributes`` section of its docstring (read by ``fourd options``);
- ``MIN_FRAMES``: the fewest input frames it accepts (1 for per-frame methods, 2 for
  sequence methods);
- ``RESULT``: the kind of result, :class:`~fourd.AnimatedMesh` (one connectivity) or
  :class:`~fourd.MeshSequence` (a mesh per frame), or a tuple of both for a method whose
  result depends on the data (``auto``: a MeshSequence where the shape splits);
- ``reconstruct(seq, options) -> RESULT``;
- optionally ``reconstruct_with_diagnostics(seq, options) -> Reconstruction``, when the
  method has figures of its own (``flow``'s mass conservation error): the result and a frozen
  dataclass of floats, the same type whatever the options;
- optionally ``estimate_peak_bytes(seq, options) -> int``, for a method whose memory grows
  with its options (a grid's ``resolution``): the peak memory a run will need beyond what the
  process holds, estimated from the options and the data in well under a second and without
  allocating what it estimates, on the high side (``flow``: :mod:`fourd.methods.flow.memory`).
  :func:`fourd.preflight.check_memory` refuses a run whose estimate exceeds the available
  memory, naming the first of ``MEMORY_OPTIONS`` (a tuple of option names the estimate grows
  with, the one to lower first), which goes with the hook;
- optionally ``COMMON_OPTIONS``: a tuple naming the few options users change first, in the
  order ``fourd options METHOD`` shows them (the others are listed by name and described under
  ``--all``); without it every option is shown as common.

:func:`check_method_module` checks a module against this contract; a test runs it on every
registry entry.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import ModuleType
from typing import Any, NamedTuple, Protocol, runtime_checkable

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.sequence import PointCloudSequence

__all__ = [
    "MethodModule",
    "Reconstruction",
    "StreamSummary",
    "check_method_module",
    "diagnostic_figures",
]


class Reconstruction(NamedTuple):
    """A method's result with its own figures.

    result : AnimatedMesh or MeshSequence, the method's ``RESULT``.
    diagnostics : a frozen dataclass of floats (the method's figures), or None for a method
        without figures of its own.
    """

    result: AnimatedMesh | MeshSequence
    diagnostics: Any = None


class StreamSummary(NamedTuple):
    """What a streamed run (``reconstruct_streamed``) of an animated-mesh method did:
    ``frames`` written to ``output``, the result's ``vertices``, the number of ``windows``
    (``resumed`` of them loaded from the cache) and the wall ``seconds``."""

    output: Path
    frames: int
    vertices: int
    windows: int
    resumed: int
    seconds: float


@runtime_checkable
class MethodModule(Protocol):
    """What a method module provides (see the module docstring)."""

    Options: type
    MIN_FRAMES: int
    RESULT: type

    def reconstruct(self, seq: PointCloudSequence, options: Any = None) -> Any: ...


def diagnostic_figures(diagnostics) -> dict[str, float]:
    """A method's typed diagnostics as ``{name: float}`` (the bench's "mass err." and such);
    ``{}`` for None.

    Examples
    --------
    >>> @dataclasses.dataclass(frozen=True)
    ... class Figures:
    ...     mass_conservation_error: float
    >>> diagnostic_figures(Figures(0.012))
    {'mass_conservation_error': 0.012}
    >>> diagnostic_figures(None)
    {}
    """
    if diagnostics is None:
        return {}
    if not dataclasses.is_dataclass(diagnostics):
        raise TypeError(f"diagnostics must be a dataclass, got {type(diagnostics).__name__}")
    return {k: float(v) for k, v in dataclasses.asdict(diagnostics).items() if v is not None}


def check_method_module(module: ModuleType) -> list[str]:
    """The ways ``module`` breaks the method contract (an empty list when it keeps it)."""
    problems = []
    options = getattr(module, "Options", None)
    if options is None or not dataclasses.is_dataclass(options):
        problems.append("Options is missing or not a dataclass")
    else:
        if not options.__dataclass_params__.frozen:
            problems.append("Options is not frozen")
        try:
            options()
        except TypeError as error:
            problems.append(f"Options() needs arguments: {error}")
    minimum = getattr(module, "MIN_FRAMES", None)
    if not isinstance(minimum, int) or minimum < 1:
        problems.append(f"MIN_FRAMES must be a positive int, got {minimum!r}")
    kinds = getattr(module, "RESULT", None)
    kinds = kinds if isinstance(kinds, tuple) else (kinds,)
    if not kinds or any(kind not in (AnimatedMesh, MeshSequence) for kind in kinds):
        problems.append("RESULT must be AnimatedMesh, MeshSequence or a tuple of them")
    if not callable(getattr(module, "reconstruct", None)):
        problems.append("reconstruct is missing")
    hook = getattr(module, "reconstruct_with_diagnostics", None)
    if hook is not None and not callable(hook):
        problems.append("reconstruct_with_diagnostics is not callable")
    estimate = getattr(module, "estimate_peak_bytes", None)
    if estimate is not None:
        if not callable(estimate):
            problems.append("estimate_peak_bytes is not callable")
        names = getattr(module, "MEMORY_OPTIONS", None)
        fields = {f.name for f in dataclasses.fields(options)} if dataclasses.is_dataclass(options) else set()
        if not isinstance(names, tuple) or not names or not set(names) <= fields:
            problems.append(f"MEMORY_OPTIONS must name options of the method, got {names!r}")
    common = getattr(module, "COMMON_OPTIONS", None)
    if common is not None:
        fields = {f.name for f in dataclasses.fields(options)} if dataclasses.is_dataclass(options) else set()
        if (
            not isinstance(common, tuple)
            or not common
            or not set(common) <= fields
            or len(set(common)) != len(common)
        ):
            problems.append(
                f"COMMON_OPTIONS must name options of the method, each once, got {common!r}"
            )
    return problems


def run_streamed(name: str, source, output, min_frames: int, run):
    """The frame of a composition's streamed run: ``output`` checked
    (:func:`fourd.io.npz.streamed_output`), at least ``min_frames`` frames in ``source``
    (:class:`~fourd.errors.InputError` otherwise), then ``run(output, work)`` with ``work`` a
    temporary folder beside the output that goes when it returns; its summary (a NamedTuple
    with ``seconds``) comes back with the wall seconds, logged on ``fourd.methods.<name>``."""
    import logging
    import tempfile
    import time

    from fourd.errors import InputError
    from fourd.io.npz import streamed_output

    output = streamed_output(output)
    if len(source) < min_frames:
        raise InputError(f"{name} needs at least {min_frames} frames, got {len(source)}")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=output.parent, prefix=f".fourd-{name}-") as work:
        summary = run(output, Path(work))
    seconds = time.perf_counter() - started
    logging.getLogger(f"fourd.methods.{name}").info(
        "%s, streamed: %d frames in %.1f s", name, len(source), seconds
    )
    return summary._replace(seconds=seconds)


def streamed_in_memory(reconstruct_streamed, seq: PointCloudSequence, options, name: str) -> Reconstruction:
    """A method's ``reconstruct_streamed(source, output, options)`` over the sequence ``seq``
    in memory (``window`` set without ``--stream``): written to a temporary ``.npz``, read
    back, with the summary's ``diagnostics`` (None for a summary without)."""
    import tempfile

    from fourd.frame_source import FrameSource
    from fourd.io.npz import read_npz

    with tempfile.TemporaryDirectory(prefix=f"fourd-{name}-") as folder:
        summary = reconstruct_streamed(FrameSource.of(seq), Path(folder) / "result.npz", options)
        result = read_npz(summary.output)
    return Reconstruction(result, getattr(summary, "diagnostics", None))
