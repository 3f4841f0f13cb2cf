"""Question: where does `surfels`' correspondence drift on bending-arm-cloth-video come from?
With good anchors the mesh's error still grows by about 0.0009 of the diagonal per frame, and
neither the rigidity, the anchor weight nor the fit to the frames moves it. Do the surfels
themselves drift, or does the mesh's carry (each vertex's offset turned by its surfels'
rotations, sec. 3.3) add it?

    PYTHONPATH=src python experiments/surfels_carry_drift.py [SCENE_LABEL]

Runs `surfels` as `fourd bench` does on the scene (default bending-arm-cloth-video), keeps the
model the pipeline meshes, and prints the correspondence mean / last (fractions of the
diagonal, `fourd.metrics.scores`' binding to the truth at frame 0) and the per-frame curve of:
the surfels' own positions; the mesh as output (after the fit to the frames); the raw carried
mesh; that mesh carried with `align_normals` off; and carried with the offsets not turned at
all (every `F` the identity).

Answer (the bench's scene, with anchors, before the colours' guide): the surfels drift, not
the carry. Surfels 0.0100 / 0.0188; output mesh 0.0098 / 0.0178; carried 0.0098 / 0.0180, the
same without `align_normals`; offsets not turned 0.0103 / 0.0190. With the colours' guide
(`color_guide`, weight 1, one round) everything moves together: surfels 0.0057 / 0.0122, mesh
0.0059 / 0.0119. benchmarks/METHODS.md, "The video's anchors" and "The colours' guide".
"""

import sys
from types import SimpleNamespace

import numpy as np

from fourd.bench.suite import scan_scene, select_scenes
from fourd.geometry.neighbors import point_spacing
from fourd.methods.surfels import Options, meshing, pipeline, reconstruct
from fourd.metrics.sampling import sample_surface
from fourd.metrics.scores import _TRUTH, _correspondence, _rng


def main(label: str) -> None:
    scene = select_scenes([label], quick=False)[0]
    truth, scans = scan_scene(scene)
    kept = {}
    original = pipeline.surfel_mesh

    def keep(state, sampling, **kwargs):
        kept.update(state=state, sampling=sampling, kwargs=kwargs)
        return original(state, sampling, **kwargs)

    pipeline.surfel_mesh = keep
    options = Options()
    result = reconstruct(scans, options)
    pipeline.surfel_mesh = original

    diagonal = truth.diagonal()
    samples = sample_surface(*truth.frame(0), 60000, _rng(0, _TRUTH, 0))

    def report(name, vertices):
        out = _correspondence(SimpleNamespace(vertices=vertices), truth, samples, diagonal)
        curve = out["_per_frame_correspondence"]
        print(f"{name}: {out['correspondence_mean']:.4f} / {out['correspondence_last']:.4f}")
        print("   " + " ".join(f"{v:.4f}" for v in curve), flush=True)

    state, sampling, kwargs = kept["state"], kept["sampling"], kept["kwargs"]
    report("surfels", state.positions)
    report("output mesh", result.vertices)
    report("carried mesh", original(state, sampling, **kwargs).vertices)
    flat = dict(kwargs, options=meshing.MeshingOptions(
        **{**kwargs["options"].__dict__, "align_normals": False}))
    report("carried, align_normals off", original(state, sampling, **flat).vertices)
    turned = meshing.surfel_frames
    meshing.surfel_frames = lambda state, reference, align_normals=True: np.broadcast_to(
        np.eye(3), (state.frames, state.count, 3, 3))
    report("carried, offsets not turned", original(state, sampling, **kwargs).vertices)
    meshing.surfel_frames = turned
    print(f"{state.count} surfels, spacing {point_spacing(scans.frames[0].points):.5f}, "
          f"sampling {sampling:.5f}, diagonal {diagonal:.4f}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "bending-arm-cloth-video")
