"""The garment capture, end to end (Popa's thesis, chapter 3).

1. Each frame's surface: its own faces when the input is per-frame meshes, else its points
   meshed on their own (:func:`fourd.geometry.frame_surface.frame_surface`).
2. The garment's openings (neck, sleeves, waist) found in the first frame as its longest
   boundary loops and tracked through every frame as ellipses (3.6.1, Appendix B); a loop's
   ellipse is the one most of it lies on, since an occlusion hole that runs into an opening
   is part of the opening's loop.
3. The template: inflated from a photo of the garment laid flat (3.7) when one is given, and
   placed on the first frame by the similarity that maps its openings onto the frame's; else
   the first frame's own surface with its other holes filled by the C1 membrane (3.6.2).
4. The template fitted onto every frame in turn, as rigidly as possible, held across the
   frame's surface and its openings pulled onto the frame's tracked openings (the frame's
   boundary points on the tracked ellipse, and the ellipse itself where the cameras missed an
   arc), free to slide along both (:mod:`.fit`; the thesis maps the template through a
   base-mesh parameterisation instead). Each frame's fit starts where the last step's motion
   carries the template (``motion_prediction``), guided by the video's anchors and the colours
   (``anchor_weight``). Where no frame data lies near, the template's shape completes the
   frame and the vertex is marked not observed.
5. The trajectories smoothed in time by a Gaussian (end of 3.7).
6. With ``wrinkles`` and video: folds seen in the video put into the garment by the
   space-time deformation of chapter 4 (:mod:`.wrinkling`); an observed vertex moves only
   along its frame's data normal toward the data (``wrinkles_hold_data``).

Not the thesis' path here: the template mapped into each frame through the base-mesh
parameterisation of 3.6.2 (:mod:`.base_mesh`). On the bench's scanned frames that map folds or
stretches about twice as much as on the true surfaces (``experiments/garment_base_mesh.py``),
so the frame-to-frame fit of step 4 places the template instead.
"""

from __future__ import annotations

import itertools
import json
import logging
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.appearance.color_guide import PhotometricGuides, colors_of_cleaned
from fourd.appearance.guide import Guide, anchor_guide
from fourd.cache import report_resumed
from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.frame_surface import SurfaceSettings, frame_surface, frame_surfaces
from fourd.geometry.hole_filling import fill_holes
from fourd.geometry.meshes import median_edge_length, remove_small_components
from fourd.geometry.normals import vertex_normals
from fourd.methods.garment.boundary_tracking import (
    TrackingOptions,
    loop_ellipse,
    read_keyframes,
    track_boundary,
    turned_outward,
)
from fourd.methods.garment.ellipse import as_batch, fit_ellipse, point_distances
from fourd.methods.garment.fit import FitOptions, align_template, fit_template
from fourd.methods.garment.options import Options
from fourd.methods.garment.template import TemplateOptions, outline_from_photo, template_from_photo
from fourd.methods.garment.wrinkling import hold_to_data, wrinkle
from fourd.progress import progress
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.garment")

#: The cache entries of the frames' surfaces.
STAGE = "garment-surface"
#: The colour guide's Lucas-Kanade patch radius and uncertainty scale, in template edges
#: (``kinematic``'s ``color_radius`` and ``color_scale``), and the least summed weight, as a
#: fraction of the vertices, for which a frame is fitted again (``kinematic``'s
#: ``LATE_GUIDE_SUPPORT``).
COLOR_RADIUS, COLOR_SCALE, LATE_GUIDE_SUPPORT = 3.0, 0.5, 0.01
#: A boundary point belongs to an opening when it lies within this many of the opening's mean
#: radii of its ellipse.
OPENING_REACH = 0.15
#: Points along a tracked opening's ellipse that its template vertices are pulled to, besides
#: the frame's own boundary points on it.
OPENING_SAMPLES = 512

#: Without ``template_edge``, the photo's template has edges this fraction of the garment's
#: diagonal laid flat: three edges across a fold of half the fold measure's cutoff wavelength
#: (5% of the diagonal; ``fourd.metrics.folds.FOLD_WAVELENGTH``), so the fit can hold the
#: folds the scans show. At 0.04 garment units (a 37th) the T-shirt's fold recall was 0.10.
PHOTO_EDGE_FRACTION = 1.0 / 60.0

__all__ = ["reconstruct"]


def _frame_meshes(seq: PointCloudSequence, options: Options) -> list[tuple[np.ndarray, np.ndarray]]:
    meshes, found = frame_surfaces(seq.frames, SurfaceSettings(), cache_dir=options.cache_dir, stage=STAGE,
                                   desc="garment: frame surfaces", scheduler=options.scheduler)
    for index, (_, faces) in enumerate(meshes):
        if len(faces) < 4:
            raise InputError(f"frame {index}: no surface could be made of its {len(seq.frames[index].points)} points")
    if found:
        report_resumed(log, f"{found} of {len(seq.frames)} frames' surfaces")
    return meshes


def _openings(vertices, faces, count: int) -> list[np.ndarray]:
    loops = [loop for loop in boundary_loops(faces, len(vertices)) if len(loop) >= 6]
    if not loops:
        raise InputError("the first frame's surface has no boundary: a garment has openings (neck, sleeves, waist)")
    if count <= 0:
        perimeter = [np.linalg.norm(np.diff(vertices[np.r_[loop, loop[:1]]], axis=0), axis=1).sum() for loop in loops]
        count = int(np.sum(np.array(perimeter) >= max(perimeter) / 3.0))
    if len(loops) < count:
        raise InputError(f"the first frame's surface has {len(loops)} boundary loops, the garment needs {count}")
    return loops[:count]


def _frame_template(vertices, faces, count: int):
    """The first frame's surface, its holes but the ``count`` openings (0: found as in
    :func:`_openings`) filled, the largest piece kept: ``(vertices, faces, openings)``."""
    vertices, faces = remove_small_components(vertices, faces, min_fraction=0.2)
    loops = [loop for loop in boundary_loops(faces, len(vertices)) if len(loop) >= 3]
    kept = _openings(vertices, faces, count)
    opening_sets = [set(loop.tolist()) for loop in kept]
    holes = [loop for loop in loops if set(loop.tolist()) not in opening_sets]
    filled = fill_holes(vertices, faces, holes=holes)
    return filled.vertices, filled.faces, kept


def _on_opening(points: np.ndarray, ellipse) -> np.ndarray:
    """Which of ``points [P, 3]`` lie on the opening that ``ellipse`` fits (within
    :data:`OPENING_REACH` of its mean radii): bool [P]."""
    return point_distances(as_batch(ellipse), points)[0] <= OPENING_REACH * ellipse.radii.mean()


def _photo_template(options: Options):
    path = Path(options.photo)
    calibration_path = path.with_name("pattern.json") if path.suffix.lower() != ".json" else path
    image_path = path if path.suffix.lower() != ".json" else path.with_suffix(".png")
    try:
        from PIL import Image

        image = np.asarray(Image.open(image_path))
        calibration = json.loads(calibration_path.read_text())
    except FileNotFoundError as error:
        raise InputError(f"garment photo: {error.filename} not found") from None
    except (OSError, ValueError) as error:
        raise InputError(f"garment photo {image_path}: cannot be read ({error})") from None
    edge = options.template_edge
    if edge <= 0:
        garment_diagonal = float(np.linalg.norm(np.ptp(outline_from_photo(image, calibration), axis=0)))
        edge = PHOTO_EDGE_FRACTION * garment_diagonal
    return template_from_photo(image, calibration, TemplateOptions(edge=edge))


def _place_photo_template(template, first_vertices, openings):
    """The photo's template moved onto the first frame (``first_vertices [N, 3]``, its
    ``openings`` as vertex loops): ``(placed vertices, template loops, frame ellipses)``, the
    template's openings matched to the frame's (in their order) by the permutation whose
    similarity fits best. Both sides' ellipses have their normals turned away from their
    garment: with either sign, the similarity put the dress upside down, its hem on the waist."""
    frame_ellipses = [turned_outward(loop_ellipse(first_vertices[loop]), first_vertices) for loop in openings]
    loops = [loop for loop in boundary_loops(template.faces, len(template.vertices)) if len(loop) >= 6]
    if len(loops) != len(frame_ellipses):
        raise InputError(f"the garment photo's template has {len(loops)} openings, the frames "
                         f"{len(frame_ellipses)}: set the option boundaries")
    ellipses = [turned_outward(fit_ellipse(template.vertices[loop]), template.vertices) for loop in loops]
    best = None
    for order in itertools.permutations(range(len(loops))):
        rotation, scale, translation = align_template([ellipses[k] for k in order], frame_ellipses)
        placed = scale * template.vertices @ rotation.T + translation
        error = sum(np.linalg.norm(placed[loops[k]].mean(axis=0) - e.center) for k, e in zip(order, frame_ellipses, strict=True))
        if best is None or error < best[0]:
            best = (error, placed, [loops[k] for k in order])
    return best[1], best[2], frame_ellipses


def _color_guides(seq, meshes, template, faces, edge) -> PhotometricGuides:
    """Per frame, the colour guide of the template lying on the first frame (its colours read
    there once): each frame's surface vertices carry the colours of their nearest points."""
    points = [vertices for vertices, _ in meshes]
    normals = [vertex_normals(vertices, mesh_faces) for vertices, mesh_faces in meshes]
    colors = [colors_of_cleaned(frame.points, frame.colors, vertices)
              for frame, (vertices, _) in zip(seq.frames, meshes, strict=True)]
    return PhotometricGuides(template, faces, range(len(meshes)), points, normals, colors,
                             radius=COLOR_RADIUS * edge, scale=COLOR_SCALE * edge)


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """The garment's animated mesh (see the module docstring)."""
    options = options or Options()
    if len(seq) < 2:
        raise InputError("garment needs at least 2 frames")
    meshes = _frame_meshes(seq, options)
    first_vertices, first_faces = meshes[0]
    anchors = None
    if options.video_anchors and getattr(seq, "video", None) is not None:
        from fourd.appearance import anchors as track_anchors

        anchors = track_anchors(seq, texture=3.0, sources=2.0)
    if options.photo:
        openings = _openings(first_vertices, first_faces, options.boundaries)
        template = _photo_template(options)
        start, template_loops, frame_ellipses = _place_photo_template(template, first_vertices, openings)
        rest, faces, uv = start, template.faces, template.uv[template.faces]  # per face corner
        first_iterations = 4 * options.iterations
    else:
        frame = seq.frames[0]
        coarse = (frame.points, frame.faces) if frame.faces is not None and len(frame.faces) else frame_surface(
            frame.points, normals=frame.normals, sensors=frame.sensors,
            settings=SurfaceSettings(grid_scale=options.template_scale))
        coarse = (np.asarray(coarse[0], dtype=np.float64), np.asarray(coarse[1], dtype=np.int64))
        rest, faces, openings = _frame_template(*coarse, options.boundaries)
        frame_ellipses = [loop_ellipse(rest[loop]) for loop in openings]
        # an occlusion hole run into an opening is part of its loop: only the opening's own
        # arc (near its ellipse) is pulled onto the frames' openings
        template_loops = [loop[_on_opening(rest[loop], ellipse)] for loop, ellipse in zip(openings, frame_ellipses, strict=True)]
        start, uv = rest, None
        first_iterations = options.iterations
    # the openings through the frames
    boundary_points = []
    for vertices, mesh_faces in meshes:
        loops = boundary_loops(mesh_faces, len(vertices))
        boundary_points.append(vertices[np.concatenate(loops)] if loops else np.zeros((0, 3)))
    keyframes = read_keyframes(options.keyframes) if options.keyframes else ()
    tracks = [track_boundary(boundary_points, ellipse, TrackingOptions(), keyframes) for ellipse in frame_ellipses]
    fit_options = FitOptions(iterations=options.iterations, data_weight=options.data_weight,
                             boundary_weight=options.boundary_weight, anchor_weight=options.anchor_weight)
    edge = median_edge_length(rest, faces)
    frames = len(meshes)
    vertices = np.empty((frames, len(rest), 3))
    observed = np.zeros((frames, len(rest)), dtype=bool)
    current = start
    colours = None
    for t in progress(range(frames), desc="garment: fitting the template", unit="frame"):
        frame_vertices, frame_faces = meshes[t]
        pairs = []
        for loop, track in zip(template_loops, tracks, strict=True):
            ellipse = track.ellipse(t)
            # the frame's boundary points on the opening, and the ellipse where the cameras missed an arc
            points = boundary_points[t]
            kept = np.concatenate([points[_on_opening(points, ellipse)], ellipse.points(OPENING_SAMPLES)])
            pairs.append((loop, kept))
        iterations = first_iterations if t == 0 else options.iterations
        if t >= 2:
            current = current + options.motion_prediction * (vertices[t - 1] - vertices[t - 2])
        guide = None
        if anchors is not None and t > 0 and len(anchors[t - 1].source):
            pair = anchors[t - 1]  # starting on frame t - 1's fit
            guide = anchor_guide(vertices[t - 1], pair.source, pair.target, pair.confidence, radius=2.0 * edge)
            start = current.copy()
            start[guide.vertices] += guide.weight[:, None] * (guide.positions - current[guide.vertices])
            current = start
        current = fit_template(rest, faces, current, frame_vertices, frame_faces, openings=pairs, guide=guide,
                               options=FitOptions(**{**fit_options.__dict__, "iterations": iterations}))
        if t == 0 and options.color_guide and all(f.colors is not None for f in seq.frames):
            colours = _color_guides(seq, meshes, current, faces, edge)
        if colours is not None and t > 0:
            late = colours[t](current)
            if late is not None and late.weight.sum() >= LATE_GUIDE_SUPPORT * len(current):
                both = late if guide is None else Guide(np.r_[guide.vertices, late.vertices],
                                                         np.r_[guide.positions, late.positions],
                                                         np.r_[guide.weight, late.weight])
                current = fit_template(rest, faces, current, frame_vertices, frame_faces, openings=pairs,
                                       guide=both, options=fit_options)
        vertices[t] = current
        distance, _ = cKDTree(frame_vertices).query(current, workers=-1)
        observed[t] = distance <= options.observed_distance * median_edge_length(frame_vertices, frame_faces)
    if options.time_sigma > 0:
        vertices = gaussian_filter1d(vertices, options.time_sigma, axis=0, mode="nearest")
    if options.wrinkles and getattr(seq, "video", None) is not None:
        wrinkled = wrinkle(vertices, faces, seq.video)
        log.info("garment: wrinkled from %d fold pairs in the video, largest edge stretch %.3f",
                 sum(frame.used for frame in wrinkled.anchors), float(wrinkled.stretch.max()))
        if options.wrinkles_hold_data:
            for t, (frame_vertices, frame_faces) in enumerate(meshes):
                wrinkled.vertices[t] = hold_to_data(vertices[t], wrinkled.vertices[t], frame_vertices,
                                                    vertex_normals(frame_vertices, frame_faces), ~observed[t])
        vertices = wrinkled.vertices
    log.info("garment: %d template vertices, %.0f%% observed", len(rest), 100 * observed.mean())
    return AnimatedMesh(faces, vertices, times=np.asarray(seq.times, dtype=np.float64), observed=observed,
                        rest=rest, uv=uv)

