"""One bench case: a method (or peer) reconstructing one scene's scans, timed, in a child process.

Each reconstruction runs in a fresh child process (``spawn``) so that its peak resident memory
is its own and a crash or a hang (``timeout``) costs one row, not the run.
"""

from __future__ import annotations

import logging
import multiprocessing
import resource
import time

from fourd.bench.suite import parse_method_spec


def _reconstruct(kind: str, name: str, scans, log_level: int):
    """``(result, diagnostics)``: the method's own figures (:func:`fourd.methods.reconstruct_with_diagnostics`); none for peers."""
    logging.getLogger("fourd").setLevel(log_level)
    if kind == "method":
        from fourd.methods import reconstruct_with_diagnostics
        from fourd.methods.base import diagnostic_figures

        method, values = parse_method_spec(name)
        result, diagnostics = reconstruct_with_diagnostics(scans, method=method, **values)
        return result, diagnostic_figures(diagnostics)
    from fourd.bench import peers

    return getattr(peers, name)(scans), {}


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
    # not a daemon, so a method may start worker processes of its own (assembly's merges);
    # the finally below stops it whatever happens here
    process = context.Process(target=_case, args=(sender, kind, name, scans, repeats, level))
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
