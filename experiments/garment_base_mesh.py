"""Question: how close to the truth does the base-mesh cross-parameterisation of 3.6.2
(`garment.base_mesh`) carry one frame of the T-shirt onto another, and can it place the
template in the bench's scanned frames (issue 54, the thesis' path of 3.6.2 and 3.7)?

    python experiments/garment_base_mesh.py truth
    python experiments/garment_base_mesh.py scan
    python experiments/garment_base_mesh.py holes
    python experiments/garment_base_mesh.py fitted

``truth``: the generated T-shirt's own meshes (5,767 vertices, the four openings clean), 20
frames. Frame 0 and frame t are each closed by cones at their anchors (one mean radius out
along each opening's ellipse normal) and mapped onto the tetrahedron of frame 0's anchors; frame
0's vertices are carried to frame t through the base and compared with their true positions
(fractions of the diagonal: median, mean, 95th percentile), for four variants: the charts'
borders fixed on the base edges or sliding across them; the paths between the anchors the
shortest, or guided by frame 0's paths moved by the anchors' similarity (reach 0.3 of the
anchors' median distance).

``scan``: the bench's T-shirt scan (tshirt-cloth-video, the standard scan, first 4 frames; the
scan cache of ``garment_fit_data.py``), each frame's own surface as ``garment`` makes it, its
openings from the tracked ellipses (each opening the loop with the most points within one mean
radius of its ellipse; a loop two openings share split into the runs within half a radius),
closed and mapped with guides from the template (the first frame's surface at the template's
grid). Reports the map's L2 stretch (relative; 1 for an isometry, inf or NaN: folded) and time.

``holes``: the thesis' iteration of re-triangulating the holes on the base and re-projecting
them, in turn with the parameterisation (`garment.base_holes.reparameterize_holes`), against
the membrane of `closed_surface` alone: on the true T-shirt with a hole of radius 0.15 cut in the
front or the back of frame t (5, 9, 15: frame 0 carried into it through the base, guided paths,
sliding borders; error of all vertices, of those in the hole, of the others), then on the scan
frames of ``scan`` (stretch after each round).

``fitted``: `garment` (defaults) on the bench's two T-shirt scans, then its fitted frames'
correspondences replaced by the map through the base (the thesis' way of tying frames
together), scored against the truth.

Answer (2-core machine, 2026-11-30):
- truth, median / 95th percentile over the vertices, at the hardest frames (5 and 15: arms
  swung down 35 degrees, torso twisted 20):
  - fixed borders, shortest paths: 0.15 / 0.25: the paths between the sleeves and between
    neck and waist go round the other way (over the back, not the chest) in 8 of the 10
    frames. The map's stretch hardly shows it (1.12-1.27, the cones left out), so it cannot be
    caught after the fact;
  - fixed borders, guided: 0.029 / 0.10;
  - sliding borders, guided: 0.013 / 0.020, mean 0.0120-0.0131 (frame 1: 0.0025 / 0.0053;
    frame 9: 0.0010 / 0.0029; frame 19, the first pose again: 0.0000); about 1 s a frame;
  - sliding borders, shortest paths: 0.145 (sliding cannot undo paths that went round the
    other way).
  The rest is the twist: with anchors only at the openings, nothing tells the map how far the
  torso turned between its neck and waist. `garment`'s frame-to-frame fit reaches 0.0055 mean
  on the scanned motion (bench).
- scan: the frames' own surfaces have 100,000-106,000 faces, 17-22 holes and slivers (edges of
  1e-7). Frame 1, closed, is not a sphere (its paths cut it into 5 pieces). Frames 2 and 3:
  with fixed borders one chart folds (12-30 triangles); sliding unfolds them, but the stretch
  is 1.95-2.43 (against 1.10 on the truth) and a frame takes 16-18 s. The template (the first
  frame's surface at the template's grid, 8,205 vertices) has stretch 3.5. The cones over
  partly seen openings and the membranes over large occlusion holes are far from the true
  surface. So `garment` keeps its frame-to-frame fit. Rerun at the commit that adds ``holes``
  (the stretch now leaves the cones' triangles out): the template 1.361; frames 2 and 3 with
  sliding borders 1.184 and 1.186, with fixed borders folded (inf); frame 1 still not a sphere.
- holes (2026-11-30): the iteration the thesis adds (Delaunay flips of the holes' triangles on
  the base, the membrane re-projected with the base embedding's mean-value weights, the map
  again):
  - true T-shirt, hole of radius 0.15 (196-206 vertices): one round, no lower stretch (1.091-
    1.102 both ways), so the membrane's map is kept; error mean 0.0011-0.0159, in the hole
    0.0026-0.0178, the same both ways. A hole in a smooth, nearly developable torso is filled as
    well by the uniform membrane; what is left is the twist (above).
  - scan frames 2 and 3 (3,282 and 4,570 hole vertices), sliding borders: stretch per round
    1.184 -> 1.181 -> 1.179 -> 1.179 and 1.186 -> 1.178 -> 1.174 -> 1.173 -> 1.173 (4,336-
    5,286 flips in the first round, fewer after), 71-87 s a frame against about 17; fixed
    borders stay folded; frame 1 is still not a sphere (its paths cut it into 5 pieces: the
    flips do not change the topology). The iteration lowers the stretch by 0.4-1.1%: the
    stretch of these maps is not in the holes but in the cones over partly seen openings and
    the scan's own slivers.
- fitted: the same map applied to `garment`'s own fitted frames instead (complete, clean, the
  template's connectivity: the first frame's vertices carried into each fitted surface through
  the base; bench scans, 20 frames, 20k samples; correspondence mean / last, Chamfer,
  completeness-95):
  - printed cloth: fit 0.0056 / 0.0070, 0.0034, 0.0067; similarity guides and sliding 0.0617 /
    0.0725, 0.0042, 0.0187 (the anchors' configuration is not rigid: the sleeves swing, the
    guides drift off, the paths change their way); the first frame's very paths with fixed
    borders 0.0218 / 0.0329, 0.0041, 0.0131;
  - plain fabric: fit 0.0244 / 0.0125, 0.0036, 0.0069; similarity guides 0.0689 / 0.0722;
    the first frame's paths 0.0263 / 0.0278, 0.0041, 0.0116.
  Worse than the fit everywhere, even where the fit slides (plain fabric): the fitted frames
  are not near-isometric to each other where the template was completed, and vertices near an
  opening land on its cone. Not kept as an option.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.meshes import remove_small_components
from fourd.geometry.rotations import procrustes
from fourd.methods.garment import TrackingOptions, initial_ellipses, loop_ellipse, track_boundary
from fourd.methods.garment.base_holes import reparameterize_holes
from fourd.methods.garment.base_mesh import (
    base_mesh,
    closed_surface,
    map_through_base,
    parameterize_onto_base,
    vertex_base_coordinates,
)
from fourd.methods.garment.ellipse import as_batch, point_distances
from fourd.synth.garments import tshirt

GUIDE_REACH = 0.3


def _reach(anchors: np.ndarray) -> float:
    return GUIDE_REACH * float(np.median(np.linalg.norm(anchors[:, None] - anchors[None], axis=2)[
        np.triu_indices(len(anchors), 1)]))


def _guides(paths: list, from_anchors: np.ndarray, to_anchors: np.ndarray) -> list:
    move = procrustes(from_anchors, to_anchors, with_scale=True)
    return [move.scale * path @ move.rotation.T + move.translation for path in paths]


def _truth_openings(vertices, faces, reference=None):
    loops = [loop for loop in boundary_loops(faces, len(vertices)) if len(loop) >= 6]
    ellipses = initial_ellipses(vertices, faces, 4)
    centres = np.array([e.center for e in ellipses])
    order = range(4) if reference is None else [int(np.argmin(np.linalg.norm(centres - c, axis=1))) for c in reference]
    ellipses = [ellipses[k] for k in order]
    loops = [loops[int(np.argmin([np.linalg.norm(vertices[loop].mean(axis=0) - e.center) for loop in loops]))]
             for e in ellipses]
    return loops, np.array([e.center + e.radii.mean() * e.normal for e in ellipses]), np.array([e.center for e in ellipses])


def _truth_closed():
    """The generated T-shirt (20 frames), its first frame's anchors and base, and that frame
    closed by cones at its anchors."""
    shirt = tshirt(20, 0)
    faces = shirt.faces
    loops, anchors, centres = _truth_openings(shirt.vertices[0], faces)
    base = base_mesh(anchors)
    closed, closed_faces, apex = closed_surface(shirt.vertices[0], faces, loops, anchors)
    return shirt, faces, anchors, centres, base, closed, closed_faces, apex


def truth() -> None:
    shirt, faces, anchors, centres, base, closed, closed_faces, apex = _truth_closed()
    for slide in (False, True):
        first = parameterize_onto_base(closed, closed_faces, apex, base, slide=slide)
        facets, barycentric = vertex_base_coordinates(first, len(shirt.vertices[0]))
        paths = [closed[path] for path in first.charts.paths]
        for guided in (False, True):
            print(f"borders {'sliding' if slide else 'fixed'}, paths {'guided' if guided else 'shortest'}:")
            for t in range(1, 20, 2):
                later = shirt.vertices[t]
                later_loops, later_anchors, _ = _truth_openings(later, faces, centres)
                guides = _guides(paths, anchors, later_anchors) if guided else None
                started = time.perf_counter()
                lv, lf, la = closed_surface(later, faces, later_loops, later_anchors)
                mapped = parameterize_onto_base(lv, lf, la, base, guides=guides, reach=_reach(later_anchors), slide=slide)
                points, _, _ = map_through_base(facets, barycentric, lv, lf, mapped)
                seconds = time.perf_counter() - started
                error = np.linalg.norm(points - later, axis=1) / shirt.diagonal()
                print(f"  frame {t:2d}: stretch {mapped.stretch:.3f}, error median {np.median(error):.4f} mean "
                      f"{error.mean():.4f} 95th {np.percentile(error, 95):.4f}, {seconds:.2f} s")


def _arcs(vertices, loops, ellipses):
    loops = [loop for loop in loops if len(loop) >= 6]
    distances = [[point_distances(as_batch(e), vertices[loop])[0] / e.radii.mean() for loop in loops] for e in ellipses]
    nearest = [int(np.argmax([np.sum(d <= 1.0) for d in row])) for row in distances]
    arcs = []
    for k, index in enumerate(nearest):
        loop, on = loops[index], distances[k][index] <= 0.5
        if nearest.count(index) == 1 or on.all():
            arcs.append(loop)
            continue
        start = int(np.argmin(on))
        rolled, flags = np.roll(loop, -start), np.roll(on, -start)
        edges = np.flatnonzero(np.diff(np.r_[0, flags.astype(np.int8), 0]))
        run = int(np.argmax(edges[1::2] - edges[::2])) if len(edges) else 0
        arcs.append(rolled[edges[2 * run]:edges[2 * run + 1]] if len(edges) else loop[:0])
    return arcs


def _scan_setup(frames: int = 4):
    """The bench's T-shirt scan (first ``frames``): each frame's surface, the tracks of its
    openings, the base of the first frame's anchors, the template's closed surface and its paths."""
    from fourd.geometry.frame_surface import SurfaceSettings, frame_surface
    from fourd.methods.garment import Options
    from fourd.methods.garment.pipeline import _frame_meshes, _frame_template

    sys.path.insert(0, "experiments")
    from garment_fit_data import _scene

    _, _, scans = _scene("tshirt-cloth-video")
    meshes = _frame_meshes(scans, Options(boundaries=4))[:frames]
    first = scans.frames[0]
    coarse = frame_surface(first.points, normals=first.normals, sensors=first.sensors,
                           settings=SurfaceSettings(grid_scale=Options().template_scale))
    rest, faces, openings = _frame_template(np.asarray(coarse[0], float), np.asarray(coarse[1], np.int64), 4)
    ellipses = [loop_ellipse(rest[loop]) for loop in openings]
    boundary = [v[np.concatenate(boundary_loops(f, len(v)))] for v, f in meshes]
    tracks = [track_boundary(boundary, ellipse, TrackingOptions()) for ellipse in ellipses]
    anchors = np.array([track.anchors[0] for track in tracks])
    base = base_mesh(anchors)
    loops = [loop for loop in boundary_loops(faces, len(rest)) if len(loop) >= 3]
    closed, closed_faces, apex = closed_surface(rest, faces, _arcs(rest, loops, [t.ellipse(0) for t in tracks]), anchors)
    template = parameterize_onto_base(closed, closed_faces, apex, base)
    print(f"template: {len(rest)} vertices, stretch {template.stretch:.3f}")
    paths = [closed[path] for path in template.charts.paths]
    return meshes, tracks, anchors, base, paths


def _scan_frames(meshes, tracks):
    """Per later frame: its index, surface, openings' arcs and anchors."""
    for t in range(1, len(meshes)):
        vertices, mesh_faces = remove_small_components(*meshes[t], min_fraction=0.2)
        loops = [loop for loop in boundary_loops(mesh_faces, len(vertices)) if len(loop) >= 3]
        frame_anchors = np.array([track.anchors[t] for track in tracks])
        yield t, vertices, mesh_faces, loops, _arcs(vertices, loops, [track.ellipse(t) for track in tracks]), frame_anchors


def scan() -> None:
    meshes, tracks, anchors, base, paths = _scan_setup()
    for t, vertices, mesh_faces, loops, arcs, frame_anchors in _scan_frames(meshes, tracks):
        try:
            lv, lf, la = closed_surface(vertices, mesh_faces, arcs, frame_anchors)
        except InputError as error:
            print(f"frame {t}: {error}")
            continue
        for slide in (False, True):
            started = time.perf_counter()
            try:
                mapped = parameterize_onto_base(lv, lf, la, base, guides=_guides(paths, anchors, frame_anchors),
                                                reach=_reach(frame_anchors), slide=slide)
                outcome = f"stretch {mapped.stretch:.3f}"
            except InputError as error:
                outcome = str(error)
            print(f"frame {t}: {len(mesh_faces)} faces, {len(loops)} holes, borders "
                  f"{'sliding' if slide else 'fixed'}: {outcome}, {time.perf_counter() - started:.1f} s")


def _holed(vertices, faces, centre, radius):
    """``vertices, faces`` without the faces whose centres lie within ``radius`` of ``centre``:
    ``(vertices, faces, index)``, ``index`` the new index of every old vertex (-1: gone)."""
    cut = np.linalg.norm(vertices[faces].mean(axis=1) - centre, axis=1) < radius
    used = np.unique(faces[~cut])
    index = np.full(len(vertices), -1)
    index[used] = np.arange(len(used))
    return vertices[used], index[faces[~cut]], index


def holes() -> None:
    shirt, faces, anchors, centres, base, closed, closed_faces, apex = _truth_closed()
    first = parameterize_onto_base(closed, closed_faces, apex, base)
    facets, barycentric = vertex_base_coordinates(first, len(shirt.vertices[0]))
    paths = [closed[path] for path in first.charts.paths]
    rest = shirt.vertices[0]
    middle = np.abs(rest[:, 1] - (0.4 * rest[:, 1].min() + 0.6 * rest[:, 1].max())) < 0.03
    spots = {"front": int(np.flatnonzero(middle)[np.argmax(rest[middle, 2])]),
             "back": int(np.flatnonzero(middle)[np.argmin(rest[middle, 2])])}
    for t in (5, 9, 15):
        later = shirt.vertices[t]
        for name, spot in spots.items():
            holed, holed_faces, index = _holed(later, faces, later[spot], 0.15)
            inside = np.linalg.norm(later - later[spot], axis=1) < 0.15
            candidates = boundary_loops(holed_faces, len(holed))
            _, later_anchors, later_centres = _truth_openings(later, faces, centres)
            openings = [candidates[int(np.argmin([np.linalg.norm(holed[c].mean(axis=0) - centre) for c in candidates]))]
                        for centre in later_centres]
            guides = _guides(paths, anchors, later_anchors)
            result = reparameterize_holes(holed, holed_faces, openings, later_anchors, base, guides=guides,
                                          reach=_reach(later_anchors))
            plain_vertices, plain_faces, plain_apex = closed_surface(holed, holed_faces, openings, later_anchors)
            plain = parameterize_onto_base(plain_vertices, plain_faces, plain_apex, base, guides=guides,
                                           reach=_reach(later_anchors))
            row = []
            for surface, surface_faces, mapped in ((plain_vertices, plain_faces, plain),
                                                   (result.vertices, result.faces, result.parameterization)):
                points, _, _ = map_through_base(facets, barycentric, surface, surface_faces, mapped)
                error = np.linalg.norm(points - later, axis=1) / shirt.diagonal()
                row.append(f"stretch {mapped.stretch:.3f}, error mean {error.mean():.4f} in the hole "
                           f"{error[inside].mean():.4f} around it {error[~inside].mean():.4f}")
            print(f"truth frame {t}, hole in the {name} ({inside.sum()} vertices): membrane {row[0]}; "
                  f"re-triangulated ({len(result.stretches) - 1} rounds) {row[1]}", flush=True)
    meshes, tracks, anchors, base, paths = _scan_setup()
    for t, vertices, mesh_faces, _, arcs, frame_anchors in _scan_frames(meshes, tracks):
        for slide in (False, True):
            started = time.perf_counter()
            try:
                result = reparameterize_holes(vertices, mesh_faces, arcs, frame_anchors, base, slide=slide,
                                              guides=_guides(paths, anchors, frame_anchors), reach=_reach(frame_anchors))
                outcome = (f"stretch per round {np.round(result.stretches, 3).tolist()}, flips {result.flips}, "
                           f"{result.filled.sum()} hole vertices")
            except InputError as error:
                outcome = str(error)
            print(f"frame {t}: borders {'sliding' if slide else 'fixed'}: {outcome}, "
                  f"{time.perf_counter() - started:.1f} s", flush=True)


def _through_base(vertices, faces, openings, anchors, similarity: bool):
    """The fitted frames' correspondences taken through the base: the first frame's vertices
    carried into every frame's fitted surface. ``similarity``: each frame's paths guided by the
    first frame's moved by the anchors' similarity, borders sliding; else cut along the first
    frame's very paths (the connectivity is the same), borders fixed."""
    vertices = np.array(vertices)
    base = base_mesh(anchors[0])
    closed, closed_faces, apex = closed_surface(vertices[0], faces, openings, anchors[0])
    first = parameterize_onto_base(closed, closed_faces, apex, base, slide=similarity)
    facets, barycentric = vertex_base_coordinates(first, vertices.shape[1])
    paths = [closed[path] for path in first.charts.paths]
    for t in range(1, len(vertices)):
        frame, frame_faces, frame_apex = closed_surface(vertices[t], faces, openings, anchors[t])
        if similarity:
            mapped = parameterize_onto_base(frame, frame_faces, frame_apex, base, reach=_reach(anchors[t]),
                                            guides=_guides(paths, anchors[0], anchors[t]))
        else:
            mapped = parameterize_onto_base(frame, frame_faces, frame_apex, base, paths=first.charts.paths,
                                            slide=False)
        if np.isfinite(mapped.stretch):
            vertices[t], _, _ = map_through_base(facets, barycentric, frame, frame_faces, mapped)
    return vertices


def fitted() -> None:
    from dataclasses import replace

    from fourd.methods import garment
    from fourd.methods.garment import pipeline
    from fourd.metrics import evaluate

    sys.path.insert(0, "experiments")
    from garment_fit_data import _scene

    for label in ("tshirt-cloth-video", "tshirt-diffuse-video"):
        _, truth, scans = _scene(label)
        captured = {}
        track = pipeline.track_boundary

        def keep(*args, _track=track, _captured=captured, **kwargs):
            result = _track(*args, **kwargs)
            _captured.setdefault("tracks", []).append(result)
            return result

        pipeline.track_boundary = keep
        result = garment.reconstruct(scans, garment.Options(boundaries=4))
        pipeline.track_boundary = track
        tracks = captured["tracks"]
        anchors = np.stack([t.anchors for t in tracks], axis=1)
        centres = [t.centers[0] for t in tracks]
        loops = boundary_loops(result.faces, result.vertex_count)
        # each track's loop of the template: the loop whose centroid lies nearest its first centre
        openings = [loops[int(np.argmin([np.linalg.norm(result.vertices[0][loop].mean(axis=0) - c)
                                         for loop in loops]))] for c in centres]
        for name, vertices in (("fit", result.vertices),
                               ("through the base, similarity guides, sliding",
                                _through_base(result.vertices, result.faces, openings, anchors, True)),
                               ("through the base, the first frame's paths, fixed borders",
                                _through_base(result.vertices, result.faces, openings, anchors, False))):
            r = evaluate(replace(result, vertices=vertices), truth, samples=20000, seed=0)
            print(f"{label} {name}: correspondence {r['correspondence_mean']:.4f} / {r['correspondence_last']:.4f}, "
                  f"Chamfer {r['chamfer']:.4f}, completeness-95 {r['completeness_95']:.4f}", flush=True)


if __name__ == "__main__":
    {"truth": truth, "scan": scan, "holes": holes, "fitted": fitted}[sys.argv[1] if len(sys.argv) > 1 else "truth"]()
