"""Messages about numba compiling fourd's kernels.

fourd's compiled kernels (``numba.njit(cache=True)``) are compiled for the machine's CPU the
first time each runs and loaded from numba's cache afterwards. On a fresh install that first
compile is most of a short run (a first ``kinematic`` run of 6 small frames: about 91 of its
97 s on a 2-core machine, 5.6 s with the cache warm; ``experiments/numba_compile_time.py``),
and without a word it looks like a hang. :class:`CompileNotice` says so when the first kernel
starts compiling, and how long the compiles took once the run is over.
"""

from __future__ import annotations

import logging
import time

from numba.core import event

#: What the first compile of a process logs.
FIRST_COMPILE = (
    "compiling fourd's kernels for this CPU: the first run after an install takes a minute or "
    "two longer; numba caches them for later runs"
)


class CompileNotice(event.Listener):
    """Listens to numba's ``"numba:compile"`` events: logs :data:`FIRST_COMPILE` at INFO when
    the first compile starts, and counts the outermost compiles (a kernel's callees compile
    inside it) and their wall time in seconds (``count``, ``seconds``)."""

    def __init__(self, logger: logging.Logger):
        self.logger = logger
        self.count = 0
        self.seconds = 0.0
        self._depth = 0
        self._started = 0.0

    def on_start(self, event_):
        if self._depth == 0:
            if self.count == 0:
                self.logger.info(FIRST_COMPILE)
            self.count += 1
            self._started = time.perf_counter()
        self._depth += 1

    def on_end(self, event_):
        self._depth = max(0, self._depth - 1)
        if self._depth == 0:
            self.seconds += time.perf_counter() - self._started

    def summary(self) -> str | None:
        """One line on the compiles so far (None when nothing compiled)."""
        if not self.count:
            return None
        plural = "s" if self.count != 1 else ""
        return (
            f"compiled {self.count} kernel{plural} in {self.seconds:.0f} s "
            "(cached: later runs load them)"
        )


def listen_for_compiles(logger: logging.Logger) -> CompileNotice:
    """A :class:`CompileNotice` on ``logger``, registered for ``"numba:compile"`` until
    :func:`stop_listening`."""
    notice = CompileNotice(logger)
    event.register("numba:compile", notice)
    return notice


def stop_listening(notice: CompileNotice) -> None:
    event.unregister("numba:compile", notice)
