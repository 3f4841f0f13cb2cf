"""Question: the assembled mesh's edges shrink along the chain of maps over a whole capture
(most of the mesh bunches up, a few triangles span the rest). Does one map shorten what it
maps, and where?

Setup: ``map_pair`` of one crane frame onto another at 160 rays a side (one process), each
source edge against the distance of its two mapped points (both ends mapped): the truth's frame 0
remeshed twice (a static pair: the true map keeps every length), the same frame scanned twice
(different noise), and consecutive scanned frames 0-4, with the relaxation and without
(``relax_sweeps=0``). With ``results``: the edge lengths of written results against their
first frame (``experiments/assembly_long_capture.py``'s outputs).

Run: ``.venv/bin/python experiments/assembly_edge_wear.py [maps | chain | scanned-chain |
results]`` (about a minute each; ``chain``: the truth's frame 0 remeshed 9 times and
assembled, a chain of 8 maps of perfect geometry that does not move; ``scanned-chain``: the
same frame scanned 9 times instead).

Answer (2-core machine, 2026-12-02; median ratio, total length ratio): remeshed static 0.995,
0.989-0.991, but projected onto the truth 0.9996-1.0001 (the target mesh's sag); scanned static
0.9965-0.9989, 0.996-0.998; consecutive scanned frames 0.9972-0.9989, 0.996-0.998. The static
chain keeps the median at 1.000-1.003 while the spread grows (10th / 99th percentile 0.889 /
2.63 after 8 maps; 0.872 / 1.75 without the relaxation); scanned 9 times, the median drops
once (0.985, frame 0's noisy edges the reference) and stays, the spread grows (0.829 / 2.46
after 8). Along the chain of the scanned
capture (results): dense 175 frames median 0.954 at frame 34, 0.903 at 174; sparse 1,000
frames 0.784 at 199, 0.272 at 999. See
``benchmarks/METHODS.md``, "`assembly` streamed", "The mesh wears along the chain".
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from fourd import synth
from fourd.methods.assembly import Options
from fourd.methods.assembly.hierarchy import map_pair
from fourd.methods.assembly.method import frame_meshes
from fourd.synth.remesh import remesh_surface

RAYS = 160
RESULTS = Path(tempfile.gettempdir()) / "fourd-assembly-long-capture"


def _edges(faces):
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(pairs, axis=1), axis=0)


def ratios(v, f, w, g, options, surface=None) -> str:
    """Mapped edges against the source's; with ``surface`` (a trimesh of the truth) also with
    the mapped points projected onto it (the target mesh's sag taken out)."""
    pair = map_pair(v, f, w, g, options)
    ok = pair.mapped
    points = np.full((len(v), 3), np.nan)
    points[ok] = np.einsum("nk,nkd->nd", pair.barycentric[ok], w[g[pair.faces[ok]]])
    edges = _edges(f)
    edges = edges[ok[edges].all(axis=1)]
    before = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    after = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
    text = (f"mapped {ok.mean():.3f}, median {np.median(after / before):.4f}, "
            f"total {after.sum() / before.sum():.4f}")
    if surface is not None:
        import trimesh

        points[ok] = trimesh.proximity.closest_point(surface, points[ok])[0]
        on = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
        text += f"; on the truth: median {np.median(on / before):.4f}, total {on.sum() / before.sum():.4f}"
    return text


def maps() -> None:
    truth = synth.scene("crane", frames=20)
    v0, f0 = truth.frame(0)
    spacing = 1.2 * truth.diagonal() / RAYS
    options = Options(workers=1)
    import trimesh

    surface = trimesh.Trimesh(v0, f0, process=False)
    for k in range(3):
        s = remesh_surface(v0, f0, spacing=spacing, offset=[0.1 * k, 0.5, 0.3])
        t = remesh_surface(v0, f0, spacing=spacing, offset=[0.7, 0.2 + 0.1 * k, 0.9])
        print(f"remeshed static {k}: {ratios(s.vertices, s.faces, t.vertices, t.faces, options, surface)}",
              flush=True)
    for k in range(2):
        a = frame_meshes(synth.scan(truth, resolution=RAYS, seed=k).select(0, 1), options)[0]
        b = frame_meshes(synth.scan(truth, resolution=RAYS, seed=k + 10).select(0, 1), options)[0]
        print(f"scanned static {k}: {ratios(*a, *b, options)}", flush=True)
    meshes = frame_meshes(synth.scan(truth, resolution=RAYS, seed=0).select(0, 5), options)
    for settings in ({}, {"relax_sweeps": 0}):
        for t in range(4):
            print(f"frames {t} -> {t + 1} {settings}: {ratios(*meshes[t], *meshes[t + 1], Options(workers=1, **settings))}",
                  flush=True)


def chain(scanned: bool = False) -> None:
    """A static chain: the crane truth's frame 0 remeshed 9 times (``scanned``: scanned 9 times,
    with different noise), assembled (8 maps), each frame's positions projected onto the truth
    and its edges against frame 0's."""
    import trimesh

    from fourd.methods.assembly import reconstruct
    from fourd.sequence import Frame, PointCloudSequence

    truth = synth.scene("crane", frames=20)
    v0, f0 = truth.frame(0)
    spacing = 1.2 * truth.diagonal() / RAYS
    surface = trimesh.Trimesh(v0, f0, process=False)
    rng = np.random.default_rng(0)
    frames = []
    for k in range(9):
        if scanned:
            frame = synth.scan(truth, resolution=RAYS, seed=k).frames[0]
            frames.append(Frame(frame.points, frame.normals, sensors=frame.sensors, time=float(k)))
            continue
        mesh = remesh_surface(v0, f0, spacing=spacing, offset=rng.random(3))
        frames.append(Frame(mesh.vertices, faces=mesh.faces, time=float(k)))
    for settings in ({}, {"relax_sweeps": 0}):
        result = reconstruct(PointCloudSequence(frames), Options(close_holes=0, color_fit=False, **settings))
        edges = _edges(result.faces)
        first = np.linalg.norm(result.vertices[0][edges[:, 0]] - result.vertices[0][edges[:, 1]], axis=1)
        for t in (1, 2, 4, 8):
            on = trimesh.proximity.closest_point(surface, result.vertices[t])[0]
            ratio = np.linalg.norm(on[edges[:, 0]] - on[edges[:, 1]], axis=1) / first
            print(f"static chain{' (scanned)' if scanned else ''} {settings} frame {t}: median {np.median(ratio):.4f}, 10th / 99th percentile "
                  f"{np.percentile(ratio, 10):.3f} / {np.percentile(ratio, 99):.2f}", flush=True)


def results() -> None:
    from fourd.io.results import load_result

    for path in sorted(RESULTS.glob("[!.]*.npz")):  # not the part files of stopped runs
        result = load_result(path)
        edges = _edges(result.faces)
        first = np.linalg.norm(result.vertices[0][edges[:, 0]] - result.vertices[0][edges[:, 1]], axis=1)
        for t in np.unique(np.linspace(0, result.frame_count - 1, 6).astype(int)):
            v = result.vertices[t]
            ratio = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1) / np.maximum(first, 1e-12)
            print(f"{path.stem} frame {t}: observed {result.observed[t].mean():.2f}, median "
                  f"{np.median(ratio):.3f}, 10th / 99th percentile {np.percentile(ratio, 10):.2f} / "
                  f"{np.percentile(ratio, 99):.1f}", flush=True)


if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 else ""
    if mode == "scanned-chain":
        chain(scanned=True)
    else:
        {"results": results, "chain": chain}.get(mode, maps)()
