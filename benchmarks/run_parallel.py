"""The full benchmark on a machine with many cores, every timing still a 2-core timing.

Each (scene, method) case is one ``fourd bench`` process pinned with ``taskset`` to its own
pair of cores; cases are dealt to the core pairs longest first, and the partial reports are
merged into one (``fourd bench --merge``).

    python benchmarks/run_parallel.py OUTPUT.md [--methods ...] [--scenes ...] [--timeout S]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from fourd.bench import STANDARD_SCENES

#: Rough relative cost of one frame, to deal out the longest cases first.
METHOD_COST = {"perframe": 1.0, "kinematic": 4.0, "flow": 8.0}
FRAMES = {"horse-gallop": 48, "elephant-gallop": 70}  # elephant: 48 frames, denser


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("output")
    parser.add_argument("--methods", nargs="+", default=["perframe", "kinematic", "flow"])
    parser.add_argument("--scenes", nargs="+", default=[s.name for s in STANDARD_SCENES])
    parser.add_argument("--timeout", type=float, default=None)
    parser.add_argument("--slots", type=int, default=max(1, (os.cpu_count() or 2) // 2))
    parser.add_argument("--skip", nargs="+", default=[], metavar="SCENE/METHOD",
                        help="cases not to run, e.g. elephant-gallop/flow")
    parser.add_argument("--deadline", type=float, default=None,
                        help="seconds after which no new case is started (the report says which were not run)")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="fourd-bench-"))
    cases = sorted(
        ((scene, method) for scene in args.scenes for method in args.methods
         if f"{scene}/{method}" not in args.skip),
        key=lambda case: -FRAMES.get(case[0], 20) * METHOD_COST.get(case[1], 4.0),
    )
    queue = list(cases)
    lock = threading.Lock()
    started = time.monotonic()
    skipped = []

    def slot(index: int) -> None:
        cores = f"{2 * index},{2 * index + 1}"
        while True:
            with lock:
                if not queue:
                    return
                scene, method = queue.pop(0)
                if args.deadline and time.monotonic() - started > args.deadline:
                    skipped.append(f"{scene} / {method}")
                    continue
            part = work / f"{scene}--{method}"
            command = ["taskset", "-c", cores, sys.executable, "-m", "fourd", "bench", "--quiet",
                       "--scenes", scene, "--methods", method, "-o", str(part / "r.md")]
            if args.timeout:
                command += ["--timeout", str(args.timeout)]
            with open(f"{part}.log", "w") as log:
                status = subprocess.call(command, stdout=log, stderr=subprocess.STDOUT)
            print(f"{scene} / {method}: exit {status}", file=sys.stderr, flush=True)

    threads = [threading.Thread(target=slot, args=(i,)) for i in range(args.slots)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    parts = sorted(str(p) for p in work.glob("*/r.json"))
    if skipped:
        print(f"not started before the deadline: {', '.join(skipped)}", file=sys.stderr)
    notes = [f"Run by benchmarks/run_parallel.py: each (scene, method) case in its own process pinned to "
             f"2 cores, {args.slots} cases at a time."]
    command = [sys.executable, "-m", "fourd", "bench", "--merge", *parts, "-o", args.output]
    for note in notes:
        command += ["--note", note]
    return subprocess.call(command)


if __name__ == "__main__":
    sys.exit(main())
