"""Issue 56 for ``assembly``: streamed (each window of frames assembled by its own hierarchy and
merged onto the frames before, the frames written as they are final), does its peak memory
stay flat as the capture grows, and what do the windows cost against one hierarchy in memory?

The capture of ``experiments/long_capture.py`` (the crane played ping-pong, scanned a frame at
a time by the three whole-volume depth cameras; :func:`fourd.synth.long_capture`) at
``RAYS`` rays per side (400: the dense rig of the bench's ``crane-full``, about 16,500 points
a frame; 160: the sparse rig), ``assembly`` with its defaults: streamed
(:func:`fourd.methods.assembly.reconstruct_streamed`, windows of 16) or in memory (one
hierarchy; ``memory``). Each run in a fresh process (peak resident memory from
``getrusage``: this process's, and the largest merge process's; the time includes the scan). Scored as ``long_capture.py`` scores: the
correspondence per frame, Chamfer and completeness-95 on every 25th frame (fractions of the
crane's diagonal).

Answer: see ``benchmarks/METHODS.md``, "`assembly` streamed".

Run from the repository root::

    .venv/bin/python experiments/assembly_long_capture.py run 40 [RAYS]      # streamed
    .venv/bin/python experiments/assembly_long_capture.py memory 175 [RAYS]  # in memory
    .venv/bin/python experiments/assembly_long_capture.py score 40 [RAYS] [memory]
    .venv/bin/python experiments/assembly_long_capture.py run 1000 160 relax_rest=true  # options
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
import time
from pathlib import Path

from long_capture import score

OUT = Path(tempfile.gettempdir()) / "fourd-assembly-long-capture"


def _name(frames: int, rays: int, memory: bool, settings: str = "") -> str:
    return f"{frames}-{rays}{'-memory' if memory else ''}{'-' + settings if settings else ''}"


def run(frames: int, rays: int, memory: bool, settings: str = "") -> dict:
    from fourd.io.npz import write_npz
    from fourd.methods import method_options
    from fourd.methods.assembly import reconstruct, reconstruct_streamed
    from fourd.synth.whole_capture import long_capture

    OUT.mkdir(exist_ok=True)
    capture = long_capture(frames, resolution=rays)
    path = OUT / f"{_name(frames, rays, memory, settings)}.npz"
    values = dict(pair.split("=", 1) for pair in settings.split(",")) if settings else {}
    options = method_options("assembly", values)
    started = time.perf_counter()
    if memory:
        result = reconstruct(capture.source.read(0, frames), options)
        seconds = time.perf_counter() - started
        write_npz(path, result)
        vertices, windows = result.vertices.shape[1], 1
    else:
        summary = reconstruct_streamed(capture.source, path, options)
        seconds = time.perf_counter() - started
        vertices, windows = summary.vertices, summary.windows
    row = {
        "frames": frames,
        "rays": rays,
        "memory": memory,
        "settings": settings,
        "windows": windows,
        "vertices": vertices,
        "s_per_frame": round(seconds / frames, 3),
        "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
        # the merge processes (the largest of them; they end with the run)
        "worker_peak_mb": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024),
    }
    print(json.dumps(row), flush=True)
    return row


if __name__ == "__main__":
    kind, frames = sys.argv[1], int(sys.argv[2])
    rays = int(sys.argv[3]) if len(sys.argv) > 3 else 400
    settings = next((arg for arg in sys.argv[4:] if "=" in arg), "")
    if kind == "score":
        memory = "memory" in sys.argv[4:]
        target = OUT / f"{_name(frames, rays, memory, settings)}.npz"
        link = OUT / "scored" / f"{frames}.npz"
        link.parent.mkdir(exist_ok=True)
        link.unlink(missing_ok=True)
        link.symlink_to(target)
        score(frames, link.parent)
    else:
        run(frames, rays, kind == "memory", settings)
