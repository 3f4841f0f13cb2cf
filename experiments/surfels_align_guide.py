"""Question: `surfels`' colours' guide acts in each merge's global optimisation, after the
alignment has placed the new range; the Lucas-Kanade then takes back only two thirds to four
fifths of a patch's drift per round (`experiments/surfels_guide_accuracy.py`). Would guides in
the alignment itself, where a range is first placed, leave less drift to close?

    PYTHONPATH=src python experiments/surfels_align_guide.py [SCENE FRAMES RESOLUTION USE]

A probe, not the method: `assembly.align_ranges` is wrapped so that, after the alignment as
it is, the colours' guides of the moved surfels are found in the frame they were aligned to
(reference colours from the range they come from, `color_guide.reference_colors`) and the
alignment runs again with them added to the video's anchors, at the guide's weight
(`color_weight`; the video's anchors keep theirs by a scaled confidence). Runs `surfels` with
default options on the scene in cloth with the rig's video (defaults: bending-arm, 20 frames
at 128 rays, the first 10), with and without the wrapper; prints Chamfer / completeness-95 /
correspondence mean / last and the per-frame correspondence.

Answer (the defaults, one run each, nothing beside them): no. As it is 0.0078 / 0.0647 /
0.0030 / 0.0050, 4.98 s/frame; with the guides in the alignment (18 alignments guided, 0.73 of
their surfels) 0.0073 / 0.0603 / 0.0031 / 0.0048, 5.46 s/frame. The geometry gains a little;
the drift does not come from where a range is first placed.
"""

import dataclasses
import sys
import time

import numpy as np
from surfels_guide_accuracy import cloth_video_scene, print_scores  # this folder's

from fourd.geometry.neighbors import point_spacing
from fourd.methods.surfels import Options, assembly, pipeline, reconstruct
from fourd.methods.surfels.anchors import Forward
from fourd.methods.surfels.color_guide import color_guides, reference_colors
from fourd.methods.surfels.pipeline import guide_settings
from fourd.methods.surfels.state import surfel_state

#: (guides, surfels) of every guided alignment of the last run
counts: list = []


def guided_alignment(options: Options, sampling: float):
    """A wrapper of ``assembly.align_ranges`` and one of the pipeline's ``assemble`` that gives
    it the frames (module docstring)."""
    align, assemble = assembly.align_ranges, pipeline.assemble
    frames: list = []
    settings = guide_settings(options, sampling)
    counts.clear()

    def record(models, given, *args, **kwargs):
        frames[:] = given
        return assemble(models, given, *args, **kwargs)

    def aligned(left, points, normals, weights, solver, *, anchors=None, **kwargs):
        result = align(left, points, normals, weights, solver, anchors=anchors, **kwargs)
        target = next((f for f in frames if f.points is points), None)
        own = frames[left.start : left.stop]
        if target is None or target.colors is None or any(f.colors is None for f in own):
            return result
        reference = reference_colors(
            left.state, left.observed, [f.points for f in own], [f.normals for f in own],
            [f.colors for f in own],
        )
        last = left.state.frames - 1
        state = surfel_state(
            np.stack([left.state.positions[last], result.positions]),
            np.stack([left.state.normals[last], result.normals]),
        )
        guides = color_guides(
            state, np.zeros((2, state.count), dtype=bool), [points[:0], points],
            [normals[:0], normals], [None, target.colors], settings._replace(reference=reference),
        )
        if guides is None or len(guides.frames) == 0:
            return result
        ratio = weights.anchor / weights.guide
        extra = Forward(
            state.positions[0, guides.surfels], guides.targets, np.clip(guides.weights, 1e-6, 1)
        )
        if anchors is not None:
            extra = Forward(
                np.concatenate([anchors.source, extra.source]),
                np.concatenate([anchors.target, extra.target]),
                np.concatenate([anchors.confidence * ratio, extra.confidence]),
            )
        counts.append((len(guides.frames), state.count))
        heavier = dataclasses.replace(weights, anchor=weights.guide)
        return align(left, points, normals, heavier, solver, anchors=extra, **kwargs)

    return (record, aligned), (assemble, align)


def main(scene: str, frames: int, resolution: int, use: int) -> None:
    truth, scans = cloth_video_scene(scene, frames, resolution, use)
    options = Options()
    sampling = options.sampling * point_spacing(scans.frames[0].points)
    for name in ("as it is", "guides in the alignment"):
        wrapped, original = guided_alignment(options, sampling)
        if name != "as it is":
            pipeline.assemble, assembly.align_ranges = wrapped
        started = time.perf_counter()
        result = reconstruct(scans, options)
        seconds = (time.perf_counter() - started) / use
        pipeline.assemble, assembly.align_ranges = original
        print_scores(name, result, truth, seconds)
        if counts:
            guided = sum(g for g, _ in counts) / sum(s for _, s in counts)
            print(f"  {len(counts)} alignments guided, {guided:.2f} of their surfels", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:] or ["bending-arm", "20", "128", "10"]
    main(args[0], int(args[1]), int(args[2]), int(args[3]))
