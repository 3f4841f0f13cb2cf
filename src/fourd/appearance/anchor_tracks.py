"""Sparse 3D anchor tracks between consecutive frames from multi-view optical flow.

Popa's thesis (004_f87f5acf96d50b57.txt), section 5.4.1 "Optical Flow Tracking": the points of
frame ``t`` are projected into every camera that sees them, slid to frame ``t + 1`` along that
camera's 2D optical flow, and lifted back onto the geometry of frame ``t + 1``; only reliable
matches are kept, by two levels of pruning, so the anchors are few but trustworthy (the thesis
keeps about 3 % of the vertices). Here, per consecutive pair ``(t, t + 1)`` and camera ``c``:

0. **Outliers.** Each frame's stray points (statistical outlier removal and small isolated
   clusters, :func:`fourd.geometry.outliers.remove_outliers`) are set aside: they are neither
   sources nor lifted onto, and they hide nothing.
1. **Sources.** The points of frame ``t`` that camera ``c`` sees: z-buffered into its image
   (:func:`fourd.appearance.depth.frame_view`), a point is seen when at most ``tolerance``
   behind the nearest depth at its pixel.
2. **Flow.** Dense flow forward (image ``t`` to ``t + 1``) and backward
   (:func:`fourd.appearance.flow.optical_flow`, OpenCV's DIS by default).
3. **2D pruning** (thesis: "every point is slided forward and then backward in time ... all
   points that do not map back within one pixel are discarded"): the forward-backward error
   must be at most ``forward_backward`` pixels (default 1). Flow that is wrong the same way
   both ways passes that test; so, beyond the thesis, the colour at the moved pixel must match
   the colour at the start within ``photometric`` (largest channel difference, fraction of
   full scale; shading changes as a patch turns, so this is loose).
4. **Lifting.** The moved pixel is lifted onto frame ``t + 1``'s points seen by that camera
   (:func:`fourd.appearance.depth.lift`: the pixel's ray cut with a plane fitted to the
   nearest seen points in the image; refused at holes, depth edges and grazing angles).
5. **3D pruning** (thesis: "each vertex is slided forward and then backward using the optical
   flow information and camera calibration ... all vertices that do not map within an epsilon
   distance from their original position are pruned"): the returned pixel, lifted onto
   frame ``t``'s points, must lie within ``tolerance`` of the source point.
6. **Agreement between cameras.** A point tracked by several cameras keeps the tracks whose
   targets lie within ``tolerance`` of another camera's target; when none agree the point is
   dropped. The anchor's target is the mean of the agreeing targets, weighted by reliability.

Confidence: each surviving track is taken to be right with probability
``r = (1 - e / (2 epsilon)) / 2`` (``e`` its forward-backward error, ``epsilon`` the
threshold; so 1/4 to 1/2), and the cameras as independent witnesses: ``confidence = 1 -
prod(1 - r)`` over the agreeing tracks (one perfect view: 0.5; two: 0.75; three: 0.875). It
orders anchors; it is not a calibrated probability.

Units: points in input units, pixels as in :mod:`fourd.appearance.cameras`. ``tolerance``
defaults to three times frame ``t``'s point spacing (:func:`surface_spacing`; from the data,
not a constant).

Examples
--------
>>> import fourd
>>> truth = fourd.synth.scene("rigid-turn", frames=2, angle=6.0)
>>> scans = fourd.synth.scan(truth, appearance="cloth", video=True, resolution=80, outliers=0)
>>> result = anchors(scans)
>>> len(result), result[0].source.shape[1], bool(len(result[0].source) > 100)
(1, 3, True)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from fourd.appearance.cameras import project
from fourd.appearance.depth import FrameView, frame_view, lift
from fourd.appearance.flow import (
    DIS_PRESETS,
    FLOW_METHODS,
    forward_backward,
    optical_flow,
    sample_flow,
    sample_image,
)
from fourd.appearance.texture import texture_significance
from fourd.errors import InputError
from fourd.geometry.grid import one_per_cube
from fourd.progress import progress

logger = logging.getLogger("fourd.appearance.anchor_tracks")

#: Stages counted in :attr:`AnchorPair.counts` (tracks summed over cameras, then anchors).
STAGES = ("seen", "forward_backward", "photometric", "lifted", "round_trip", "agreed", "anchors")


@dataclass(frozen=True)
class AnchorOptions:
    """Settings of :func:`anchors`.

    Attributes
    ----------
    flow : {"dis", "farneback"}
        Optical flow method (OpenCV).
    preset : {"ultrafast", "fast", "medium"}
        DIS preset.
    forward_backward : float
        Largest forward-backward error kept, pixels (thesis 5.4.1: one pixel); ``inf`` turns
        the 2D check off.
    photometric : float
        Largest colour change along a track (largest RGB channel difference, fraction of full
        scale, bilinear samples); ``inf`` turns the check off.
    tolerance : float or None
        3D tolerance, input units: how far a point may lie behind the depth map and still be
        seen, the largest depth step lifted across, the 3D round-trip distance and the
        agreement distance between cameras. None: ``tolerance_spacings`` times frame ``t``'s
        point spacing (:func:`surface_spacing`).
    tolerance_spacings : float
        The default tolerance in point spacings.
    min_cameras : int
        Anchors need this many agreeing cameras (1 keeps points only one camera tracked;
        their confidence is lower).
    splat_radius : float or None
        Radius of a point in the z-buffers that decide visibility, pixels; None: the point
        spacing in pixels at the median depth, at least 1 (lifting reaches 2.5 times as far).
    neighbours : int
        Points the lifting plane is fitted to.
    thin : float
        Keep at most one anchor (the most confident) per cube of ``thin`` point spacings
        (0: keep all).
    remove_outliers : bool
        Set each frame's outliers aside first (step 0).
    texture : float
        Keep only tracks that start where the image has hue texture: the chromaticity's
        structure tensor at least this many times what the noise alone gives it
        (:func:`~fourd.appearance.texture.texture_significance`, window ``texture_window``
        pixels); 0 keeps every track. Flow elsewhere follows the shading, which stays with the
        lamps while the surface turns.
    texture_window : float
        Gaussian window of that structure tensor, pixels.
    sources : float
        Track from at most one point per cube of ``sources`` point spacings (0: from every
        point): fewer tracks to lift when the anchors are denser than their user needs.
    """

    flow: str = "dis"
    preset: str = "medium"
    forward_backward: float = 1.0
    photometric: float = 0.12
    tolerance: float | None = None
    tolerance_spacings: float = 3.0
    min_cameras: int = 1
    splat_radius: float | None = None
    neighbours: int = 8
    thin: float = 0.0
    remove_outliers: bool = True
    texture: float = 0.0
    texture_window: float = 2.0
    sources: float = 0.0

    def __post_init__(self):
        if self.flow not in FLOW_METHODS:
            raise InputError(f"flow must be one of {', '.join(FLOW_METHODS)}, got {self.flow!r}")
        if self.preset not in DIS_PRESETS:
            raise InputError(f"preset must be one of {', '.join(DIS_PRESETS)}, got {self.preset!r}")
        if not self.forward_backward > 0:
            raise InputError(f"forward_backward must be > 0 pixels, got {self.forward_backward!r}")
        if not self.photometric > 0:
            raise InputError(f"photometric must be > 0, got {self.photometric!r}")
        if self.tolerance is not None and not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise InputError(f"tolerance must be finite and > 0, got {self.tolerance!r}")
        if not (np.isfinite(self.tolerance_spacings) and self.tolerance_spacings > 0):
            raise InputError(f"tolerance_spacings must be > 0, got {self.tolerance_spacings!r}")
        if int(self.min_cameras) != self.min_cameras or self.min_cameras < 1:
            raise InputError(f"min_cameras must be a positive integer, got {self.min_cameras!r}")
        object.__setattr__(self, "min_cameras", int(self.min_cameras))
        if self.splat_radius is not None and not (0 <= self.splat_radius <= 32):
            raise InputError(f"splat_radius must be in [0, 32] pixels, got {self.splat_radius!r}")
        if int(self.neighbours) != self.neighbours or self.neighbours < 3:
            raise InputError(f"neighbours must be an integer >= 3, got {self.neighbours!r}")
        object.__setattr__(self, "neighbours", int(self.neighbours))
        if not (np.isfinite(self.thin) and self.thin >= 0):
            raise InputError(f"thin must be >= 0, got {self.thin!r}")


class AnchorPair(NamedTuple):
    """The anchors from frame ``first`` to frame ``second = first + 1``.

    Attributes
    ----------
    first, second : int
        Frame indices in the sequence.
    source : ndarray float64 [M, 3]
        Points of frame ``first`` (input units).
    target : ndarray float64 [M, 3]
        Where each is in frame ``second`` (input units; on frame ``second``'s surface as its
        points give it, not necessarily one of them).
    confidence : ndarray float64 [M]
        In (0, 1), see the module docstring.
    views : ndarray int64 [M]
        Number of cameras whose tracks agreed.
    index : ndarray int64 [M]
        Index of each source into frame ``first``'s points.
    counts : dict
        Tracks left after each stage (:data:`STAGES`, summed over cameras) and the anchors.
    tolerance : float
        The 3D tolerance used (input units).
    """

    first: int
    second: int
    source: np.ndarray
    target: np.ndarray
    confidence: np.ndarray
    views: np.ndarray
    index: np.ndarray
    counts: dict
    tolerance: float


@dataclass(frozen=True, eq=False)
class Anchors:
    """Anchor tracks of a sequence: ``pairs[i]`` links frame ``i`` to frame ``i + 1``.

    ``len(anchors)`` is the number of pairs (frames - 1); ``anchors[i]`` is an
    :class:`AnchorPair`.
    """

    pairs: tuple[AnchorPair, ...]

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, index) -> AnchorPair:
        return self.pairs[index]

    def __iter__(self):
        return iter(self.pairs)

    @property
    def total(self) -> int:
        """Anchors over all pairs."""
        return int(sum(len(p.source) for p in self.pairs))


def anchor_options(options: AnchorOptions | None = None, **overrides) -> AnchorOptions:
    """An :class:`AnchorOptions` from an options object and/or keyword overrides."""
    from fourd.options import with_overrides

    return with_overrides(AnchorOptions, options, what="anchor", **overrides)


def pixel_spacing(camera, points, spacing: float) -> float:
    """The point spacing in pixels at the points' median depth (at least 1)."""
    _, z = project(camera, points)
    z = z[z > 0]
    if not len(z):
        return 1.0
    pixels = spacing * 0.5 * (camera.K[0, 0] + camera.K[1, 1]) / float(np.median(z))
    return float(np.clip(pixels, 1.0, 8.0))


class _CameraFrame(NamedTuple):
    image: np.ndarray
    view: FrameView


def surface_spacing(points, *, k: int = 8) -> float:
    """The sampling distance of a scanned surface: ``r_k sqrt(pi / k)`` with ``r_k`` the
    median distance to the ``k``-th nearest neighbour (for ``rho`` points per unit area,
    ``r_k = sqrt(k / (pi rho))``), input units. Unlike the nearest-neighbour distance it is not
    fooled by near-duplicate points (two cameras' rays meeting a sheet at almost the same
    place)."""
    from fourd.geometry.neighbors import knn

    points = np.asarray(points, dtype=np.float64)
    k = min(k, len(points) - 1)
    if k < 1:
        raise InputError("need at least two points to measure their spacing")
    distances, _ = knn(points, k)
    spacing = float(np.median(distances[:, k - 1])) * np.sqrt(np.pi / k)
    return spacing if spacing > 0 else 1.0


def _inliers(seq, t: int, options: AnchorOptions, cache: dict) -> np.ndarray:
    """Indices of frame ``t``'s points kept by step 0 (cached per frame)."""
    key = ("inliers", t)
    if key not in cache:
        points = seq[t].points
        if options.remove_outliers and len(points) > 32:
            from fourd.geometry.outliers import remove_outliers

            spacing = surface_spacing(points)
            kept = remove_outliers(points, spacing=spacing).inliers
            cache[key] = np.flatnonzero(kept)
        else:
            cache[key] = np.arange(len(points))
    return cache[key]


def _camera_frame(seq, c, t, radius, tolerance, options, cache) -> _CameraFrame:
    camera = seq.video.cameras[c]
    kept = _inliers(seq, t, options, cache)
    view = frame_view(camera, seq[t].points[kept], tolerance=tolerance, radius=radius)
    view = view._replace(index=kept[view.index])  # indices into the frame's points
    return _CameraFrame(seq.video.image(c, t), view)


class CameraTracks(NamedTuple):
    """One camera's tracks from frame ``first`` to ``first + 1``, after steps 1-5 (before the
    cameras are compared).

    Attributes
    ----------
    index : ndarray int64 [K]
        Source points (indices into frame ``first``'s points).
    target : ndarray float64 [K, 3]
        Their lifted positions in frame ``first + 1``.
    error : ndarray float64 [K]
        Forward-backward error, pixels.
    counts : dict
        Tracks left after each of the steps (``seen`` ... ``round_trip``).
    """

    index: np.ndarray
    target: np.ndarray
    error: np.ndarray
    counts: dict


def _tracks(points0, before: _CameraFrame, after: _CameraFrame, tolerance, reach, options, counts,
            candidates=None):
    """One camera's tracks: ``(index [K], target [K, 3], error [K])``; ``candidates`` (bool
    [P], optional): the points tracks may start from."""
    seen, uv = before.view.index, before.view.uv
    if candidates is not None:
        keep = candidates[seen]
        seen, uv = seen[keep], uv[keep]
    counts["seen"] += len(seen)
    if options.texture > 0 and len(seen):
        significance = texture_significance(before.image, sigma=options.texture_window)
        keep = sample_flow(significance[:, :, None], uv, channels=1)[:, 0] >= options.texture
        seen, uv = seen[keep], uv[keep]
    forward = optical_flow(before.image, after.image, method=options.flow, preset=options.preset)
    backward = optical_flow(after.image, before.image, method=options.flow, preset=options.preset)
    moved, returned, error = forward_backward(forward, backward, uv)
    keep = error <= options.forward_backward
    counts["forward_backward"] += int(keep.sum())
    seen, uv, moved, returned, error = seen[keep], uv[keep], moved[keep], returned[keep], error[keep]
    if np.isfinite(options.photometric):
        change = np.abs(sample_image(after.image, moved) - sample_image(before.image, uv))
        keep = change.max(axis=1) <= options.photometric
        seen, moved, returned, error = seen[keep], moved[keep], returned[keep], error[keep]
    counts["photometric"] += len(seen)
    k = options.neighbours
    target = lift(after.view, moved, tolerance=tolerance, k=k, reach=reach)
    keep = np.isfinite(target).all(axis=1)
    counts["lifted"] += int(keep.sum())
    seen, target, returned, error = seen[keep], target[keep], returned[keep], error[keep]
    back = lift(before.view, returned, tolerance=tolerance, k=k, reach=reach)
    with np.errstate(invalid="ignore"):
        keep = np.linalg.norm(back - points0[seen], axis=1) <= tolerance  # NaN: refused
    counts["round_trip"] += int(keep.sum())
    return seen[keep], target[keep], error[keep]


def merge_tracks(index, camera, target, reliability, camera_count: int, tolerance: float):
    """Merge the tracks of all cameras per source point (the module docstring's step 6).

    Parameters
    ----------
    index : ndarray int [K]
        Source point of each track.
    camera : ndarray int [K]
        Camera of each track (one track per point and camera), in ``0 .. camera_count - 1``.
    target : ndarray [K, 3]
    reliability : ndarray [K]
        In (0, 1): the chance the track is right.
    camera_count : int
    tolerance : float
        Largest distance between agreeing targets (input units).

    Returns
    -------
    index : ndarray int64 [M]
        Points kept, sorted.
    target : ndarray [M, 3]
        Reliability-weighted mean of the agreeing targets.
    confidence : ndarray [M]
        ``1 - prod(1 - reliability)`` over the agreeing tracks.
    views : ndarray int64 [M]
        Agreeing tracks per point.
    agreed : int
        Tracks kept in all.
    """
    index = np.asarray(index, dtype=np.int64)
    if not len(index):
        return index, np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64), 0
    points, group = np.unique(index, return_inverse=True)
    table = np.full((len(points), camera_count, 3), np.nan)
    weight = np.zeros((len(points), camera_count))
    table[group, camera] = target
    weight[group, camera] = reliability
    present = weight > 0
    count = present.sum(axis=1)
    distance = np.linalg.norm(table[:, :, None, :] - table[:, None, :, :], axis=3)
    close = (distance <= tolerance) & present[:, :, None] & present[:, None, :]
    close[:, np.arange(camera_count), np.arange(camera_count)] = False
    agreeing = present & (close.any(axis=2) | (count == 1)[:, None])
    views = agreeing.sum(axis=1)
    keep = views > 0
    w = np.where(agreeing, weight, 0.0)[keep]
    merged = (np.nan_to_num(table[keep]) * w[:, :, None]).sum(axis=1) / w.sum(axis=1)[:, None]
    confidence = 1.0 - np.prod(1.0 - w, axis=1)
    return points[keep], merged, confidence, views[keep].astype(np.int64), int(views.sum())


def _setup(seq, first: int, options: AnchorOptions):
    if not 0 <= first < len(seq) - 1:
        raise InputError(f"frame {first} has no next frame (the sequence has {len(seq)} frames)")
    points0 = seq[first].points
    spacing = surface_spacing(points0)
    tolerance = (
        options.tolerance if options.tolerance is not None else options.tolerance_spacings * spacing
    )
    return points0, spacing, float(tolerance)


def camera_tracks(
    seq, first: int, camera: int | str, options: AnchorOptions | None = None, **overrides
) -> CameraTracks:
    """The tracks of one camera from frame ``first`` to ``first + 1`` (steps 1-5 of the module
    docstring, without the agreement between cameras): what each camera contributes to
    :func:`anchor_pair`."""
    _check(seq)
    options = anchor_options(options, **overrides)
    points0, spacing, tolerance = _setup(seq, first, options)
    c = seq.video.camera_index(camera)
    pixels = pixel_spacing(seq.video.cameras[c], points0, spacing)
    radius = pixels if options.splat_radius is None else options.splat_radius
    cache: dict = {}
    before = _camera_frame(seq, c, first, radius, tolerance, options, cache)
    after = _camera_frame(seq, c, first + 1, radius, tolerance, options, cache)
    counts = dict.fromkeys(STAGES[:5], 0)
    index, target, error = _tracks(points0, before, after, tolerance, 2.5 * pixels, options, counts)
    return CameraTracks(index, target, error, counts)


def anchor_pair(seq, first: int, options: AnchorOptions | None = None, *, cache=None) -> AnchorPair:
    """The anchors from frame ``first`` to ``first + 1`` of ``seq`` (which has ``video``).

    ``cache`` (a dict, optional) keeps the decoded images, views and inliers of frame
    ``first + 1`` for the next pair.
    """
    _check(seq)
    options = AnchorOptions() if options is None else options
    video = seq.video
    second = first + 1
    points0, spacing, tolerance = _setup(seq, first, options)
    counts = dict.fromkeys(STAGES, 0)
    cache = {} if cache is None else cache
    candidates = None
    if options.sources > 0 and len(points0):
        candidates = np.zeros(len(points0), dtype=bool)
        candidates[one_per_cube(points0, options.sources * spacing)] = True
    indices, cameras, targets, reliabilities = [], [], [], []
    for c, camera in enumerate(video.cameras):
        pixels = pixel_spacing(camera, points0, spacing)
        radius = pixels if options.splat_radius is None else options.splat_radius
        before = cache.pop((c, first), None) or _camera_frame(
            seq, c, first, radius, tolerance, options, cache
        )
        after = _camera_frame(seq, c, second, radius, tolerance, options, cache)
        cache[(c, second)] = after
        index, target, error = _tracks(
            points0, before, after, tolerance, 2.5 * pixels, options, counts, candidates
        )
        indices.append(index)
        cameras.append(np.full(len(index), c))
        targets.append(target)
        if np.isfinite(options.forward_backward):
            reliabilities.append(0.5 * (1.0 - 0.5 * error / options.forward_backward))
        else:
            reliabilities.append(np.full(len(index), 0.5))
    index, target, confidence, views, agreed = merge_tracks(
        np.concatenate(indices),
        np.concatenate(cameras),
        np.concatenate(targets).reshape(-1, 3),
        np.concatenate(reliabilities),
        len(video.cameras),
        tolerance,
    )
    counts["agreed"] = agreed
    keep = views >= options.min_cameras
    index, target, confidence, views = index[keep], target[keep], confidence[keep], views[keep]
    if options.thin > 0 and len(index):
        kept = one_per_cube(points0[index], options.thin * spacing, confidence)
        index, target, confidence, views = index[kept], target[kept], confidence[kept], views[kept]
    counts["anchors"] = len(index)
    cache.pop(("inliers", first), None)
    logger.debug("anchors %d -> %d: %s", first, second, counts)
    return AnchorPair(
        first, second, points0[index], target, confidence, views, index, counts, float(tolerance)
    )


def _check(seq) -> None:
    from fourd.sequence import PointCloudSequence

    if not isinstance(seq, PointCloudSequence):
        raise InputError(f"expected a PointCloudSequence, got {type(seq).__name__}")
    if seq.video is None:
        raise InputError(
            "anchors need the capture's video: cameras.json and video/<camera>/ beside the "
            "frames (see the README), or fourd.synth.scan(..., video=True)"
        )


def anchors(seq, options: AnchorOptions | None = None, **overrides) -> Anchors:
    """3D anchor tracks between every pair of consecutive frames of ``seq``.

    Parameters
    ----------
    seq : PointCloudSequence
        With ``video`` (cameras and one image per camera and frame: ``cameras.json`` and
        ``video/`` beside the frames, or ``fourd.synth.scan(..., video=True)``).
    options : AnchorOptions, optional
        Keyword arguments (``flow``, ``forward_backward``, ``tolerance``, ``min_cameras``,
        ...) override its fields.

    Returns
    -------
    Anchors
        ``len(seq) - 1`` pairs; pair ``i`` holds ``source [M, 3]`` (points of frame ``i``),
        ``target [M, 3]`` (the same material points in frame ``i + 1``), ``confidence [M]``,
        ``views [M]`` and ``index [M]`` (see :class:`AnchorPair`).

    Raises
    ------
    InputError
        The sequence has no video, or bad options.

    References
    ----------
    T. Popa, "Capturing and Modeling of Deformable Objects", PhD thesis, UBC 2009, section
    5.4.1 (optical flow tracking and its two levels of pruning).
    """
    options = anchor_options(options, **overrides)
    _check(seq)
    cache: dict = {}
    pairs = [
        anchor_pair(seq, t, options, cache=cache)
        for t in progress(range(len(seq) - 1), desc="anchors", total=len(seq) - 1, unit="pair")
    ]
    return Anchors(tuple(pairs))


def cleaned_anchors(points, times, video, names=(), **overrides) -> Anchors:
    """:func:`anchors` of frames a method has already cleaned: ``points`` (list of [P_t, 3]) at
    ``times`` [T], filmed by ``video`` (:class:`~fourd.io.video.Video`, one image per camera
    and frame; ``names`` name the frames for messages). Their outliers are not set aside again
    (``remove_outliers`` false); keyword arguments override :class:`AnchorOptions`' fields."""
    from fourd.sequence import Frame, PointCloudSequence

    cleaned = PointCloudSequence(
        tuple(Frame(p, time=t) for p, t in zip(points, times, strict=True)), tuple(names), video
    )
    return anchors(cleaned, **{"remove_outliers": False, **overrides})
