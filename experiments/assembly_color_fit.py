"""Question: how far does `assembly`'s colour fit (``color_fit``) bring an assembled sequence
back to the first frame's colours, and how do its settings matter?

Setup: a bench scene scanned with the bench protocol, in its appearance (printed cloth unless
the scene names another, e.g. ``crane-skin-video``), with the rig's 3-camera
video at 256 pixels (the bench's ``*-cloth-video`` scenes; ``crane-full-mid``, the whole
capture, too); `assembly` once with ``color_fit=false`` and ``anchors`` from the environment's
``ANCHORS`` (``geometry`` unless set; kept in ``/tmp`` between runs), then
:func:`fourd.methods.assembly.color_fit.fit_colors` on its result with the settings given as
``KEY=VALUE`` (``passes=N``: the fit run N times, each on the last one's result; ``coarse=1``: first a pass
on colour fields blurred over 32 neighbours at radius 10 and scale 2; several sets
separated by ``/``); correspondence mean / last, Chamfer (20,000
samples) and the correspondence every fourth frame.

Run: ``.venv/bin/python experiments/assembly_color_fit.py bending-arm radius=3 / radius=5``

Answer: see ``benchmarks/METHODS.md``, `assembly`, "The colour fit".
"""

from __future__ import annotations

import os
import pickle
import sys
import time

from fourd import synth
from fourd.animation import AnimatedMesh
from fourd.appearance.surface_color import FIELD_POINTS_PER_READ, ColorField
from fourd.bench.suite import APPEARANCE_SCENES, PROTOCOL, STANDARD_SCENES, WHOLE_CAPTURE_SCENES
from fourd.geometry.normals import vertex_normals
from fourd.methods import reconstruct
from fourd.methods.assembly import Options, color_fit
from fourd.methods.assembly.color_fit import fit_colors, frame_colors
from fourd.methods.assembly.method import frame_meshes
from fourd.metrics import evaluate


def _score(result, truth, label: str) -> None:
    scores = evaluate(result, truth, samples=20000)
    curve = scores["per_frame"]["correspondence"]
    print(f"{label}: correspondence {scores['correspondence_mean']:.4f} / {scores['correspondence_last']:.4f}, "
          f"Chamfer {scores['chamfer']:.4f}; " + " ".join(f"{curve[t]:.4f}" for t in range(0, len(curve), max(4, len(curve) // 7))),
          flush=True)


def _blurred_field(vertices, faces, colors, count: int) -> ColorField:
    stride = max(1, len(vertices) // (FIELD_POINTS_PER_READ * count))
    normals = vertex_normals(vertices, faces)
    return ColorField(vertices[::stride], normals[::stride], colors[::stride], smoothing=32)


def main(name: str, settings: list[dict]) -> None:
    scene = next(s for s in STANDARD_SCENES + APPEARANCE_SCENES + WHOLE_CAPTURE_SCENES if s.key == name)
    name = scene.key
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    appearance = scene.appearance or "cloth"
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, appearance=appearance, video=True,
                       video_resolution=256, **PROTOCOL)
    anchors = os.environ.get("ANCHORS", "geometry")
    path = f"/tmp/fourd_assembly_color_fit_{name}_{anchors}.pkl"
    if not os.path.exists(path):
        with open(path, "wb") as file:
            pickle.dump(reconstruct(scans, "assembly", anchors=anchors, color_fit=False), file)
    with open(path, "rb") as file:
        assembled = pickle.load(file)
    meshes = frame_meshes(scans, Options())
    colors = frame_colors(scans, meshes)
    _score(assembled, truth, "assembled")
    for values in settings:
        values = dict(values)
        passes = int(values.pop("passes", 1))  # the fit run again on its own result
        coarse = int(values.pop("coarse", 0))
        started = time.perf_counter()
        vertices = assembled.vertices
        if coarse:  # first a pass on blurred colour fields (32 neighbours), radius 10, scale 2
            fine, color_fit._field = color_fit._field, _blurred_field
            try:
                vertices = fit_colors(vertices, assembled.faces, assembled.observed, meshes, colors, radius=10.0,
                                      scale=2.0)
            finally:
                color_fit._field = fine
        for _ in range(passes):
            vertices = fit_colors(vertices, assembled.faces, assembled.observed, meshes, colors, **values)
        values = values | ({"passes": passes} if passes > 1 else {}) | ({"coarse": 1} if coarse else {})
        fitted = AnimatedMesh(assembled.faces, vertices, assembled.times, assembled.observed, rest=vertices[0])
        _score(fitted, truth, f"{values} ({time.perf_counter() - started:.1f} s)")


if __name__ == "__main__":
    groups = " ".join(sys.argv[2:]).split("/") if len(sys.argv) > 2 else [""]
    main(sys.argv[1], [{k: float(v) if "." in v else int(v) for k, v in (a.split("=", 1) for a in g.split())}
                       for g in groups])
