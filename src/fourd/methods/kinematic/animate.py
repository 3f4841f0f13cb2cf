"""The urshape at the first time and its sliding along a space-time field (sections 4 and 5
with the data term): everything of :func:`~fourd.methods.kinematic.reconstruct` after the
4D fit.
"""

from __future__ import annotations

import logging
import time as _time
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.appearance.color_guide import PhotometricGuides
from fourd.cache import NO_CACHE, Chain, StageCache, cached, report_resumed, stage_key
from fourd.errors import InputError
from fourd.geometry.meshes import median_edge_length
from fourd.methods.kinematic.framesurface import FrameSurface
from fourd.methods.kinematic.options import PROJECTION_LIMIT, SMOOTHED_PROJECTION_MIN, Options
from fourd.methods.kinematic.projection import project_to_surface
from fourd.methods.kinematic.register import RegisterOptions
from fourd.methods.kinematic.sliding import SlideOptions, slide
from fourd.methods.kinematic.trajectories import smooth_trajectories
from fourd.methods.kinematic.urshape import extract_template, template_cell_size, template_size

log = logging.getLogger("fourd.methods.kinematic")

#: An automatic template cell is at least the longest side of the box over this many cells
#: (marching cubes over 600^3 grid points is the most the urshape extraction allows).
MAX_TEMPLATE_CELLS = 600
#: The cache entries of the urshape, of the frames slid forwards in time and of those slid
#: backwards (output times before the first input time).
URSHAPE_STAGE = "kinematic-urshape"
SLIDE_STAGE = "kinematic-slide"
SLIDE_BACK_STAGE = "kinematic-slide-back"


def animate(
    field,
    points: list[np.ndarray],
    normals: list[np.ndarray],
    times: np.ndarray,
    *,
    spacing: float,
    options: Options,
    closed: bool = False,
    bounds: np.ndarray | None = None,
    project_smoothed: bool = False,
    edge_stiffness: tuple | None = None,
    anchors=None,
    colors: list | None = None,
    cache: StageCache = NO_CACHE,
    field_key: str = "",
) -> AnimatedMesh:
    """Urshape at ``times[0]`` and its sliding along ``field`` (sections 4 and 5 with this
    method's data term): everything of :func:`reconstruct` after the 4D fit, for any
    :class:`~fourd.Field4D`.

    Parameters
    ----------
    field : Field4D
        Space-time implicit, negative inside, time in the units of ``times``.
    points, normals : lists of T arrays [P_k, 3]
        Cleaned input points per frame with oriented unit normals (``P_k`` may be 0: a frame
        with no data slides without a data term; frame 0 must have points).
    times : array [T]
        Input times, strictly increasing.
    spacing : float
        Point spacing ``s`` (see :class:`Options`).
    closed : bool
        Polygonise the urshape everywhere in ``bounds`` (a closed template of a closed
        field), not only near the first frame's points (open scans stay open).
    bounds : ndarray [2, 3], optional
        Box of the urshape (default: the first frame's points).
    project_smoothed : bool
        After the trajectory smoothing, project the vertices it moved farther than
        :data:`SMOOTHED_PROJECTION_MIN` median edges back onto the surface (4 Newton steps,
        at most 2 edges each; the template's frame stays): on fast curved motion the filter
        cuts the corners of the trajectories, off the surface. The surface is the frame's own
        points where the data term has them, else ``field``. The vertices the smoothing
        moved less keep their smoothed place: projecting every vertex brought the frames'
        noise back (``flow`` ``coherent=true`` on ``dfaust-hopping``, 20k samples: jitter
        0.89 unprojected, 1.74 all projected, 0.94 with this rule; crane Chamfer /
        completeness-95 0.0034 / 0.0073, 0.0031 / 0.0060 and 0.0032 / 0.0062).
    edge_stiffness : tuple, optional
        ``(edges [E, 2], values [E])``: factors on the sliding's ARAP weights of those urshape
        edges (:attr:`SlideOptions.edge_stiffness`).
    anchors : Anchors, optional
        Anchor tracks between consecutive input frames (:func:`fourd.appearance.anchors`):
        the forward sliding's steps between two consecutive input frames start where they
        went (:mod:`fourd.appearance.guide`).
    colors : list of T arrays [P_k, 3] or None, optional
        Colours of ``points`` (None for a frame without): with ``options.color_guide``, the
        forward sliding's steps at input frames relax again pulled where the template's
        colours say the vertices went (:mod:`fourd.appearance.color_guide`).
    cache : StageCache
        Where the urshape and every slid frame are kept as they finish (a rerun resumes
        after the last slid frame); needs ``field_key``.
    field_key : str
        The cache key of ``field`` (:func:`~.field.fit_key`): what identifies it.
    """
    if cache.enabled and not field_key:
        raise ValueError("animate: a cache needs the field's key (field_key)")
    started = _time.perf_counter()
    times = np.asarray(times, dtype=float)
    # the cache keys of the frames: what the urshape and each sliding step read of them
    frame_keys = None
    if cache.enabled:
        frame_keys = [stage_key(p, n) for p, n in zip(points, normals, strict=True)]
    box, target_vertices, cell, bandwidth = template_settings(points, spacing, options, bounds)
    urshape_key = ""
    if cache.enabled:
        urshape_key = stage_key(
            URSHAPE_STAGE, field_key, frame_keys[0], float(times[0]), np.asarray(box, float),
            cell, options.cell_size, target_vertices, options.smoothing_iterations,
            options.data_term, bandwidth, closed,
        )

    def urshape():
        vertices, faces = urshape_of_field(
            field, points, normals, times, box, cell, bandwidth, options, closed
        )
        return {"vertices": vertices, "faces": faces}

    template, resumed = cached(cache, URSHAPE_STAGE, urshape_key, urshape)
    vertices, faces = template["vertices"], template["faces"]
    if resumed:
        report_resumed(log, "the urshape")
    urshape = _time.perf_counter()
    log.info("urshape: %d vertices in %.2f s", len(vertices), urshape - started)

    time_unit = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    out_times = np.array(options.times, dtype=float) if options.times else times.copy()
    out_times = np.unique(out_times)
    nearest = np.abs(out_times[:, None] - times[None, :]).argmin(axis=1)
    # per output time, the input frame whose surface is the data term there (-1: none)
    exact = np.abs(out_times - times[nearest]) <= 1e-9 * time_unit
    has_points = np.array([len(points[k]) > 0 for k in nearest])
    surface_frames = list(np.where(exact & has_points & options.data_term, nearest, -1))

    def surfaces(frames):
        return FrameSurfaces(frames, points, normals, bandwidth)

    slide_options = slide_settings(options, vertices, faces, spacing, edge_stiffness)

    def chain(stage, slide_times, data_frames, surface_frames):
        """The cache entries of one sliding run: each step keyed by the step before it, its
        time, its data and its surface."""
        if not cache.enabled:
            return None
        base = stage_key(stage, urshape_key, slide_options, bandwidth, float(slide_times[0]),
                         anchor_key, colour_key)
        steps = [
            (float(t), frame_keys[d], None if f < 0 else frame_keys[f])
            for t, d, f in zip(slide_times[1:], data_frames[1:], surface_frames[1:], strict=True)
        ]
        return Chain.of(cache, stage, base, steps)

    anchor_key = None
    if anchors is not None and cache.enabled:
        anchor_key = [(p.source, p.target, p.confidence) for p in anchors]
    color_guided = options.color_guide and colors is not None and colors[0] is not None
    colour_key = None
    if color_guided and cache.enabled:
        colour_key = ["colour", options.color_radius, options.color_scale] + [
            np.zeros(0) if c is None else c for c in colors
        ]
    t0 = float(times[0])
    forward = out_times >= t0
    parts_v, parts_o = [], []
    if (~forward).any():
        back_times = np.r_[t0, out_times[~forward][::-1]]
        count = int((~forward).sum())
        back_frames = [0] + [int(k) for k in nearest[:count][::-1]]
        back_surfaces = [-1] + surface_frames[:count][::-1]
        back = _slide_monotone(
            vertices,
            faces,
            field,
            back_times,
            slide_options,
            [points[k] for k in back_frames],
            surfaces(back_surfaces),
            chain(SLIDE_BACK_STAGE, back_times, back_frames, back_surfaces),
        )
        parts_v.append(back[0][1:][::-1])
        parts_o.append(back[1][1:][::-1])
    fwd_times = out_times[forward]
    fwd_frames = [int(nearest[i]) for i in np.flatnonzero(forward)]
    fwd_surfaces = [surface_frames[i] for i in np.flatnonzero(forward)]
    prepend = len(fwd_times) == 0 or fwd_times[0] > t0
    if prepend:
        fwd_times = np.r_[t0, fwd_times]
        fwd_frames = [0] + fwd_frames
        fwd_surfaces = [-1] + fwd_surfaces
    fv, fo = _slide_monotone(
        vertices,
        faces,
        field,
        fwd_times,
        slide_options,
        [points[k] for k in fwd_frames],
        surfaces(fwd_surfaces),
        chain(SLIDE_STAGE, fwd_times, fwd_frames, fwd_surfaces),
        _step_anchors(anchors, fwd_surfaces),
        (
            PhotometricGuides(
                vertices, faces, fwd_surfaces, points, normals, colors,
                radius=options.color_radius * median_edge_length(vertices, faces),
                scale=options.color_scale * median_edge_length(vertices, faces),
            )
            if color_guided else None
        ),
    )
    if prepend:
        fv, fo = fv[1:], fo[1:]
    parts_v.append(fv)
    parts_o.append(fo)
    slid = np.concatenate(parts_v)
    smoothed = smooth_trajectories(
        slid, out_times, options.temporal_smoothing, motion_threshold=options.smoothing_motion
    )
    if project_smoothed:
        edge = median_edge_length(vertices, faces)
        for k in np.flatnonzero(out_times != t0):
            moved = np.linalg.norm(smoothed[k] - slid[k], axis=1) > SMOOTHED_PROJECTION_MIN * edge
            frame = surface_frames[k]
            smoothed[k][moved] = project_to_surface(
                field,
                smoothed[k][moved],
                float(out_times[k]),
                iterations=4,
                max_step=2.0 * edge,
                surface=FrameSurface(points[frame], normals[frame], bandwidth) if frame >= 0 else None,
            )
    return AnimatedMesh(
        faces=faces,
        vertices=smoothed,
        times=out_times,
        observed=np.concatenate(parts_o),
        rest=vertices,
    )


class TemplateSettings(NamedTuple):
    """How the urshape is extracted (:func:`template_settings`): the box ``[2, 3]`` it is
    polygonised in, its target vertex count, the marching-cubes cell and the data term's
    bandwidth."""

    box: np.ndarray
    target_vertices: int
    cell: float
    bandwidth: float


def template_settings(points, spacing: float, options: Options, bounds=None) -> TemplateSettings:
    """The urshape's settings from the cleaned frames ``points`` (list of ``[P_k, 3]``; the
    first frame's box unless ``bounds``) and the point spacing."""
    box = np.array([points[0].min(axis=0), points[0].max(axis=0)]) if bounds is None else bounds
    target_vertices = template_size(options.template_vertices, points)
    if target_vertices < options.template_vertices:
        log.info("sparse frames: a template of about %d vertices (%d asked)", target_vertices,
                 options.template_vertices)
    cell = options.cell_size or max(
        template_cell_size(points[0], spacing, target_vertices),
        # a few scattered points estimate a tiny area: keep the grid within bounds
        float(np.max(np.ptp(np.asarray(box, dtype=float), axis=0))) / MAX_TEMPLATE_CELLS,
    )
    bandwidth = options.data_bandwidth or 2.0 * spacing
    return TemplateSettings(box, target_vertices, cell, bandwidth)


def slide_settings(options: Options, vertices, faces, spacing: float, edge_stiffness=None) -> SlideOptions:
    """The sliding's options for the urshape ``vertices``, ``faces``."""
    return SlideOptions(
        iterations=options.iterations,
        # a vertex is observed when an input point lies within 2 edges, or within 3 point
        # spacings when the urshape is finer than the data
        epsilon=options.epsilon or max(2.0 * median_edge_length(vertices, faces), 3.0 * spacing),
        substeps=options.substeps,
        rigid_guess=options.rigid_guess,
        rigid_neighbours=options.rigid_neighbours,
        # both act only at input times with the data term
        register=(
            RegisterOptions(previous_shape=options.shape_memory) if options.large_motion
            else None
        ),
        projection_limit=PROJECTION_LIMIT,
        still_normals=options.still_normals,
        previous_shape=options.slide_memory,
        edge_stiffness=edge_stiffness,
        anchor_pull=options.anchor_pull,
        anchor_gate=options.anchor_gate,
    )


def urshape_of_field(field, points, normals, times, box, cell, bandwidth, options, closed):
    """The urshape at ``times[0]``: ``(vertices [N, 3], faces [F, 3])``."""
    # the area estimate of template_cell_size is rough on curved or thin shapes
    # (dfaust-hopping: 1.7x the target), so an automatic cell size is corrected once from the
    # marching-cubes vertex count: sliding costs grow with the vertex count
    vertices, faces = extract_template(
        field,
        times[0],
        bounds=np.asarray(box, dtype=float),
        cell_size=cell,
        data_points=None if closed else points[0],
        smoothing_iterations=options.smoothing_iterations,
        min_component_faces=20,
        target_vertices=0 if options.cell_size else template_size(options.template_vertices, points),
    )
    if len(faces) == 0:
        raise InputError("the 4D implicit has no surface at the first frame (too few points?)")
    if options.data_term:
        # the urshape on the first frame's own points: f(., t0) is posed a little off them
        vertices = project_to_surface(
            field,
            vertices,
            times[0],
            surface=FrameSurface(points[0], normals[0], bandwidth),
            max_step=2.0 * median_edge_length(vertices, faces),
        )
    return vertices, faces


class FrameSurfaces(Sequence):
    """Per sliding time, the :class:`FrameSurface` of input frame ``frames[i]`` (None where
    it is -1), built when the sliding asks for it: one frame's grid in memory at a time."""

    def __init__(self, frames, points, normals, bandwidth):
        self.frames, self.points, self.normals, self.bandwidth = frames, points, normals, bandwidth

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        k = int(self.frames[i])
        return None if k < 0 else FrameSurface(self.points[k], self.normals[k], self.bandwidth)


def _step_anchors(anchors, frames):
    """Per sliding time, the anchor tracks ``(source, target, confidence)`` from the previous
    time's input frame to this one's when they are consecutive input frames, else None."""
    if anchors is None:
        return None
    steps = [None]
    for before, after in zip(frames[:-1], frames[1:], strict=True):
        ok = before >= 0 and after == before + 1 and before < len(anchors)
        pair = anchors[before] if ok else None
        steps.append(None if pair is None else (pair.source, pair.target, pair.confidence))
    return steps


def _slide_monotone(vertices, faces, field, times, options, data, surfaces, checkpoints=None,
                    anchors=None, colour_guides=None):
    """Slide through monotone ``times`` (decreasing allowed); returns (frames, observed).
    ``checkpoints``: the cache entries of the steps (:func:`slide`), or None; ``anchors``:
    per time, the anchor tracks from the previous one (forward only), or None;
    ``colour_guides``: per time, the colour guide (forward only), or None."""
    if len(times) == 1:
        from scipy.spatial import cKDTree

        d, _ = cKDTree(data[0]).query(vertices, distance_upper_bound=options.epsilon or np.inf)
        return vertices[None].copy(), np.isfinite(d)[None]
    sign = 1.0 if times[-1] >= times[0] else -1.0
    # slide() wants increasing times: run it on a reflected time axis when going backwards
    if sign > 0:
        anim = slide(
            vertices, faces, field, times, options=options, data=data, surfaces=surfaces,
            checkpoints=checkpoints, anchors=anchors, colour_guides=colour_guides,
        )
    else:
        anim = slide(
            vertices,
            faces,
            _Reflected(field),
            -np.asarray(times),
            options=options,
            data=data,
            surfaces=surfaces,
            checkpoints=checkpoints,
        )
    return anim.vertices, anim.observed


class _Reflected:
    """``g(x, t) = f(x, -t)``: sliding backwards in time as forwards."""

    def __init__(self, field):
        self.field = field

    def value(self, points, times):
        return self.field.value(points, -np.asarray(times))

    def value_and_gradient(self, points, times):
        return self.value(points, times), self.gradient(points, times)

    def gradient(self, points, times):
        g = self.field.gradient(points, -np.asarray(times)).copy()
        g[:, 3] *= -1.0
        return g
