"""Issue 50 ("Long sequences: memory grows with the window being merged, not with the
sequence: report peak memory at 20, 40 and 80 frames of crane") and issue 56 for ``surfels``:
does the streamed run (:func:`fourd.methods.surfels.reconstruct_streamed`, windows of 10
frames, each merged onto the last frames before it) keep its peak memory and its time per
frame as the capture grows, and how does it score against one model over every frame?

The capture of ``experiments/long_capture.py`` (the crane at step 1 played ping-pong, three
virtual depth cameras framing the whole capture volume; :func:`fourd.synth.long_capture`),
scanned at 200 rays a side instead of 700 (about 4,500 points a frame: ``surfels`` takes
tens of seconds a frame at the bench's 15,000), ``surfels`` with its defaults otherwise.
Each length runs in a fresh process (peak resident memory from ``getrusage``; the time
includes scanning). ``MODE=memory`` runs :func:`fourd.methods.surfels.reconstruct` on the
whole sequence instead (one model, the paper's). Each result is then scored as
``long_capture.py`` scores it: correspondence per frame, Chamfer and completeness-95 on
every 25th frame (fractions of the crane's diagonal).

Answer (2-core Intel Xeon, nothing else running; details in benchmarks/METHODS.md, "`surfels`
streamed"): at 41f7844, 20, 40, 80 frames take 694, 714, 821 MB and 5.40, 5.96, 6.44 s/frame
(at 1e46fb8: 820, 946, 1,075 MB and 5.81, 6.65, 7.52 s/frame); correspondence mean / last
0.0083 / 0.0172, 0.0173 / 0.0251, 0.0312 / 0.0569 (it drifts), Chamfer 0.0108-0.0117. The
growth is not the length's: logged per window, the memory held between windows stays at
300-330 MB, each window's peak follows its surfel count (311 in the first window, 460-510 in
the later ones, which also hold the mesh's surfels and 4 past frames), and the time per frame
is the first, cheaper window's share thinned out.

Run from the repository root::

    .venv/bin/python experiments/surfels_long_capture.py              # 20, 40 and 80 frames
    .venv/bin/python experiments/surfels_long_capture.py run 40       # one length
    .venv/bin/python experiments/surfels_long_capture.py score 40     # score a finished run
    MODE=memory .venv/bin/python experiments/surfels_long_capture.py run 20
    WINDOWS=1 .venv/bin/python experiments/surfels_long_capture.py run 80  # memory per window

With ``WINDOWS=1`` each window's log line carries the process's peak resident memory since
the window before (reset through ``/proc/self/clear_refs``, Linux) and its resident memory
once the window is written, in kB.
"""

from __future__ import annotations

import json
import logging
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import long_capture as scoring

FRAMES = (20, 40, 80)
RESOLUTION = 200
WINDOW = 10
MODE = os.environ.get("MODE", "streamed")
OUT = Path(tempfile.gettempdir()) / f"fourd-surfels-{MODE}-long-capture"


class _WindowMemory(logging.Filter):
    """Appends ``[peak resident]`` kB to each log line and, after a window's line, resets the
    peak, so each window's line shows that window's peak."""

    def filter(self, record: logging.LogRecord) -> bool:
        status = Path("/proc/self/status").read_text().splitlines()
        kb = {line.split(":")[0]: line.split()[1] for line in status if line.startswith("Vm")}
        record.msg = f"{record.msg} [peak {kb['VmHWM']} resident {kb['VmRSS']} kB]"
        if "written" in str(record.msg):
            Path("/proc/self/clear_refs").write_text("5")
        return True


def run(frames: int) -> dict:
    from fourd.io.npz import write_npz
    from fourd.methods import surfels
    from fourd.synth.whole_capture import long_capture

    OUT.mkdir(exist_ok=True)
    if os.environ.get("WINDOWS"):
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
        for handler in logging.getLogger().handlers:
            handler.addFilter(_WindowMemory())
    capture = long_capture(frames, resolution=RESOLUTION)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    started = time.perf_counter()
    if MODE == "memory":
        result = surfels.reconstruct(capture.source.read(0, frames))
        write_npz(OUT / f"{frames}.npz", result)
        vertices, windows = result.vertices.shape[1], 1
    else:
        summary = surfels.reconstruct_streamed(
            capture.source, OUT / f"{frames}.npz", surfels.Options(window=WINDOW)
        )
        vertices, windows = summary.vertices, summary.windows
    seconds = time.perf_counter() - started
    row = {
        "mode": MODE,
        "frames": frames,
        "windows": windows,
        "vertices": vertices,
        "s_per_frame": seconds / frames,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "before_mb": before,
    }
    print(json.dumps(row), flush=True)
    return row


def score(frames: int) -> dict:
    scoring.RESOLUTION = RESOLUTION  # the capture as it was scanned here
    return scoring.score(frames, OUT)


if __name__ == "__main__":
    if len(sys.argv) == 3:
        (run if sys.argv[1] == "run" else score)(int(sys.argv[2]))
    else:
        for count in FRAMES:
            subprocess.run([sys.executable, __file__, "run", str(count)], check=True)
        for count in FRAMES:
            subprocess.run([sys.executable, __file__, "score", str(count)], check=True)
