"""Question (CI time, first run of a fresh install): how much of the test suite's 21 minutes,
and of a new user's first ``kinematic`` run, is numba compiling fourd's kernels, and which
kernels cost it? Can a plain restructuring cut it?

Run from the repository root (an empty cache folder, so every kernel compiles)::

    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=src .venv/bin/python \\
        experiments/numba_compile_time.py kinematic
    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=src:experiments .venv/bin/python -m pytest -q \\
        -p numba_compile_time -p no:cacheprovider

The first runs ``kinematic`` on 6 frames of bending-arm (the exact-anchors test's scene) and
prints each kernel's compile time (callees included, so nested kernels count twice); the
second loads this file as a pytest plugin and writes the outermost compile time per kernel and
per test to ``$COMPILE_OUT`` (``/tmp/numba-compile.json`` by default).

Answer (2-core AMD EPYC at 2.45 GHz, numba 0.68.1, nothing else running, 2026-12-07 at
79bbd24):

- **The suite** spent 236 s compiling in its own process (outermost compiles; subprocesses
  such as the CLI tests' compile on their own and are not counted): about a fifth of the CI's
  pytest time (1,279 s at 280007c). The most: ``mpu_fit._fit_cells`` 67 s, ``flow.sparse.
  _strong_rows`` 21 s (six specializations: two index types times the three ways
  ``strong_pattern``/``strong_values`` call it), ``rotations._best_rotations`` 11 s,
  ``normals._pca_kernel`` 9 s, ``mpu_eval._evaluate`` 8 s and ``_evaluate_slice`` 7 s; 45
  kernels over 1 s. Whichever test first runs a method pays its compile: the exact-anchors test
  (``tests/appearance/test_anchor_guide.py``) takes 128-164 s in CI, of which 137 s compiling,
  and 17 s with the cache warm.
- **A first ``kinematic`` run** (the scene above, ``kinematic``): 96.9 s, of which 91.4 s
  compiling (outermost compiles); the same run with the cache warm, 5.6 s. Earlier runs with
  other timers took 106-128 s: compile times move by 10-15% between runs. The compile includes numba's shape
  errors for array slice assignments (``raise_with_shape_context``, its string formatting: 9 s
  for 5 signatures) and the parallel loops' own passes.
- **Tried: the body of ``_fit_cells``' parallel loop moved into a plain function** (the loop
  calling it per cell). Compile 43.4 s before, 41.2 s after, in alternating runs: no gain, and
  the first try compiled the plain function twice (the loop's index is typed int64 in one pass
  and uint64 in the parallel one: 37 s for the two), which a cast to int64 fixed. The
  parallel wrapper still costs about 15 s over the plain function's 27-30 s: numba links the
  callee into the loop's module and LLVM optimises it again there. Reverted; results were
  bit-identical.

- **Kept (701bac2): ``_strong_rows``' three calls take one signature** (``strong_pattern``
  passed an int64 array where ``strong_values`` passes the matrix's index type, and the stored
  pattern's index pointer in that type): with a fresh cache ``test_amg.py`` and
  ``test_sparse.py`` compile it twice (the suite's two matrix types) where the suite compiled it
  six times, about 3.5 s each; a flow run pays one compile instead of three. The other kernels
  with several specializations (``_csr_multiply_add`` 4, ``_csr_transpose_multiply`` 3,
  ``_normal_residual`` 3) take float32 and float64 operands on purpose; ``projector_sums._sums``
  (3) differs only in read-only inputs.

So the compile is spread over many kernels and no single restructuring removes a large share;
it is paid once per machine (``cache=True``), but CI and every new user pay it in full. What
could: a compile step at install time or at the first run of the CLI, with progress shown;
not done.
"""

from __future__ import annotations

import collections
import json
import os
import sys
import time

from numba.core import event

_outermost = collections.defaultdict(float)
_inclusive = collections.defaultdict(float)
_counts = collections.Counter()
_per_test = collections.defaultdict(float)
_state = {"depth": 0, "started": [], "test": None}


class _Listener(event.Listener):
    def on_start(self, ev):
        _state["depth"] += 1
        _state["started"].append(time.perf_counter())

    def on_end(self, ev):
        _state["depth"] -= 1
        elapsed = time.perf_counter() - _state["started"].pop()
        function = ev.data["dispatcher"].py_func
        name = f"{function.__module__}.{function.__qualname__}"
        _inclusive[name] += elapsed
        _counts[name] += 1
        if _state["depth"] == 0:
            _outermost[name] += elapsed
            _per_test[_state["test"]] += elapsed


event.register("numba:compile", _Listener())


def pytest_runtest_setup(item):
    _state["test"] = item.nodeid


def pytest_sessionfinish(session):
    with open(os.environ.get("COMPILE_OUT", "/tmp/numba-compile.json"), "w") as out:
        json.dump(
            {"total": sum(_outermost.values()), "kernels": _outermost, "tests": _per_test},
            out,
            indent=0,
        )


def kinematic() -> None:
    from fourd import synth
    from fourd.methods import kinematic

    started = time.perf_counter()
    truth = synth.scene("bending-arm", frames=6)
    scans = synth.scan(
        truth, resolution=96, seed=0, appearance="cloth", video=True, video_resolution=64
    )
    kinematic.reconstruct(scans, kinematic.Options(color_guide=False, video_anchors=False))
    print(f"the run: {time.perf_counter() - started:.1f} s, compiling (outermost) "
          f"{sum(_outermost.values()):.1f} s")
    for name, seconds in sorted(_inclusive.items(), key=lambda kv: -kv[1])[:25]:
        print(f"{seconds:7.2f} s  {_counts[name]:2d}  {name}")


if __name__ == "__main__":
    {"kinematic": kinematic}[sys.argv[1]]()
