"""Thread pools of worker processes sized to share the machine, and threads side by side in
this process.

A worker process started while the environment asks nothing loads its BLAS, OpenMP and numba
thread pools one thread per core; two such workers on a 2-core machine then run four
busy-waiting threads, and were four times slower than one process alone (``assembly``'s
merges of 8 crane frames, ``workers=2``). :func:`threads_per_worker` sets the pools' sizes in
the environment the workers inherit while they start.

Work that runs in a worker or in this process must not depend on where it ran, nor on how many
workers there are: OpenBLAS's results depend on its thread count (``assembly``'s maps on 5
crane frames, ``workers=2``: two runs apart by up to 0.03 in a vertex, identical with one BLAS
thread). Such work runs inside :func:`one_blas_thread`.

Within one process, work runs side by side in threads (:func:`map_in_threads`; ``surfels``'
merges, ``kinematic``'s and ``surfels``' per-frame stages) where numba's threading layer lets
two threads run parallel kernels at once (:func:`concurrent_kernels_safe`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

import numba
from threadpoolctl import threadpool_limits

#: The environment variables the thread pools of numpy's BLAS, OpenMP and numba read at start.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


@contextlib.contextmanager
def threads_per_worker(workers: int):
    """While inside, processes started get ``cores // workers`` threads per pool (at least
    one); the environment is restored on leaving. Variables the user set are kept.

    >>> import os
    >>> before = os.environ.get("OPENBLAS_NUM_THREADS")
    >>> with threads_per_worker(1024):
    ...     os.environ["OPENBLAS_NUM_THREADS"] if before is None else "1"
    '1'
    >>> os.environ.get("OPENBLAS_NUM_THREADS") == before
    True
    """
    threads = str(max(1, (os.cpu_count() or 1) // max(1, int(workers))))
    saved = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, threads)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@contextlib.contextmanager
def one_blas_thread():
    """While inside (or in a function it decorates), this process's BLAS runs one thread, so
    what is computed there is the same in any process, whatever its thread pools."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def concurrent_kernels_safe() -> bool:
    """Whether numba's threading layer (chosen at the first parallel kernel) lets two threads
    of this process run parallel kernels at once: ``tbb`` and ``omp`` do, ``workqueue`` aborts
    the process. False before any parallel kernel has run."""
    try:
        return numba.threading_layer() in ("tbb", "omp")
    except ValueError:  # no parallel kernel has run yet
        return False


def map_in_threads(function: Callable, items: Iterable, workers: int) -> Iterator:
    """``function(item)`` for each of ``items``, yielded in the items' order, on ``workers``
    threads side by side where numba's threading layer allows it
    (:func:`concurrent_kernels_safe`; else one after another). The first item runs alone, as
    numba picks its layer at the first parallel kernel. For a ``function`` whose result
    depends on its item alone (a per-frame stage) the results are the same either way."""
    items = list(items)
    for item in items[:1]:
        yield function(item)
    rest = items[1:]
    if workers > 1 and len(rest) > 1 and concurrent_kernels_safe():
        with ThreadPoolExecutor(max_workers=workers) as pool:
            yield from pool.map(function, rest)
    else:
        for item in rest:
            yield function(item)
