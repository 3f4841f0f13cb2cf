"""Would a less holey urshape help ``kinematic``? An experiment, not part of the package.

Run: ``.venv/bin/python experiments/urshape_holes.py SCENE [SCENE ...] [--closing N]
[--dilation N] [--fill-loops K]`` (any bench scene; 10-40 s per scene on 2 cores).

Why: the paper polygonises the urshape only in cells with an input point inside their
circumsphere, so open scans stay open. With the standard scans that leaves crane's urshape
with 241 boundary loops (horse-gallop 351), most of them pinholes between scan lines, and
its completeness-95 (0.0116) behind ``perframe``'s (0.0076), whose mesh is kept within two
point spacings of the data. Two ways to close them are tried here:

- ``--closing N``: the cell mask morphologically closed by N cells (26-neighbourhood) before
  marching cubes, so gaps up to about 2N cells between masked cells are polygonised too;
- ``--dilation N``: the cell mask grown by N cells, which also extends the template's borders
  by N cells into what no point saw (``perframe`` keeps its mesh within two point spacings of
  the data);
- ``--fill-loops K``: boundary loops of at most K edges closed after marching cubes by a fan
  from their centroid (the urshape's smoothing and projection onto ``f = 0`` follow).

Measured (20,000 samples, single runs; Chamfer / completeness-95 / correspondence mean / last
frame / boundary loops):

| scene | as is | closing 2 | closing 3 | fill loops <= 30 | fill loops <= 100 |
|---|---|---|---|---|---|
| crane | 0.00316 / 0.0126 / 0.0073 / 0.0120 / 241 | 0.00306 / 0.0097 / 0.0075 / 0.0112 / 95 | 0.00297 / 0.0073 / 0.0078 / 0.0109 / 79 | 0.00315 / 0.0123 / 0.0073 / 0.0111 / 17 | 0.00316 / 0.0117 / 0.0073 / 0.0116 / 15 |
| dfaust-hopping | 0.00357 / 0.0175 / 0.0043 / 0.0061 / 149 | 0.00340 / 0.0147 / 0.0044 / 0.0062 / 99 | 0.00334 / 0.0132 / 0.0043 / 0.0056 / 77 | | |
| horse-gallop | 0.00356 / 0.0173 / 0.0087 / 0.0043 / 351 | 0.00407 / 0.0221 / 0.0118 / 0.0068 / 172 | 0.00406 / 0.0219 / 0.0118 / 0.0068 / 153 | 0.00355 / 0.0174 / 0.0091 / 0.0045 / 15 | 0.00403 / 0.0213 / 0.0114 / 0.0042 / 10 |
| bending-arm | 0.00473 / 0.0368 / 0.0202 / 0.0338 / 153 | 0.00459 / 0.0349 / 0.0178 / 0.0258 / 89 | 0.00390 / 0.0261 / 0.0165 / 0.0226 / 83 | | |
| waving-sheet | 0.00310 / 0.0057 / 0.0313 / 0.0425 / 6 | 0.00305 / 0.0055 / 0.0297 / 0.0397 / 2 | 0.00300 / 0.0054 / 0.0295 / 0.0389 / 1 | | |
| rigid-turn | 0.00617 / 0.0512 / 0.0012 / 0.0017 / 143 | 0.00613 / 0.0508 / 0.0012 / 0.0018 / 131 | 0.00610 / 0.0499 / 0.0012 / 0.0018 / 124 | | |

Growing the mask by one cell instead (``--dilation 1``): crane 0.00294 / 0.0065 / 0.0082 /
0.0117 / 10, dfaust-hopping 0.00330 / 0.0100 / 0.0046 / 0.0062 / 13, horse-gallop 0.00376 /
0.0132 / 0.0139 / 0.0114 / 15. Completeness-95 falls by 25-50%, but the vertices on the
unseen border track badly: correspondence gets worse everywhere, on horse-gallop by 60%.

Closing helps every scene but horse-gallop, where it bridges legs that are close in the first
frame (rendered: from frame 4 on the front legs move as one), and its completeness-95 goes
0.0173 -> 0.022. What pays on crane is not the pinholes: filling every loop of up to 30 edges
leaves 17 of 241 and changes completeness-95 by 2%. The gain comes from polygonising the
concave places between close surfaces (armpits, crotch), where the implicit also joins parts
that are apart. Filling loops of up to 100 edges puts membranes between horse-gallop's legs
too. So the paper's mask stays; a guard that tells a gap in the data from a gap between
parts would be needed first.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy import ndimage

from fourd import evaluate, reconstruct, synth
from fourd.bench import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.methods.kinematic import urshape


def closed_mask(mask: np.ndarray, cells: int) -> np.ndarray:
    """``mask`` [X, Y, Z] bool morphologically closed by ``cells`` steps of the 26-neighbourhood
    (padded first, so nothing is lost at the grid's border)."""
    if cells <= 0:
        return mask
    structure = ndimage.generate_binary_structure(3, 3)
    padded = ndimage.binary_closing(np.pad(mask, cells), structure=structure, iterations=cells)
    return padded[cells:-cells, cells:-cells, cells:-cells]


def fill_loops(vertices: np.ndarray, faces: np.ndarray, most: int) -> tuple[np.ndarray, np.ndarray]:
    """Close every boundary loop of ``faces`` with 3 to ``most`` edges by a fan from a new vertex
    at its centroid; loops through a vertex with two boundary edges leaving it are left open."""
    half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = len(vertices)
    boundary = half[~np.isin(half[:, 1] * n + half[:, 0], half[:, 0] * n + half[:, 1])]
    following, pinched = {}, set()
    for a, b in boundary.tolist():
        if a in following:
            pinched.add(a)
        following[a] = b
    seen: set[int] = set()
    new_vertices, new_faces = [vertices], [faces]
    for start in list(following):
        if start in seen:
            continue
        loop, v = [start], following[start]
        seen.add(start)
        while v != start and v in following and v not in seen and len(loop) <= most:
            loop.append(v)
            seen.add(v)
            v = following[v]
        if v != start or not 3 <= len(loop) <= most or pinched.intersection(loop):
            continue
        ring = np.array(loop)
        centre = n + len(new_vertices) - 1
        new_vertices.append(vertices[ring].mean(axis=0)[None])
        # the half-edge a -> b is the loop's; the triangle that closes it holds b -> a
        new_faces.append(np.stack([np.roll(ring, -1), ring, np.full(len(ring), centre)], axis=1))
    return np.concatenate(new_vertices), np.concatenate(new_faces)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--closing", type=int, default=0)
    parser.add_argument("--dilation", type=int, default=0)
    parser.add_argument("--fill-loops", type=int, default=0)
    args = parser.parse_args()

    cell_mask, polygonise = urshape.data_cell_mask, urshape._polygonise

    def masked(points, origin, cell_size, shape):
        mask = closed_mask(cell_mask(points, origin, cell_size, shape), args.closing)
        if args.dilation > 0:
            structure = ndimage.generate_binary_structure(3, 3)
            mask = ndimage.binary_dilation(mask, structure=structure, iterations=args.dilation)
        return mask

    def filled(*arguments):
        vertices, faces = polygonise(*arguments)
        return fill_loops(vertices, faces, args.fill_loops) if args.fill_loops and len(faces) else (vertices, faces)

    urshape.data_cell_mask, urshape._polygonise = masked, filled
    scenes = {s.key: s for s in STANDARD_SCENES + HELD_OUT_SCENES}
    for name in args.scenes:
        bench_scene = scenes[name]
        truth = synth.scene(bench_scene.name, frames=bench_scene.frames, seed=0, **bench_scene.options)
        scans = synth.scan(truth, resolution=bench_scene.resolution, seed=0, **{**PROTOCOL, **bench_scene.scan})
        metrics = evaluate(reconstruct(scans, method="kinematic"), truth, samples=20_000, seed=0)
        keys = ["chamfer", "completeness_95", "correspondence_mean", "correspondence_last", "boundary_loops_max"]
        print(json.dumps({"scene": name, "closing": args.closing, "dilation": args.dilation,
                          "fill_loops": args.fill_loops}
                         | {key: metrics[key] for key in keys}))


if __name__ == "__main__":
    main()
