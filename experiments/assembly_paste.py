"""Does pasting target-only geometry into the union mesh (thesis 5.6, second half; `assembly`'s
``paste``) complete what frame 0's scan misses, and at what cost?

Runs the bench on the first 4 crane frames at the standard scan (every second frame, the
scene labelled ``crane-4`` as in ``benchmarks/METHODS.md``), with ``paste`` on and off, in one
process (``isolate=False``). Prints each run's table row.

    .venv/bin/python experiments/assembly_paste.py [frames]

Answer (see ``benchmarks/METHODS.md``, "Pasting target-only geometry"): in the closing rows
there.
"""

from __future__ import annotations

import sys

import fourd.bench.suite as suite
from fourd.bench.runner import run_bench


def main(frames: int = 4) -> None:
    label = f"crane-{frames}"
    scene = suite.BenchScene("crane", frames=frames, options={"start": 0, "step": 2}, label=label)
    suite.REMESHED_SCENES = suite.REMESHED_SCENES + (scene,)
    report = run_bench(
        methods=["assembly", "assembly:paste=false"],
        scenes=[label],
        isolate=False,
        output=f"benchmarks/out/assembly_paste_{frames}.md",
    )
    for path in report["paths"]:
        if str(path).endswith(".md"):
            print(open(path).read())


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
