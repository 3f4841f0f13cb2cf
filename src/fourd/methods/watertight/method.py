"""Method ``watertight``: one closed animated mesh, by composition of two methods.

The ``kinematic`` method's result (Süßmuth et al. 2008, ``000_00387fefe94cc850.txt``) is open
where no frame saw the surface; the ``flow`` method's closed, manifold frames (Sharf et al.
2008, ``002_382acf333feb7a6e.txt``) give a signed distance in space-time
(:func:`fourd.methods.flow.surface_distance`). A closed template of the flow's surface at the
first frame is bound to the kinematic first frame: its bound vertices follow the kinematic
result exactly, the others are carried rigidly with their nearest bound vertices and moved
onto the flow's surface at every frame (:func:`close_animation`). The flow fills what the
frames do not see. Neither paper gives watertight frames with correspondences; this
composition does. With ``window`` set, the stages run window by window
(:mod:`fourd.methods.watertight.stream`).

Until this module existed the composition was the ``flow`` option ``coherent=true``; the
registry still accepts that spelling (:data:`fourd.methods.ALIASES`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Iterable, Iterator
from typing import NamedTuple

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.cache import subfolder
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.neighbors import point_spacing
from fourd.methods import flow, kinematic
from fourd.methods.base import Reconstruction, streamed_in_memory
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.watertight")

MIN_FRAMES = flow.MIN_FRAMES
RESULT = AnimatedMesh
#: The options :func:`estimate_peak_bytes` grows with (the flow's).
MEMORY_OPTIONS = flow.MEMORY_OPTIONS
#: The options users change first: the flow's (``fourd options watertight``).
COMMON_OPTIONS = flow.COMMON_OPTIONS

#: A template vertex farther than this many cells of the sliding field's grid from both the
#: flow's surface and its frame's points is off the surface, and a frame with more than
#: :data:`OFF_SURFACE_WARNING` of its vertices off it is reported (a warning, and the
#: diagnostic ``off_surface``, the largest fraction over the frames). Both, because the
#: sliding's data term follows each frame's own points, and the flow lags fast thin parts by
#: several cells (horse-gallop's legs: 10% of the template farther than 2 cells from the
#: flow's surface in its worst frame, in a sound run). Measured on horse-gallop (resolution
#: 32), a sound run and one whose hoof (1.5% of the template) flew off from frame 15: at most
#: 0.3% and 1.5% of the vertices off.
OFF_SURFACE_CELLS = 8.0
OFF_SURFACE_WARNING = 0.005
#: :func:`close_animation`: a vertex carried along moves by the rigid motion of this many
#: nearest bound vertices (:func:`rigid_blend`).
RIGID_ANCHORS = 32
#: :func:`close_on_flow` warns when the closed result lacks more than this fraction of the
#: tracked first frame (:class:`Closing` ``lost``).
LOST_WARNING = 0.02
#: :func:`close_animation` binds a template vertex to the open mesh within this many of its
#: median edges (or ``reach``, when farther).
BIND_EDGES = 1.5

__all__ = [
    "COMMON_OPTIONS",
    "MEMORY_OPTIONS",
    "MIN_FRAMES",
    "OFF_SURFACE_CELLS",
    "OFF_SURFACE_WARNING",
    "Options",
    "RESULT",
    "WatertightDiagnostics",
    "off_surface_fraction",
    "off_surface_fractions",
    "ClosedTemplate",
    "closed_template",
    "carry_frame",
    "free_offsets",
    "closed_frames",
    "lost_fraction",
    "reconstruct",
    "reconstruct_with_diagnostics",
    "close_animation",
    "Closing",
    "estimate_peak_bytes",
    "LOST_WARNING",
    "close_on_flow",
    "rigid_blend",
]


@dataclasses.dataclass(frozen=True)
class Options(flow.Options):
    pass


Options.__doc__ = (
    "Options of the watertight method: those of the ``flow`` method, whose surfaces close\n"
    "    the kinematic result (run with its defaults).\n"
    + flow.Options.__doc__.split("\n", 1)[1].split("    cache_dir : ")[0]
    + """    cache_dir : str or None
        Folder where the finished stages are kept: the ``kinematic`` run's in its subfolder
        ``kinematic``, the ``flow`` run's in ``flow`` (see those methods' ``cache_dir``); a
        rerun after an interruption resumes after the last one (``fourd reconstruct
        --cache``). None: nothing is kept.
    """
)


@dataclasses.dataclass(frozen=True)
class WatertightDiagnostics:
    """The composition's own figures.

    Attributes
    ----------
    mass_conservation_error : float
        The flow's (a fraction, :func:`fourd.methods.flow.mass_conservation_error`).
    off_surface : float
        The largest fraction over the frames of the template's vertices far from both the
        flow's surface and the frame's points (:func:`off_surface_fractions`).
    lost : float
        The fraction of the tracked first frame the closed result lacks (:class:`Closing`).
    """

    mass_conservation_error: float
    off_surface: float
    lost: float


def flow_options(options: Options) -> flow.Options:
    """The ``flow`` options within ``options``."""
    return flow.Options(
        **{f.name: getattr(options, f.name) for f in dataclasses.fields(flow.Options)}
    )


def close_animation(
    opened: AnimatedMesh,
    field,
    *,
    bounds: np.ndarray,
    cell_size: float,
    target_vertices: int = 10000,
    reach: float = 0.0,
) -> AnimatedMesh:
    """An open animated mesh closed by a signed distance in space-time: a closed template of
    ``field`` at ``opened.times[0]`` whose vertices on the open mesh follow it exactly and
    whose other vertices (the parts no frame showed at the first time) follow the rigid
    motion of their nearest bound vertices (:func:`rigid_blend`), then move onto ``field``
    at each time by at most two template cells (where the field lags a fast thin part by
    more, the rigid motion is the better guess).

    Measured cause of the closed sliding's drift (``experiments/watertight_drift.py``,
    crane-130, correspondence mean / last frame): the closed template slid along the flow's
    surfaces 0.0209 / 0.0271; the open template slid along the same surfaces 0.0119 / 0.0195;
    the kinematic method 0.0116 / 0.0186. Neither the field, nor the frames' points, nor the
    projection of the smoothed frames (0.0208 / 0.0271 without it) is the cause: the closed
    template's filled parts (between the legs, under the arms) hold limbs together as
    rigidly as the skin. Here they are carried along instead.

    Parameters
    ----------
    opened : AnimatedMesh
        The open animation (one frame per time of ``field``); its frame 0 is the surface the
        template's vertices are bound to.
    field : Field4D
        Signed distance, negative inside, at ``opened.times`` (closed surfaces).
    bounds : ndarray [2, 3]
        Box holding the closed surface at the first time.
    cell_size : float
        Marching-cubes cell of the closed template (input units).
    target_vertices : int
        About this many template vertices (:func:`~fourd.methods.kinematic.extract_template`).
    reach : float
        A template vertex within this distance of the open mesh (input units; at least
        :data:`BIND_EDGES` of its median edges), facing the same way, is bound to it:
        :func:`close_on_flow` takes half a flow cell, the offset of a coarse flow's surface
        from the data.

    Returns
    -------
    AnimatedMesh with the closed template as ``rest``; ``observed`` is the open mesh's, by
    the nearest bound corner, and False for the vertices carried along.
    """
    times = np.asarray(opened.times, dtype=float)
    template = closed_template(
        opened.vertices[0], opened.faces, field, float(times[0]), bounds=bounds,
        cell_size=cell_size, target_vertices=target_vertices, reach=reach,
    )
    frames = (
        (opened.vertices[k], opened.observed[k], field, float(t), None)
        for k, t in enumerate(times)
    )
    out = np.empty((len(times), len(template.rest), 3))
    observed = np.zeros((len(times), len(template.rest)), dtype=bool)
    for k, (vertices, seen, _) in enumerate(closed_frames(template, frames, len(times))):
        out[k], observed[k] = vertices, seen
    return AnimatedMesh(
        faces=template.faces, vertices=out, times=times, observed=observed, rest=template.rest
    )


class ClosedTemplate(NamedTuple):
    """A closed template bound to an open animation's first frame (:func:`closed_template`).

    rest : [N, 3], faces : [F, 3]: the template, its bound vertices on the open mesh.
    bound : int [B], the vertices bound to the open mesh; corners : int [B, 3], the open
        mesh's vertices of the triangle each lies on; barycentric : [B, 3], where on it.
    free : int [M], the vertices carried along; near : int [M, K], their nearest bound
        vertices (indices into ``bound``); weights : [M, K], those vertices' weights (None
        without three bound vertices).
    cell_size : float, the template's marching-cubes cell (the projections' step bound).
    """

    rest: np.ndarray
    faces: np.ndarray
    bound: np.ndarray
    corners: np.ndarray
    barycentric: np.ndarray
    free: np.ndarray
    near: np.ndarray | None
    weights: np.ndarray | None
    cell_size: float


def closed_template(
    first: np.ndarray,
    faces: np.ndarray,
    field,
    time: float,
    *,
    bounds: np.ndarray,
    cell_size: float,
    target_vertices: int = 10000,
    reach: float = 0.0,
) -> ClosedTemplate:
    """The closed template of :func:`close_animation`: ``field``'s surface at ``time``, its
    vertices within ``reach`` of the open mesh ``(first [V, 3], faces)`` and facing its way
    bound to it, the others given their nearest bound vertices. Parameters as
    :func:`close_animation`'s."""
    first = np.asarray(first, dtype=float)
    vertices, template_faces = kinematic.extract_template(
        field, float(time), bounds=np.asarray(bounds, float), cell_size=cell_size,
        min_component_faces=20, target_vertices=target_vertices,
    )
    mesh = trimesh.Trimesh(first, faces, process=False)
    closest, distance, triangle = trimesh.proximity.closest_point(mesh, vertices)
    normals = trimesh.Trimesh(vertices, template_faces, process=False).vertex_normals
    facing = np.einsum("ij,ij->i", normals, mesh.face_normals[triangle]) > 0.3
    is_bound = (distance < max(reach, BIND_EDGES * median_edge_length(first, faces))) & facing
    bound, free = np.flatnonzero(is_bound), np.flatnonzero(~is_bound)
    log.info(
        "watertight: closed template of %d vertices, %d (%.0f%%) carried along the open mesh's "
        "holes", len(vertices), len(free), 100 * len(free) / len(vertices),
    )
    corners = faces[triangle[bound]]
    barycentric = trimesh.triangles.points_to_barycentric(first[corners], closest[bound])
    rest = vertices.copy()
    rest[bound] = closest[bound]
    near = weights = None
    if len(free) and len(bound) >= 3:
        distance, near = cKDTree(rest[bound]).query(rest[free], k=min(RIGID_ANCHORS, len(bound)))
        near = near.reshape(len(free), -1)
        weights = 1.0 / (distance.reshape(len(free), -1) ** 2 + (1e-3 * cell_size) ** 2)
    return ClosedTemplate(
        rest, template_faces, bound, corners, barycentric, free, near, weights, float(cell_size)
    )


def carry_frame(
    template: ClosedTemplate, vertices: np.ndarray, observed: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The closed template at one frame of the open animation (its ``vertices`` [V, 3] and
    ``observed`` [V]): the bound vertices on the open mesh, the free ones moved rigidly with
    their nearest bound vertices (:func:`rigid_blend`), not yet on the field; ([N, 3], [N])
    with ``observed`` the open mesh's by the nearest bound corner, False where carried."""
    vertices = np.asarray(vertices, dtype=float)
    out = template.rest.copy()
    seen = np.zeros(len(out), dtype=bool)
    frame = np.einsum("ij,ijk->ik", template.barycentric, vertices[template.corners])
    out[template.bound] = frame
    seen[template.bound] = np.asarray(observed)[template.corners].any(axis=1)
    if template.near is not None:
        out[template.free] = rigid_blend(
            template.rest[template.bound][template.near], frame[template.near], template.weights,
            template.rest[template.free],
        )
    return out, seen


def closed_frames(
    template: ClosedTemplate, frames: Iterable, count: int
) -> Iterator[tuple[np.ndarray, np.ndarray, object]]:
    """The closed template at each of ``count`` frames, in order and one frame behind its
    input: ``frames`` gives (open vertices [V, 3], observed [V], field, time, payload) per
    frame, each carried (:func:`carry_frame`) and its free vertices moved onto ``field``
    (:func:`free_offsets`; a field of None moves none); yields (vertices [N, 3], observed
    [N], payload).

    The flow's surface moves by a fraction of a cell from frame to frame in the filled parts:
    the moves are smoothed over time by one [1, 2, 1] pass (the first and last frames, and a
    sequence of two, keep theirs), which keeps that from showing as flicker."""
    before = current = None  # frames k - 2 and k - 1, waiting for their neighbour in time
    for vertices, seen, field, at, payload in frames:
        carried, observed = carry_frame(template, vertices, seen)
        offsets = (
            free_offsets(template, carried, field, at) if field is not None
            else np.zeros((len(template.free), 3))
        )
        frame = (carried, observed, offsets, payload)
        if current is not None:
            yield _moved(template, current, before if count > 2 else None, frame)
        before, current = current, frame
    if current is not None:
        yield _moved(template, current, None, None)


def _moved(template: ClosedTemplate, frame, before, after):
    """``frame`` (carried, observed, offsets, payload) with its free vertices moved by its
    offsets, smoothed with its neighbours' when it has both."""
    carried, observed, offsets, payload = frame
    if before is not None and after is not None:
        offsets = 0.25 * before[2] + 0.5 * offsets + 0.25 * after[2]
    carried = carried.copy()
    carried[template.free] += offsets
    return carried, observed, payload


def lost_fraction(rest: np.ndarray, first: np.ndarray, faces: np.ndarray) -> float:
    """The fraction of the open mesh's first-frame vertices (``first`` [V, 3], ``faces``)
    farther than two of its median edges from the closed template ``rest`` [N, 3]: parts the
    flow does not have (:class:`Closing` ``lost``)."""
    edge = median_edge_length(first, faces)
    distance, _ = cKDTree(rest).query(first, distance_upper_bound=2.0 * edge, workers=-1)
    return float(np.mean(~np.isfinite(distance)))


def free_offsets(template: ClosedTemplate, vertices: np.ndarray, field, time: float) -> np.ndarray:
    """How far the free vertices of a carried frame (:func:`carry_frame`) move onto ``field``
    at ``time``: at most two template cells (four Newton steps of half a cell); [M, 3]."""
    free = np.asarray(vertices, dtype=float)[template.free]
    if len(free) == 0:
        return np.zeros((0, 3))
    return kinematic.project_to_surface(
        field, free, float(time), iterations=4, max_step=0.5 * template.cell_size
    ) - free


def rigid_blend(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray, points: np.ndarray
) -> np.ndarray:
    """Moving least squares rigid deformation (Schaefer, McPhail, Warren 2006): each point
    [M, 3] moves by the rigid motion that best maps its anchors ``source`` [M, K, 3] onto
    ``target`` [M, K, 3] with ``weights`` [M, K] (weighted Kabsch, reflections excluded).
    A rigid motion of all anchors moves every point by exactly that motion.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> source = rng.normal(size=(1, 6, 3))
    >>> turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    >>> moved = rigid_blend(source, source @ turn.T + 1.0, np.ones((1, 6)), np.zeros((1, 3)))
    >>> np.allclose(moved, [[1.0, 1.0, 1.0]])
    True
    """
    w = weights / weights.sum(axis=1, keepdims=True)
    source_centre = np.einsum("mk,mki->mi", w, source)
    target_centre = np.einsum("mk,mki->mi", w, target)
    covariance = np.einsum(
        "mk,mki,mkj->mij", w, source - source_centre[:, None], target - target_centre[:, None]
    )
    u, _, vt = np.linalg.svd(covariance)
    flip = np.sign(np.linalg.det(np.einsum("mji,mkj->mik", vt, u)))
    vt[:, 2, :] *= flip[:, None]
    rotation = np.einsum("mji,mkj->mik", vt, u)
    return np.einsum("mij,mj->mi", rotation, points - source_centre) + target_centre


def off_surface_fractions(
    animation: AnimatedMesh, field, distance: float, points: list | None = None
) -> np.ndarray:
    """Per frame of ``animation``, the fraction of its vertices where ``|field|`` (a signed
    distance at the animation's times) exceeds ``distance`` (input units) and, where
    ``points`` gives the frame points ([P, 3] or None, one per frame), no point lies within
    ``distance``; [T] (:func:`off_surface_fraction` per frame)."""
    return np.array([
        off_surface_fraction(v, field, float(t), distance, None if points is None else points[k])
        for k, (v, t) in enumerate(zip(animation.vertices, animation.times, strict=True))
    ])


def off_surface_fraction(
    vertices: np.ndarray, field, time: float, distance: float, points: np.ndarray | None = None
) -> float:
    """The fraction of ``vertices`` [N, 3] where ``|field|`` at ``time`` exceeds ``distance``
    and no one of ``points`` ([P, 3] or None) lies within ``distance``."""
    vertices = np.asarray(vertices, dtype=float)
    off = np.abs(field.value(vertices, time)) > distance
    if points is not None and len(points) and off.any():
        near, _ = cKDTree(points).query(vertices[off], distance_upper_bound=distance, workers=-1)
        off[np.flatnonzero(off)[np.isfinite(near)]] = False
    return float(off.mean())


class Closing(NamedTuple):
    """What :func:`close_on_flow` made.

    animation : AnimatedMesh, the closed result.
    off_surface : float, the largest fraction over the frames of its vertices far from both
        the flow's surface and the frame's points (:func:`off_surface_fractions`).
    lost : float, the fraction of the open result's first-frame vertices farther than two of
        its median edges from the closed template: parts the flow does not have (a thin,
        fast limb it lags), which the closed result lacks.
    """

    animation: AnimatedMesh
    off_surface: float
    lost: float


def close_on_flow(
    seq: PointCloudSequence,
    opened: AnimatedMesh,
    flowed: flow.FlowResult,
) -> Closing:
    """``opened`` (the kinematic result on ``seq``) closed by the surfaces of a ``flow`` run
    on ``seq`` (:func:`close_animation`), with the figures that say whether it is sound
    (:class:`Closing`; warned above :data:`OFF_SURFACE_WARNING` and :data:`LOST_WARNING`)."""
    clock = time.perf_counter()
    field = flow.surface_distance(flowed)
    first = next(i for i, p in enumerate(flowed.frame_points) if p is not None and len(p) >= 4)
    points = flowed.frame_points[first]
    spacing = point_spacing(points)
    cell = kinematic.template_cell_size(points, spacing, kinematic.Options().template_vertices)
    animation = close_animation(
        opened, field, bounds=field.bounds(), cell_size=cell, reach=0.5 * flowed.grid.h
    )
    off_surface = off_surface_fractions(
        animation, field, OFF_SURFACE_CELLS * field.spacing, flowed.frame_points
    )
    lost = np.flatnonzero(off_surface > OFF_SURFACE_WARNING)
    if len(lost):
        log.warning(
            "watertight: in %d of %d frames (first %d) more than %.1f%% of the closed mesh "
            "lies far from both the flow's surface and the frame's points (at most %.1f%%, "
            "frame %d): the tracking lost part of it; the plain flow meshes (method flow) are "
            "sound", len(lost), len(off_surface), lost[0], 100 * OFF_SURFACE_WARNING,
            100 * off_surface.max(), int(off_surface.argmax()),
        )
    lost = lost_fraction(animation.rest, np.asarray(opened.vertices[0]), opened.faces)
    if lost > LOST_WARNING:
        log.warning(
            "watertight: the flow's surface lacks %.1f%% of the tracked first frame (a thin "
            "or fast part it lags), and so does the closed result; the kinematic method keeps "
            "it", 100 * lost,
        )
    log.info("watertight: closing %.1f s", time.perf_counter() - clock)
    return Closing(animation, float(off_surface.max()), lost)


def estimate_peak_bytes(seq: PointCloudSequence, options: Options | None = None) -> int:
    """Estimated peak memory (bytes): the flow's (:func:`fourd.methods.flow.estimate_peak_bytes`),
    which dominates; the kinematic sliding's is a fraction of it."""
    options = Options() if options is None else options
    return flow.estimate_peak_bytes(seq, flow_options(options))


def reconstruct_with_diagnostics(
    seq: PointCloudSequence, options: Options | None = None
) -> Reconstruction:
    """:func:`reconstruct` and :class:`WatertightDiagnostics`."""
    options = Options() if options is None else options
    if options.window:
        return _windowed(seq, options)
    opened = kinematic.reconstruct(
        seq, kinematic.Options(cache_dir=subfolder(options.cache_dir, "kinematic"))
    )
    flowed = flow.run(
        seq,
        dataclasses.replace(
            flow_options(options), cache_dir=subfolder(options.cache_dir, "flow")
        ),
    )
    closing = close_on_flow(seq, opened, flowed)
    return Reconstruction(
        closing.animation,
        WatertightDiagnostics(float(flowed.mass_error), closing.off_surface, closing.lost),
    )


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """One closed, manifold animated mesh: the flow's surfaces, the kinematic sliding's
    correspondences (see the module docstring)."""
    return reconstruct_with_diagnostics(seq, options).result


def _windowed(seq: PointCloudSequence, options: Options) -> Reconstruction:
    """``options.window`` set: the streamed run (:mod:`fourd.methods.watertight.stream`) over
    ``seq``, its result read back."""
    from fourd.methods.watertight.stream import reconstruct_streamed

    return streamed_in_memory(reconstruct_streamed, seq, options, "watertight")
