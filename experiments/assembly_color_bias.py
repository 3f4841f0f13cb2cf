"""Question: on the whole crane capture, does the colour fit's Lucas-Kanade against the first
frame's colours ask points that are already where they belong to move, and more so the farther
the frame is from the first one? (Its result creeps from 0.74 edges at frame 25 to 3.0 at the
end though each frame is read against the first frame: a bias that grows with the pose would
do that, since each frame starts from the last one's correction.)

Setup: all 175 crane frames, 256 rays a side, printed cloth, the rig's video at 256 pixels
(``experiments/assembly_color_fit.py crane-full-mid``'s input); each frame's mesh and colours
as `assembly` makes them. Points: the truth's vertices, one per cube of 1.5 frame-mesh edges,
at their true positions in every frame (the truth's vertices correspond by construction).
Reference colours: frame 0's colour field at those points. In frame ``t``,
``photometric_shift`` (the fit's radius and scale) at the true positions against frame ``t``'s
field: what it asks of points that need no move, median / 90th percentile in edges, over the
points weighing at least exp(-1), and their share.

Run: ``.venv/bin/python experiments/assembly_color_bias.py`` (about 3 minutes).

Answer: see ``benchmarks/METHODS.md``, `assembly`, "What the colour fit leaves on the whole
capture".
"""

from __future__ import annotations

import numpy as np

from fourd import synth
from fourd.appearance.photometric import photometric_shift
from fourd.bench.suite import PROTOCOL
from fourd.geometry.grid import one_per_cube
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.normals import vertex_normals
from fourd.methods.assembly import Options
from fourd.methods.assembly.color_fit import SAMPLE_SPACING, _field, frame_colors
from fourd.methods.assembly.method import frame_meshes


def main() -> None:
    truth = synth.scene("crane", frames=175, seed=0, start=0, step=1)
    scans = synth.scan(truth, resolution=256, seed=0, appearance="cloth", video=True, video_resolution=256,
                       **PROTOCOL)
    meshes = frame_meshes(scans, Options())
    colors = frame_colors(scans, meshes)
    edge = median_edge_length(*meshes[0])
    sample = one_per_cube(truth.vertices[0], SAMPLE_SPACING * edge)
    reference = _field(*meshes[0], colors[0], len(sample)).sample(truth.vertices[0][sample])
    for t in (1, 10, 25, 50, 75, 100, 125, 150, 174):
        x = truth.vertices[t]
        field = _field(*meshes[t], colors[t], len(sample))
        result = photometric_shift(x[sample], vertex_normals(x, truth.faces)[sample], reference, field,
                                   radius=5.0 * edge)
        weight = np.exp(-((result.uncertainty / (0.5 * edge)) ** 2))
        pinned = np.isfinite(result.uncertainty) & (weight >= np.exp(-1.0))
        asked = np.linalg.norm(result.shift[pinned], axis=1) / edge
        print(f"frame {t}: {pinned.mean():.0%} pinned, asked {np.median(asked):.2f} / "
              f"{np.percentile(asked, 90):.2f} edges (median / 90th percentile)", flush=True)


if __name__ == "__main__":
    main()
