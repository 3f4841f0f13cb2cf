"""Colours for a frame's points from the calibrated video: what the cameras that see each point show.

For scans without colours but with multi-view video beside them (:mod:`fourd.io.video`). Each
camera z-buffers the frame's own points (:func:`fourd.appearance.depth.splat_depth`); a point
counts as seen by a camera when it is in the image, in front, and the z-buffer agrees with its
depth within ``tolerance`` at the four pixels its bilinear sample reads (so a nearer surface
of the scan, or the background, is not read as its colour). The splat widens every surface by
its radius, so next to a depth edge that test still passes pixels that show what lies beside
or behind: a view that sees the point there counts ``EDGE_WEIGHT`` as much as a clean one
(:class:`ViewColors`). The image is read bilinearly at the point's projection
(:func:`fourd.appearance.flow.sample_image`), and the views that see the point are averaged,
each also weighted by how frontally it sees the point (``|cos|`` between the normal and the
ray, when normals are given). With three or more views,
those farther than ``agreement`` (any channel) from the per-channel median of the views are
dropped first: a camera whose view of the point is blocked by something not in the scan (a
hand, a prop) or that catches a highlight is outvoted.

Colour space: the values are the images' as :func:`fourd.io.video.read_image` decodes them
(8-bit, divided by 255), i.e. sRGB-encoded for ordinary PNG and JPEG files, which is how fourd
keeps colours that came from a scanner or a PLY file (:mod:`fourd.io.colorspace`); the
bilinear sample and the average are taken on the encoded values. The synthetic scanner writes
the same quantity into the points' colours and the images (:mod:`fourd.synth.filming`), so the
two compare directly. Colours of different frames are comparable as long as the cameras'
exposure does not change, which is all the colour guide needs.

A point no camera sees gets NaN from :func:`point_colors`; :func:`colors_from_video` (and so
:func:`with_video_colors`) gives it the colour of the nearest seen point instead, since a frame's
colours must be finite. Such a point then lies in a patch of one colour, which pins nothing down
in the colour guide (no colour gradient).

Examples
--------
>>> from fourd.appearance.cameras import look_at
>>> cam = look_at("c", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=30, width=32, height=32)
>>> g = np.linspace(-1, 1, 60)
>>> x, y = np.meshgrid(g, g)
>>> plane = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
>>> image = np.zeros((32, 32, 3), np.uint8)
>>> image[:, 16:] = 255                              # the right half of the picture is white
>>> colors = point_colors([cam], [image], plane, tolerance=0.1)
>>> colors[np.argmin(np.abs(plane - [0.5, 0, 0]).sum(1))].tolist()
[1.0, 1.0, 1.0]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter
from scipy.spatial import cKDTree

from fourd.appearance.cameras import Camera, in_image, project
from fourd.appearance.depth import splat_depth
from fourd.appearance.flow import sample_image
from fourd.errors import InputError

__all__ = [
    "AGREEMENT", "ViewColors", "colors_from_video", "fill_unseen", "point_colors", "view_colors",
    "with_video_colors",
]

#: Default largest difference (any channel, colours in [0, 1]) of a view from the views' median.
AGREEMENT = 0.1
#: Weight of a view that sees a point next to a depth edge (:class:`ViewColors`), against 1.
EDGE_WEIGHT = 0.1
#: Default depth tolerance in point spacings.
TOLERANCE_SPACINGS = 3.0


def _disc(radius: float) -> np.ndarray:
    reach = int(np.floor(radius))
    dy, dx = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    return dx**2 + dy**2 <= radius**2 + 1e-9


class ViewColors(NamedTuple):
    """What one camera shows of a frame's points.

    Attributes
    ----------
    colors : ndarray float64 [P, 3]
        In [0, 1]; NaN rows for points the camera does not see.
    direction : ndarray float64 [P, 3]
        Unit ray from the camera to each seen point; NaN rows where unseen.
    clean : ndarray bool [P]
        Seen away from any depth edge: the z-buffer agrees with the point's depth within the
        splat radius of the pixels its sample reads, so no other surface and no background can
        be in them (the splat widens every surface by its radius, so the plain test passes
        pixels up to a radius beyond a silhouette).
    """

    colors: np.ndarray
    direction: np.ndarray
    clean: np.ndarray


def view_colors(camera: Camera, image, points, *, tolerance: float, radius: float = 1.0, depth=None) -> ViewColors:
    """What one camera shows of ``points [P, 3]`` (a :class:`ViewColors`).

    Parameters
    ----------
    camera : Camera
    image : uint8 array [H, W, 3]
        The camera's image of the frame.
    points : array [P, 3]
        The frame's points (input units); they are also the occluders.
    tolerance : float
        Largest depth difference (input units) between a point and the z-buffer at the four
        pixels its bilinear sample reads.
    radius : float
        Splat radius of the z-buffer, pixels (about the point spacing in pixels, so that the
        surface has no holes the background shows through).
    depth : DepthMap, optional
        The z-buffer of ``points``, when already splatted.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    image = np.asarray(image)
    if image.shape[:2] != (camera.height, camera.width):
        raise InputError(
            f"camera {camera.name}: the image is {image.shape[1]}x{image.shape[0]} but the camera "
            f"is {camera.width}x{camera.height}"
        )
    if depth is None:
        depth = splat_depth(camera, points, radius=radius)
    footprint = _disc(radius)
    nearest = minimum_filter(depth.depth, footprint=footprint, mode="nearest")
    farthest = maximum_filter(depth.depth, footprint=footprint, mode="nearest")
    uv, z = project(camera, points)
    at = np.flatnonzero(in_image(camera, uv) & (z > 0))
    low = np.floor(uv[at]).astype(np.int64)
    agree = np.ones(len(at), dtype=bool)
    clean = np.ones(len(at), dtype=bool)
    for di in (0, 1):
        for dj in (0, 1):
            i = np.clip(low[:, 1] + di, 0, camera.height - 1)
            j = np.clip(low[:, 0] + dj, 0, camera.width - 1)
            agree &= np.abs(depth.depth[i, j] - z[at]) <= tolerance  # inf (nothing there) fails
            clean &= (nearest[i, j] >= z[at] - tolerance) & (farthest[i, j] <= z[at] + tolerance)
    seen = at[agree]
    colors = np.full((len(points), 3), np.nan)
    colors[seen] = sample_image(image, uv[seen])[:, :3]
    direction = np.full((len(points), 3), np.nan)
    offset = points[seen] - camera.center
    direction[seen] = offset / np.linalg.norm(offset, axis=1, keepdims=True)
    is_clean = np.zeros(len(points), dtype=bool)
    is_clean[at[agree & clean]] = True
    return ViewColors(colors, direction, is_clean)


def point_colors(
    cameras, images, points, *, normals=None, tolerance, radius=1.0,
    agreement: float = AGREEMENT,
) -> np.ndarray:
    """Colours ``[P, 3]`` of ``points [P, 3]`` from the cameras that see them (module docstring);
    NaN rows for points no camera sees.

    Parameters
    ----------
    cameras : sequence of Camera
    images : sequence of uint8 arrays [H, W, 3]
        One image per camera, of this frame.
    points : array [P, 3]
    normals : array [P, 3], optional
        Unit normals (orientation does not matter): each view weighs ``|cos|`` of its ray with
        the normal (at least 0.05). Without them every view weighs the same.
    tolerance : float or sequence of float
        As in :func:`view_colors`, one for all cameras or one per camera.
    radius : float or sequence of float
        Splat radius in pixels (:func:`view_colors`), one for all cameras or one per camera.
    agreement : float
        With three or more views, views farther than this (any channel) from the median of the
        views are left out, unless that leaves none.
    """
    cameras = list(cameras)
    images = list(images)
    if not cameras or len(images) != len(cameras):
        raise InputError(f"need one image per camera, got {len(images)} images for {len(cameras)} cameras")
    tolerances = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (len(cameras),))
    if not (np.isfinite(tolerances).all() and (tolerances > 0).all()):
        raise InputError(f"tolerance must be finite and > 0, got {tolerance!r}")
    if not agreement > 0:
        raise InputError(f"agreement must be > 0, got {agreement!r}")
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(cameras),))
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    views = np.empty((len(cameras), len(points), 3))
    weights = np.zeros((len(cameras), len(points)))
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        if normals.shape != points.shape:
            raise InputError(f"{len(normals)} normals for {len(points)} points")
    for c, (camera, image) in enumerate(zip(cameras, images, strict=True)):
        view = view_colors(camera, image, points, tolerance=tolerances[c], radius=radii[c])
        views[c] = view.colors
        seen = np.isfinite(view.colors[:, 0])
        weights[c, seen] = np.where(view.clean[seen], 1.0, EDGE_WEIGHT)
        if normals is not None:
            cosine = np.abs(np.einsum("ij,ij->i", view.direction[seen], normals[seen]))
            weights[c, seen] *= np.maximum(cosine, 0.05)
    count = (weights > 0).sum(axis=0)
    several = np.flatnonzero(count >= 3)
    if len(several):
        median = np.nanmedian(views[:, several], axis=0)
        far = np.nan_to_num(np.abs(views[:, several] - median).max(axis=2), nan=np.inf) > agreement
        kept = np.where(far, 0.0, weights[:, several])
        # views split evenly far from their median: keep them all rather than none
        weights[:, several] = np.where(kept.sum(axis=0) > 0, kept, weights[:, several])
    total = weights.sum(axis=0)
    colors = np.full((len(points), 3), np.nan)
    have = total > 0
    colors[have] = np.einsum("cp,cpk->pk", weights[:, have], np.nan_to_num(views[:, have])) / total[have, None]
    return colors


def colors_from_video(
    seq, frame_index: int, *, points=None, normals=None, tolerance: float | None = None,
    radius: float | None = None, agreement: float = AGREEMENT,
) -> np.ndarray:
    """Colours ``[P, 3]`` in [0, 1] of frame ``frame_index``'s points from ``seq.video``.

    Points no camera sees take the colour of the nearest seen point (module docstring).

    Parameters
    ----------
    seq : PointCloudSequence
        With ``video``.
    frame_index : int
    points : array [P, 3], optional
        The points to colour (default: the frame's), e.g. the frame after outlier removal; they
        are the occluders of the depth test too, so stray outliers in front of the surface
        would hide it.
    normals : array [P, 3], optional
        Their normals (default: the frame's, when ``points`` is not given); without any, every
        view counts the same.
    tolerance : float, optional
        Depth tolerance (input units); default per camera three times the points' spacing
        (:func:`fourd.appearance.anchor_tracks.surface_spacing`) or the width of a pixel at the
        points' median depth, whichever is larger (the z-buffer's depth changes by about a
        pixel's width times the slope from one pixel to the next).
    radius : float, optional
        Splat radius, pixels; default per camera, the point spacing in pixels at the points'
        median depth (1 to 8).
    agreement : float
        See :func:`point_colors`.

    Raises
    ------
    InputError
        No video, a frame index outside the sequence, or no point seen by any camera (the
        calibration does not fit the points, e.g. other units).
    """
    from fourd.appearance.anchor_tracks import pixel_spacing, surface_spacing

    video = getattr(seq, "video", None)
    if video is None:
        raise InputError("the sequence has no video to take colours from")
    if not -len(seq) <= int(frame_index) < len(seq):
        raise InputError(f"frame {frame_index} outside the sequence's {len(seq)} frames")
    frame = seq.frames[int(frame_index)]
    if points is None:
        points, normals = frame.points, frame.normals if normals is None else normals
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 2:
        raise InputError(f"frame {frame_index}: need at least two points to colour")
    spacing = surface_spacing(points)
    cameras = video.cameras
    if tolerance is None:
        tolerance = [TOLERANCE_SPACINGS * max(spacing, _pixel_size(camera, points)) for camera in cameras]
    if radius is None:
        radius = [pixel_spacing(camera, points, spacing) for camera in cameras]
    images = [video.image(c, int(frame_index)) for c in range(len(cameras))]
    colors = point_colors(
        cameras, images, points, normals=normals, tolerance=tolerance, radius=radius, agreement=agreement
    )
    return fill_unseen(points, colors, where=f"frame {frame_index}")


def _pixel_size(camera: Camera, points) -> float:
    """The width of a pixel on a surface facing the camera at the points' median depth."""
    _, z = project(camera, points)
    z = z[z > 0]
    return float(np.median(z)) / float(0.5 * (camera.K[0, 0] + camera.K[1, 1])) if len(z) else 0.0


def fill_unseen(points, colors, *, where: str = "the frame") -> np.ndarray:
    """``colors [P, 3]`` with NaN rows replaced by the colour of the nearest point that has one;
    InputError when none has."""
    colors = np.array(colors, dtype=np.float64)
    unseen = np.isnan(colors).any(axis=1)
    if unseen.all():
        raise InputError(f"{where}: no camera of the video sees any point (is the calibration in the points' units?)")
    if unseen.any():
        seen = np.flatnonzero(~unseen)
        _, nearest = cKDTree(points[seen]).query(points[unseen], workers=-1)
        colors[unseen] = colors[seen[nearest]]
    return np.clip(colors, 0.0, 1.0)


def with_video_colors(seq, **options):
    """``seq`` with every frame that has no colours coloured from its video
    (:func:`colors_from_video`, ``options`` passed on); a sequence without video, or whose
    frames all have colours, is returned as it is."""
    from dataclasses import replace

    from fourd.sequence import PointCloudSequence

    if getattr(seq, "video", None) is None or all(f.colors is not None for f in seq.frames):
        return seq
    frames = tuple(
        f if f.colors is not None else replace(f, colors=colors_from_video(seq, t, **options))
        for t, f in enumerate(seq.frames)
    )
    return PointCloudSequence(frames, seq.names, seq.video)
