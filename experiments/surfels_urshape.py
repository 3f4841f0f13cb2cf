"""Does the urshape (Wand et al. 2007, sec. 3.2) help ``surfels`` when it is optimised with the
trajectories after the final pass, or should it only be fitted to them? An experiment, not
part of the package.

Run: ``.venv/bin/python experiments/surfels_urshape.py [CACHE_DIR]`` (crane, the bench's
20 frames and scan protocol; the merges are cached in CACHE_DIR, default
``/tmp/fourd-surfels-urshape``, so only the first variant pays for them: about 15 minutes,
then 2-3 minutes per variant on 2 cores).

Variants of ``Options.urshape``: ``off`` (no urshape; the rest is frame 0's mesh), ``final``
(the urshape and the trajectories optimised together after the final pass, with its
weights), ``rest`` (the urshape fitted to the final trajectories, which stay as they are).

Answer (2-core machine, one run each; Chamfer / completeness-95 / correspondence mean / last
/ mesh vertices / final stage seconds):

| urshape | Chamfer | compl. 95% | corr mean | corr last | vertices | final stage s |
|---|---|---|---|---|---|---|
| off | 0.0060 | 0.0285 | 0.0127 | 0.0210 | 5,271 | 60 |
| final | 0.0069 | 0.0321 | 0.0124 | 0.0203 | 4,554 | 120 |
| rest | 0.0060 | 0.0285 | 0.0127 | 0.0210 | 5,271 | 95 |

Optimised with the trajectories, the urshape trades 15% of Chamfer (frame 0's mesh loses 14%
of its vertices) for 2-3% of correspondence; fitted alone it leaves the frames as they were
and gives the result its rest shape. The default is ``rest`` (benchmarks/METHODS.md, "The
urshape").
"""

from __future__ import annotations

import logging
import sys
import time

from fourd import synth
from fourd.bench.suite import PROTOCOL
from fourd.methods import surfels
from fourd.metrics import evaluate


def main(cache: str) -> None:
    truth = synth.scene("crane", frames=20, seed=0, start=0, step=2)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    for variant in ("final", "rest", "off"):
        started = time.perf_counter()
        result = surfels.reconstruct(scans, surfels.Options(urshape=variant, cache_dir=cache))
        seconds = time.perf_counter() - started
        m = evaluate(result, truth, samples=60000)
        print(
            f"| {variant} | {m['chamfer']:.4f} | {m['completeness_95']:.4f} | "
            f"{m['correspondence_mean']:.4f} | {m['correspondence_last']:.4f} | "
            f"{result.vertices.shape[1]} | {seconds:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    main(sys.argv[1] if len(sys.argv) > 1 else "/tmp/fourd-surfels-urshape")
