"""Question: does the colour guide (``kinematic`` option ``color_guide``: per-vertex Lucas-Kanade
on each frame's coloured points against the colours the template took from the first frame,
:mod:`fourd.appearance.color_guide`) reduce the drift when the input has coloured
points but no video?

    python experiments/color_guide.py crane skin 20
    VARIANTS="color_radius=3,anchor_pull=1;color_radius=6" python experiments/color_guide.py crane cloth 20

Prints kinematic's correspondence mean / last frame, Chamfer and s/frame without the guide and
with each variant (standard scan protocol + coloured points, 20k samples).

Answer (20 frames, standard scan with coloured points and no video, 20k samples; correspondence
mean / last frame, off -> on with ``anchor_pull`` 1). With one brightness offset per patch:
crane printed cloth 0.0073 / 0.0120 -> 0.0047 / 0.0068; bending-arm cloth 0.0202 / 0.0338 ->
0.0067 / 0.0136; squash-ball cloth 0.0226 / 0.0066 -> 0.0144 / 0.0017; but crane skin 0.0077 /
0.0126 and a uniform colour 0.0080 / 0.0129, worse than off: the lamps' shading passed for
texture. With only the hue counting and the colour noise's share taken out of the structure
tensor (the default): crane cloth 0.0043 / 0.0070, uniform 0.0074 / 0.0124, skin 0.0072 /
0.0117. Before the guide ran after the step (on the rigid prediction, which on crane's fast
limbs is cells off): crane cloth 0.0111 / 0.0153. See benchmarks/METHODS.md (``color_guide``).
"""

from __future__ import annotations

import os
import sys
import time

from fourd import synth
from fourd.bench.suite import PROTOCOL, STANDARD_SCENES
from fourd.methods import kinematic
from fourd.metrics import evaluate


def _variant(text: str) -> dict:
    out = {}
    for item in filter(None, text.split(",")):
        key, value = item.split("=")
        out[key] = float(value)
    return out


def main(name: str, appearance: str, frames: int) -> None:
    scene = next(s for s in STANDARD_SCENES if s.key == name)
    count = frames if scene.frames is None else min(frames, scene.frames)
    truth = synth.scene(scene.name, frames=count, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, appearance=appearance, **PROTOCOL)
    variants = [None] + [_variant(v) for v in os.environ.get("VARIANTS", "anchor_pull=1").split(";")]
    if os.environ.get("NOBASE"):
        variants = variants[1:]
    for variant in variants:
        options = kinematic.Options(color_guide=False) if variant is None else kinematic.Options(color_guide=True, **variant)
        started = time.perf_counter()
        result = kinematic.reconstruct(scans, options)
        seconds = time.perf_counter() - started
        r = evaluate(result, truth, samples=20000, seed=0)
        print(f"{name} {appearance} {variant or 'off'}: correspondence {r['correspondence_mean']:.4f} / "
              f"{r['correspondence_last']:.4f}, Chamfer {r['chamfer']:.4f}, {seconds / count:.2f} s/frame",
              flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
