"""Method ``auto``, the default: one animated mesh, with the method chosen from the data.

The rule, in order:

1. The ``kinematic`` method (Süßmuth et al. 2008, ``000_00387fefe94cc850.txt``) runs first:
   its urshape is the first frame's surface where the frame has points, so its holes are
   the parts of the surface the first frame did not see.
2. **Open surface** (a sheet, a face, a one-sided scan): a closed surface has no vector area
   (``sum of n_f A_f`` over its faces is zero, by the divergence theorem), and holes add only
   their own projected area, while an open sheet's vector area is nearly its whole area. When
   the urshape's vector area exceeds ``open_area`` of its area, the data does not enclose a
   volume and the kinematic result is returned: closing it would invent a back side.
3. **Closed object**: the ``flow`` method (Sharf et al. 2008, ``002_382acf333feb7a6e.txt``)
   reconstructs closed, manifold frames. When the number of parts of those frames changes
   over the sequence (the shape **splits or merges**, :func:`splits`), one connectivity
   cannot follow it: a warning says so and the flow's per-frame meshes are returned (a
   :class:`~fourd.MeshSequence`, no correspondences). Otherwise the kinematic result is
   closed by the flow's surfaces (:func:`fourd.methods.watertight.close_on_flow`): one
   closed animated mesh whose observed vertices are the kinematic result's.
4. **A flow that lacks parts**: where the flow's surface misses more than ``lost_limit`` of
   the tracked first frame (it lags thin, fast parts), the closed result would miss them too,
   so the kinematic (open) result is returned.

5. **Fit to the frames**: the animated mesh's vertices are moved along their normals onto each
   frame's points (:func:`fourd.geometry.surface_fit.fit_along_normals`, a local quadric fit
   of the frame's points, smoothed over the mesh and in time): the tracking trades the data
   against rigidity and the filled-in parts come from the coarser flow, and moving along the
   normal removes that error without moving a vertex along the surface, so the
   correspondences stay. ``fit_frames`` turns it off.

``surface`` forces step 2's answer. The decision and its figures are logged at info level and
returned by :func:`reconstruct_with_diagnostics`.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Literal

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.cache import subfolder
from fourd.geometry.meshes import vertex_components
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.outliers import distance_ratio_inliers
from fourd.geometry.surface_fit import fit_along_normals
from fourd.methods import flow, kinematic, watertight
from fourd.methods.base import Reconstruction, streamed_in_memory
from fourd.methods.kinematic.options import OUTLIER_NEIGHBOURS
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.auto")

MIN_FRAMES = 2
#: An AnimatedMesh, or the flow's MeshSequence where the shape splits or merges (warned).
RESULT = (AnimatedMesh, MeshSequence)
#: The options users change first (``fourd options auto``; the others under ``--all``).
COMMON_OPTIONS = ("surface", "resolution", "fit_frames")
#: The option :func:`estimate_peak_bytes` grows with (the flow's grid).
MEMORY_OPTIONS = ("resolution",)

__all__ = [
    "COMMON_OPTIONS",
    "MIN_FRAMES",
    "AutoDiagnostics",
    "MEMORY_OPTIONS",
    "Options",
    "fit_points",
    "fit_scales",
    "fit_to_frames",
    "RESULT",
    "estimate_peak_bytes",
    "part_counts",
    "reconstruct",
    "reconstruct_with_diagnostics",
    "splits",
    "vector_area_fraction",
]


@dataclasses.dataclass(frozen=True)
class Options:
    """Options of the default method.

    Attributes
    ----------
    surface : str
        ``auto`` (default): decide from the data whether it is an open surface or a closed
        object (see the module docstring); ``open``: always the kinematic result; ``closed``:
        always the closed composition.
    open_area : float
        The data is an open surface when the vector area of the first frame's urshape
        (:func:`vector_area_fraction`) exceeds this fraction of its area (0.5; a closed
        surface has 0 and its holes add their projected area: 0.10-0.18 on the bench's
        closed objects, 0.94 on waving-sheet).
    resolution : int
        The flow grid for closed objects: cells along the longest side of the data's box
        (32).
    lost_limit : float
        For a closed object, the kinematic (open) result is returned instead of the closed
        one when the flow's surface lacks more than this fraction of the tracked first frame
        (0.02; a thin, fast limb the flow lags: horse-gallop's legs).
    split_part : float
        A part of a flow frame counts towards the split test when it holds at least this
        fraction of the frame's faces (0.05).
    fit_frames : bool
        Move the result's vertices along their normals onto each frame's points (step 5 of
        the module docstring; True).
    fit_radius : float
        Width of that fit's Gaussian weights along the surface, in point spacings of the
        first frame (2).
    fit_reach : float
        The fit ignores points farther than this from a vertex's tangent plane and moves no
        vertex farther, in point spacings (4).
    seed : int
        Seed of the kinematic method's sampling (0).
    window : int
        0 (default): the kinematic and flow stages each see the whole sequence at once. Set,
        the run goes window by window as ``fourd reconstruct --stream`` does
        (:func:`fourd.methods.auto.reconstruct_streamed`): both stages in windows of this many
        frames, the closing and the fit a chunk of frames at a time, so memory is bounded by
        the window (and the result); the kinematic stage tracks the input video's anchors
        and keeps its colour guide window by window then. ``--stream`` with 0 takes 20.
    cache_dir : str or None
        Folder where the finished stages are kept: the ``kinematic`` run's in its subfolder
        ``kinematic``, the ``flow`` run's in ``flow`` (see those methods' ``cache_dir``); a
        rerun after an interruption resumes after the last one (``fourd reconstruct
        --cache``). None: nothing is kept.
    """

    surface: Literal["auto", "open", "closed"] = "auto"
    open_area: float = 0.5
    resolution: int = 32
    lost_limit: float = 0.02
    split_part: float = 0.05
    fit_frames: bool = True
    fit_radius: float = 2.0
    fit_reach: float = 4.0
    seed: int = 0
    window: int = 0
    cache_dir: str | None = None

    def __post_init__(self):
        if self.surface not in ("auto", "open", "closed"):
            raise ValueError(f"surface must be auto, open or closed, got {self.surface!r}")
        if not 0 < self.open_area <= 1:
            raise ValueError(f"open_area must be in (0, 1], got {self.open_area}")
        if not 0 < self.split_part < 1:
            raise ValueError(f"split_part must be between 0 and 1, got {self.split_part}")
        if self.window < 0 or self.window == 1:
            raise ValueError(f"window must be 0 or at least 2 frames, got {self.window}")
        if self.fit_radius <= 0 or self.fit_reach <= 0:
            raise ValueError(
                f"fit_radius and fit_reach must be positive, got {self.fit_radius}, {self.fit_reach}"
            )


@dataclasses.dataclass(frozen=True)
class AutoDiagnostics:
    """What the default method decided, and on which figures.

    Attributes
    ----------
    open_surface : float
        1 when the kinematic (open) result was returned (an open surface, or a flow that
        lacks tracked parts), else 0.
    vector_area : float
        :func:`vector_area_fraction` of the first frame's urshape.
    split : float
        1 when the flow's frames change their number of parts (the flow's meshes returned).
    mass_conservation_error : float or None
        The flow's, where it ran.
    off_surface, lost : float or None
        The closed composition's :class:`~fourd.methods.watertight.Closing` figures, where
        it ran.
    """

    open_surface: float
    vector_area: float
    split: float
    mass_conservation_error: float | None = None
    off_surface: float | None = None
    lost: float | None = None


def vector_area_fraction(vertices: np.ndarray, faces: np.ndarray) -> float:
    """``|sum_f n_f A_f| / sum_f A_f`` of a triangle mesh, in [0, 1]: 0 for a closed surface
    (divergence theorem), the sum of its holes' projected areas over its area for a surface
    with holes, 1 for a flat open sheet.

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    >>> vector_area_fraction(square, np.array([[0, 1, 2], [0, 2, 3]]))
    1.0
    >>> tetrahedron = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> round(vector_area_fraction(tetrahedron, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])), 12)
    0.0
    """
    a, b, c = (np.asarray(vertices, float)[faces[:, k]] for k in range(3))
    cross = 0.5 * np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1).sum()
    return float(np.linalg.norm(cross.sum(axis=0)) / area) if area > 0 else 0.0


def part_counts(meshes: MeshSequence, smallest: float) -> np.ndarray:
    """Per frame, the connected parts holding at least ``smallest`` of its faces; [T]."""
    counts = []
    for vertices, faces in meshes.meshes:
        if len(faces) == 0:
            counts.append(0)
            continue
        _, labels = vertex_components(faces, len(vertices))
        sizes = np.bincount(labels[faces[:, 0]])
        counts.append(int((sizes >= smallest * len(faces)).sum()))
    return np.array(counts)


def splits(parts: np.ndarray) -> bool:
    """Whether per-frame part counts [T] (:func:`part_counts`) say the shape splits or
    merges: the most frequent count of the first quarter of the frames (at least three)
    differs from that of the last quarter. A part the flow pinches off for a frame or three
    (a thin, fast leg: horse-gallop's counts flicker between 1 and 2) is no split.

    Examples
    --------
    >>> splits(np.array([1] * 11 + [2] * 9)), splits(np.array([2, 1, 1, 1, 2, 2, 1, 1, 2, 1, 1, 1]))
    (True, False)
    """
    parts = np.asarray(parts)
    present = parts[parts > 0]
    if len(present) < 4:
        return False
    quarter = max(3, len(present) // 4)
    first, last = (np.bincount(part).argmax() for part in (present[:quarter], present[-quarter:]))
    return bool(first != last)


def fit_to_frames(seq: PointCloudSequence, animation: AnimatedMesh, options: Options) -> AnimatedMesh:
    """Step 5 of the module docstring: ``animation`` with every frame's vertices moved along
    their normals onto that frame's points (outliers removed as ``kinematic`` removes them).
    Needs one mesh frame per input frame; otherwise (other output ``times``) it is returned
    as it is."""
    if not options.fit_frames or len(animation.vertices) != len(seq.frames):
        return animation
    frames = fit_points([frame.points for frame in seq.frames])
    radius, reach = fit_scales(frames[0], options)
    fit = fit_along_normals(animation.vertices, animation.faces, frames, radius=radius, reach=reach)
    log.info(
        "auto: fitted to the frames along the normals (median |offset| %.2g, %.0f%% of the "
        "vertices near points)", float(np.median(np.abs(fit.offsets))), 100 * fit.supported.mean(),
    )
    return dataclasses.replace(animation, vertices=fit.vertices)


def fit_points(frames: list[np.ndarray]) -> list[np.ndarray]:
    """The points [P, 3] of each frame that step 5 fits to: without the outliers
    ``kinematic``'s frame preparation removes (its test and its threshold)."""
    factor, k = kinematic.Options().outlier_factor, OUTLIER_NEIGHBOURS
    return [
        points[distance_ratio_inliers(points, k=k, factor=factor)] if len(points) > k + 1 else points
        for points in frames
    ]


def fit_scales(first: np.ndarray, options: Options) -> tuple[float, float]:
    """Step 5's radius and reach (input units): ``fit_radius`` and ``fit_reach`` point
    spacings of the first frame's points ``first`` [P, 3] (:func:`fit_points`)."""
    spacing = point_spacing(first)
    return options.fit_radius * spacing, options.fit_reach * spacing


def estimate_peak_bytes(seq: PointCloudSequence, options: Options | None = None) -> int:
    """Estimated peak memory (bytes): the flow's at ``resolution``
    (:func:`fourd.methods.flow.estimate_peak_bytes`) when the data may be a closed object;
    0 with ``surface="open"`` (the kinematic method alone, whose memory is not estimated)."""
    options = Options() if options is None else options
    if options.surface == "open":
        return 0
    return flow.estimate_peak_bytes(
        seq, flow.Options(resolution=options.resolution, window=options.window)
    )


def reconstruct_with_diagnostics(
    seq: PointCloudSequence, options: Options | None = None
) -> Reconstruction:
    """:func:`reconstruct` and :class:`AutoDiagnostics`."""
    options = Options() if options is None else options
    if options.window:
        return _windowed(seq, options)
    opened = kinematic.reconstruct(
        seq,
        kinematic.Options(
            seed=options.seed, cache_dir=subfolder(options.cache_dir, "kinematic")
        ),
    )
    openness = vector_area_fraction(opened.rest, opened.faces)
    is_open = options.surface == "open" or (
        options.surface == "auto" and openness > options.open_area
    )
    if is_open:
        log.info(
            "auto: an open surface (the first frame's vector area is %.2f of its area, over "
            "%.2f): the kinematic result", openness, options.open_area,
        )
        return Reconstruction(fit_to_frames(seq, opened, options), AutoDiagnostics(1.0, openness, 0.0))
    flowed = flow.run(
        seq,
        flow.Options(
            resolution=options.resolution, cache_dir=subfolder(options.cache_dir, "flow")
        ),
    )
    parts = part_counts(flowed.meshes, options.split_part)
    if splits(parts):
        log.warning(
            "auto: the shape splits or merges (parts per frame %s): one connectivity cannot "
            "follow it, so the result is the flow's closed meshes, one per frame, without "
            "correspondences", " ".join(map(str, parts)),
        )
        return Reconstruction(
            flowed.meshes, AutoDiagnostics(0.0, openness, 1.0, float(flowed.mass_error))
        )
    closing = watertight.close_on_flow(seq, opened, flowed)
    if closing.lost > options.lost_limit:
        log.warning(
            "auto: the flow's surface lacks %.1f%% of the tracked first frame (over %.1f%%; a "
            "thin, fast part it lags), so the result is the kinematic one, open where no frame "
            "saw (method watertight closes it anyway)", 100 * closing.lost,
            100 * options.lost_limit,
        )
        return Reconstruction(
            fit_to_frames(seq, opened, options),
            AutoDiagnostics(1.0, openness, 0.0, float(flowed.mass_error), None, closing.lost),
        )
    log.info(
        "auto: a closed object (vector area %.2f of the area): the kinematic result closed "
        "by the flow's surfaces", openness,
    )
    return Reconstruction(
        fit_to_frames(seq, closing.animation, options),
        AutoDiagnostics(
            0.0, openness, 0.0, float(flowed.mass_error), closing.off_surface, closing.lost
        ),
    )


def reconstruct(
    seq: PointCloudSequence, options: Options | None = None
) -> AnimatedMesh | MeshSequence:
    """One animated mesh from ``seq`` by the rule of the module docstring."""
    return reconstruct_with_diagnostics(seq, options).result


def _windowed(seq: PointCloudSequence, options: Options) -> Reconstruction:
    """``options.window`` set: the streamed run (:mod:`fourd.methods.auto.stream`) over
    ``seq``, its result read back."""
    from fourd.methods.auto.stream import reconstruct_streamed

    return streamed_in_memory(reconstruct_streamed, seq, options, "auto")
