"""Method ``watertight``: one closed animated mesh, by composition of two methods.

The ``flow`` method's closed, manifold frames (Sharf et al. 2008, ``002_382acf333feb7a6e.txt``)
give a signed distance in space-time (:func:`fourd.methods.flow.surface_distance`); a closed
template of the first frame with data is slid along it with the ``kinematic`` method's
:func:`~fourd.methods.kinematic.animate` (Süßmuth et al. 2008, ``000_00387fefe94cc850.txt``,
section 5), whose data term follows each frame's own points where it has them. The flow
fills what the frames do not see. Neither paper gives watertight frames with
correspondences; this composition does.

Until this module existed the composition was the ``flow`` option ``coherent=true``; the
registry still accepts that spelling (:data:`fourd.methods.ALIASES`).
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.geometry.neighbors import point_spacing
from fourd.methods import flow, kinematic
from fourd.methods.base import Reconstruction
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.watertight")

MIN_FRAMES = flow.MIN_FRAMES
RESULT = AnimatedMesh

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

__all__ = [
    "MIN_FRAMES",
    "OFF_SURFACE_CELLS",
    "OFF_SURFACE_WARNING",
    "Options",
    "RESULT",
    "WatertightDiagnostics",
    "off_surface_fractions",
    "reconstruct",
    "reconstruct_with_diagnostics",
    "slide_closed_template",
]


@dataclasses.dataclass(frozen=True)
class Options(flow.Options):
    pass


Options.__doc__ = (
    "Options of the watertight method: those of the ``flow`` method, whose field the closed\n"
    "    template slides along (the sliding takes the ``kinematic`` method's defaults).\n"
    + flow.Options.__doc__.split("\n", 1)[1]
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
    """

    mass_conservation_error: float
    off_surface: float


def flow_options(options: Options) -> flow.Options:
    """The ``flow`` options within ``options``."""
    return flow.Options(
        **{f.name: getattr(options, f.name) for f in dataclasses.fields(flow.Options)}
    )


def slide_closed_template(
    field, seq: PointCloudSequence, frame_points: list, frame_normals: list
) -> AnimatedMesh:
    """Slide a closed template of the first frame with data along ``field``, a signed
    distance in space-time (:func:`fourd.methods.flow.surface_distance`).

    The kinematic method's :func:`~fourd.methods.kinematic.animate` with the urshape
    polygonised everywhere in the grid (so closed), its data term (each frame's own points,
    with the large-motion registration) and the smoothed frames projected back where the
    filter cut the corners of fast curved trajectories. ``field`` fills what the frames do
    not see. Frames before the first with data are reached by sliding backwards.

    Parameters
    ----------
    field : Field4D, negative inside, at the times of ``seq``.
    frame_points, frame_normals : lists of T arrays [P, 3] or None (a frame without data).
    """
    if all(n is None for n in frame_normals):
        raise InputError("watertight: no frame has data to build a template from")
    first = next(i for i, n in enumerate(frame_normals) if n is not None)
    empty = np.zeros((0, 3))
    points = [empty if n is None else p for p, n in zip(frame_points, frame_normals, strict=True)]
    normals = [empty if n is None else n for n in frame_normals]
    times = np.asarray(seq.times, dtype=float)
    return kinematic.animate(
        field,
        points[first:],
        normals[first:],
        times[first:],
        spacing=point_spacing(points[first]),
        options=kinematic.Options(times=tuple(times) if first else ()),
        closed=True,
        bounds=field.bounds(),
        project_smoothed=True,
    )


def off_surface_fractions(
    animation: AnimatedMesh, field, distance: float, points: list | None = None
) -> np.ndarray:
    """Per frame of ``animation``, the fraction of its vertices where ``|field|`` (a signed
    distance at the animation's times) exceeds ``distance`` (input units) and, where
    ``points`` gives the frame points ([P, 3] or None, one per frame), no point lies within
    ``distance``; [T]."""
    vertices = np.asarray(animation.vertices)
    times = np.asarray(animation.times, dtype=float)
    fractions = np.empty(len(vertices))
    for k, (v, t) in enumerate(zip(vertices, times, strict=True)):
        off = np.abs(field.value(v, t)) > distance
        frame = None if points is None else points[k]
        if frame is not None and len(frame) and off.any():
            near, _ = cKDTree(frame).query(v[off], distance_upper_bound=distance, workers=-1)
            off[np.flatnonzero(off)[np.isfinite(near)]] = False
        fractions[k] = off.mean()
    return fractions


def reconstruct_with_diagnostics(
    seq: PointCloudSequence, options: Options | None = None
) -> Reconstruction:
    """:func:`reconstruct` and :class:`WatertightDiagnostics`."""
    options = Options() if options is None else options
    flowed = flow.run(seq, flow_options(options))
    clock = time.perf_counter()
    field = flow.surface_distance(flowed)
    animation = slide_closed_template(field, seq, flowed.frame_points, flowed.frame_normals)
    off_surface = off_surface_fractions(
        animation, field, OFF_SURFACE_CELLS * field.spacing, flowed.frame_points
    )
    lost = np.flatnonzero(off_surface > OFF_SURFACE_WARNING)
    if len(lost):
        log.warning(
            "watertight: in %d of %d frames (first %d) more than %.1f%% of the template lies "
            "far from both the flow's surface and the frame's points (at most %.1f%%, frame "
            "%d): the sliding lost part of it; the plain flow meshes (method flow) are sound",
            len(lost), len(off_surface), lost[0], 100 * OFF_SURFACE_WARNING,
            100 * off_surface.max(), int(off_surface.argmax()),
        )
    log.info("watertight: sliding %.1f s", time.perf_counter() - clock)
    diagnostics = WatertightDiagnostics(float(flowed.mass_error), float(off_surface.max()))
    return Reconstruction(animation, diagnostics)


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """One closed, manifold animated mesh: the flow's surfaces, the kinematic sliding's
    correspondences (see the module docstring)."""
    return reconstruct_with_diagnostics(seq, options).result
