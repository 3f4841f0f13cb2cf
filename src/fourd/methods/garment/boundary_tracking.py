"""Garment boundaries tracked through the frames, and the off-surface anchors they give
(Popa's thesis, section 3.6.1 and Appendix B).

A garment's natural boundaries (a T-shirt's neck, sleeves and waist) are nearly elliptical.
In the first frame each is the ellipse most of one of the mesh's longest boundary loops lies
on (:func:`loop_ellipse`, :func:`initial_ellipses`; the thesis lets the user pick it from the
candidates). In
every later frame (B.1): RANSAC candidates from six boundary points near the previous good
ellipse, pruned by location, orientation and size against it, the one that most boundary
points lie on kept and refitted to those points; a frame with no candidate left is skipped,
the last good ellipse stays the reference, and skipped frames are interpolated (B.2). The
centres, normals and radii are then smoothed in time by a Gaussian, and the anchor of a
boundary is the point a fixed distance from its centre along the normal, on the side away
from the garment (3.6.1, Figure 3.5).

Examples
--------
>>> angles = np.linspace(0, 2 * np.pi, 60, endpoint=False)
>>> ring = np.column_stack([np.cos(angles), 0.6 * np.sin(angles), np.zeros(60)])
>>> first = fit_ellipse(ring)
>>> frames = [ring + [0.05 * t, 0, 0] for t in range(5)]
>>> track = track_boundary(frames, first, TrackingOptions(time_sigma=0))
>>> (np.round(track.centers[:, 0], 3) + 0.0).tolist()
[0.0, 0.05, 0.1, 0.15, 0.2]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import gaussian_filter1d

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.methods.garment.ellipse import (
    Ellipse,
    as_batch,
    fit_ellipse,
    fit_ellipses,
    point_distances,
    prune,
    ransac_candidates,
    support,
)

__all__ = ["BoundaryTrack", "TrackingOptions", "initial_ellipses", "loop_ellipse", "read_keyframes",
           "track_boundary", "turned_outward"]


@dataclass(frozen=True)
class TrackingOptions:
    """How a boundary ellipse is followed from frame to frame (Appendix B).

    Attributes
    ----------
    samples : int
        RANSAC samples (six boundary points each) per frame and boundary. The thesis drew
        50,000-100,000 among all boundary points; drawing only near the reference needs far
        fewer.
    reach : float
        Samples come from boundary points within this many times the reference's largest
        radius of its centre (the thesis: 2).
    max_shift : float
        A candidate's centre lies within this many times the reference's largest radius of the
        reference's centre (the thesis: 10 cm for sleeves of about 8 cm).
    max_angle_degrees : float
        A candidate's plane turns at most this much from the reference's (the thesis: 30).
    size_tolerance : float
        Each radius and the perimeter stay within a factor ``1 +- size_tolerance`` of the
        reference's.
    tolerance : float
        A boundary point supports an ellipse when it lies within this many times the
        reference's largest radius of it.
    min_support : int
        A frame whose best candidate has fewer supporting points is skipped (interpolated).
    time_sigma : float or None
        Standard deviation of the Gaussian smoothing in time, frames (0: none). None: chosen
        per boundary among ``time_sigma_choices`` as the one whose smoothing best predicts
        each frame's centre from the other frames (leave-one-out): a boundary that moves
        steadily and is found cleanly in every frame (a sleeve swinging with its arm) is
        smoothed little, so the smoothing does not lag it; one whose ellipse jumps from frame
        to frame (a neck whose back the cameras miss) is smoothed more. A take of fewer than
        8 frames is smoothed 1 frame wide.
    time_sigma_choices : tuple of float
        The candidates for ``time_sigma`` None.
    anchor_offset : float
        The anchor's distance from the ellipse's centre along its normal, in mean radii.
    seed : int
        Seed of the random samples.
    """

    samples: int = 1500
    reach: float = 2.0
    max_shift: float = 1.0
    max_angle_degrees: float = 30.0
    size_tolerance: float = 0.3
    tolerance: float = 0.05
    min_support: int = 8
    time_sigma: float | None = None
    time_sigma_choices: tuple = (0.5, 1.0, 1.5, 2.0)
    anchor_offset: float = 1.0
    seed: int = 0


@dataclass(frozen=True)
class BoundaryTrack:
    """One boundary through ``T`` frames.

    Attributes
    ----------
    centers, normals : float64 [T, 3]
        The ellipses' centres and unit normals (normals away from the garment), smoothed.
    axes : float64 [T, 2, 3]
    radii : float64 [T, 2]
    found : bool [T]
        False where the frame was skipped and its ellipse interpolated.
    support : int64 [T]
        Boundary points on the chosen ellipse (0 where skipped).
    anchors : float64 [T, 3]
        The off-surface anchors.
    """

    centers: np.ndarray
    normals: np.ndarray
    axes: np.ndarray
    radii: np.ndarray
    found: np.ndarray
    support: np.ndarray
    anchors: np.ndarray

    def ellipse(self, t: int) -> Ellipse:
        return Ellipse(self.centers[t], self.normals[t], self.axes[t], self.radii[t])


def loop_ellipse(points: np.ndarray, options: TrackingOptions | None = None) -> Ellipse:
    """The ellipse of one boundary loop ``points [P, 3]`` (at least 6) of the first frame: the
    RANSAC candidate from six of its points that most of them lie on, refitted to those (B.1.1
    against the loop's least-squares ellipse, with loose limits: centre within its largest
    radius, size within 60%).

    Where an occlusion hole runs into an opening (an underarm's hole into the sleeve), the two
    are one boundary loop: its least-squares ellipse lies between them, while the opening's own
    arc, the part of the loop that is an ellipse, holds the most support."""
    options = options or TrackingOptions()
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    fitted = fit_ellipse(points)
    loose = replace(options, reach=np.inf, max_shift=1.0,
                    max_angle_degrees=90.0, size_tolerance=0.6, min_support=6)
    best = _best_candidate(points, fitted, np.random.default_rng(options.seed), loose)
    return fitted if best is None else best[0]


def initial_ellipses(vertices: np.ndarray, faces: np.ndarray, count: int) -> list[Ellipse]:
    """The ellipses (:func:`loop_ellipse`) of the ``count`` longest boundary loops of a frame's mesh,
    longest first, each normal turned away from the garment (the mesh's vertices within two
    radii of the centre lie behind it)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    loops = [loop for loop in boundary_loops(faces, len(vertices)) if len(loop) >= 6]
    if len(loops) < count:
        raise InputError(
            f"the first frame's mesh has {len(loops)} boundary loops of 6 vertices or more, "
            f"the garment needs {count}"
        )
    return [turned_outward(loop_ellipse(vertices[loop]), vertices) for loop in loops[:count]]


def turned_outward(ellipse: Ellipse, vertices: np.ndarray) -> Ellipse:
    """``ellipse`` (an opening of the surface with ``vertices [N, 3]``) with its normal away
    from the garment: the surface's vertices within two radii of its centre lie behind it on
    average. A fitted ellipse's normal has either sign."""
    vertices = np.asarray(vertices, dtype=np.float64)
    near = vertices[np.linalg.norm(vertices - ellipse.center, axis=1) <= 2.0 * ellipse.radii[0]]
    if len(near) and float(np.mean((near - ellipse.center) @ ellipse.normal)) > 0:
        return ellipse.flipped()
    return ellipse


def track_boundary(
    boundary_points: Sequence[np.ndarray],
    first: Ellipse,
    options: TrackingOptions | None = None,
    keyframes: Sequence[tuple[int, Ellipse]] = (),
) -> BoundaryTrack:
    """Follow the boundary that ``first`` fits in frame 0 through every frame's boundary points
    (``boundary_points[t] [P_t, 3]``: the vertices of all boundary loops of frame ``t``).

    ``keyframes``: ``(frame, ellipse)`` a user chose (B.2, the semi-automatic path), of this
    boundary or of others: in its frame, the keyframe ellipse nearest the reference (its centre
    within ``reach`` times the reference's largest radius) is taken as found and becomes the
    reference."""
    options = options or TrackingOptions()
    rng = np.random.default_rng(options.seed)
    frames = len(boundary_points)
    chosen: list[Ellipse | None] = [first] + [None] * (frames - 1)
    counts = np.zeros(frames, dtype=np.int64)
    reference = first
    given: dict[int, list[Ellipse]] = {}
    for frame, ellipse in keyframes:
        if not 0 <= int(frame) < frames:
            raise InputError(f"keyframe {frame} is not one of the {frames} frames")
        given.setdefault(int(frame), []).append(ellipse)
    for t in range(1, frames):
        points = np.asarray(boundary_points[t], dtype=np.float64).reshape(-1, 3)
        keyed = _keyframe(given.get(t, ()), reference, options)
        if keyed is not None:
            chosen[t] = keyed
            scale = options.tolerance * keyed.radii[0]
            counts[t] = support(as_batch(keyed), points, scale)[0][0] if len(points) else 0
            reference = keyed
            continue
        best = _best_candidate(points, reference, rng, options)
        if best is None:
            continue  # skipped: the last good ellipse stays the reference (B.2)
        chosen[t], counts[t] = best
        reference = chosen[t]
    first_points = np.asarray(boundary_points[0], dtype=np.float64).reshape(-1, 3)
    scale = options.tolerance * first.radii[0]
    counts[0] = support(as_batch(first), first_points, scale)[0][0] if len(first_points) else 0
    found = np.array([e is not None for e in chosen])
    centers, normals, axes, radii = _interpolate(chosen, found)
    sigma = options.time_sigma
    if sigma is None:
        sigma = _cross_validated_sigma(centers, options.time_sigma_choices)
    if sigma > 0 and frames > 1:
        centers = gaussian_filter1d(centers, sigma, axis=0, mode="nearest")
        normals = gaussian_filter1d(normals, sigma, axis=0, mode="nearest")
        radii = gaussian_filter1d(radii, sigma, axis=0, mode="nearest")
        axes = gaussian_filter1d(axes, sigma, axis=0, mode="nearest")
    normals, axes = _orthonormal(normals, axes)
    anchors = centers + options.anchor_offset * radii.mean(axis=1)[:, None] * normals
    return BoundaryTrack(centers, normals, axes, radii, found, counts, anchors)


def _keyframe(ellipses, reference: Ellipse, options: TrackingOptions) -> Ellipse | None:
    """The given ellipse of this boundary in a keyframe (nearest the reference, within
    ``reach`` of its largest radius), turned to the reference's side; None without one."""
    best, distance = None, options.reach * reference.radii[0]
    for ellipse in ellipses:
        gap = float(np.linalg.norm(ellipse.center - reference.center))
        if gap <= distance:
            best, distance = ellipse, gap
    return None if best is None else _aligned(best, reference)


def _best_candidate(points, reference: Ellipse, rng, options: TrackingOptions):
    """``(ellipse, support)`` of the frame, or None when no candidate survives the pruning."""
    candidates = ransac_candidates(
        points, reference, rng, samples=options.samples, reach=options.reach
    )
    limits = dict(
        max_shift=options.max_shift * reference.radii[0],
        max_angle_degrees=options.max_angle_degrees,
        size_tolerance=options.size_tolerance,
    )
    candidates = prune(candidates, reference, **limits)
    if not len(candidates):
        return None
    tolerance = options.tolerance * reference.radii[0]
    counts, mean = support(candidates, points, tolerance)
    best = int(np.lexsort((mean, -counts))[0])
    if counts[best] < options.min_support:
        return None
    ellipse, count = candidates[best], int(counts[best])
    # refit to the points on it: the six samples only found it
    inliers = points[np.linalg.norm(points - ellipse.center, axis=1) <= options.reach * reference.radii[0]]
    on = point_distances(as_batch(ellipse), inliers)[0] <= tolerance
    if on.sum() >= 6:
        refit = fit_ellipses(inliers[on][None])
        if refit.valid[0]:
            refined = refit[0]
            if len(prune(as_batch(refined), reference, **limits)):
                ellipse = refined
                count = int(support(as_batch(ellipse), points, tolerance)[0][0])
    return _aligned(ellipse, reference), count


def _aligned(ellipse: Ellipse, reference: Ellipse) -> Ellipse:
    """``ellipse`` with its normal and major axis turned to the reference's side (a fit's
    signs are arbitrary; blending over time needs them to agree)."""
    normal = ellipse.normal if ellipse.normal @ reference.normal >= 0 else -ellipse.normal
    major = ellipse.axes[0] if ellipse.axes[0] @ reference.axes[0] >= 0 else -ellipse.axes[0]
    return Ellipse(ellipse.center, normal, np.stack([major, np.cross(normal, major)]), ellipse.radii)


def _interpolate(chosen: list, found: np.ndarray):
    """Per-frame arrays of the found ellipses, skipped frames linearly interpolated between
    their found neighbours (held at the ends)."""
    frames = len(chosen)
    known = np.flatnonzero(found)
    t = np.arange(frames)

    def field(get):
        values = np.stack([get(chosen[k]) for k in known])
        flat = values.reshape(len(known), -1)
        out = np.stack([np.interp(t, known, flat[:, j]) for j in range(flat.shape[1])], axis=1)
        return out.reshape((frames,) + values.shape[1:])

    return (
        field(lambda e: e.center),
        field(lambda e: e.normal),
        field(lambda e: e.axes),
        field(lambda e: e.radii),
    )


#: Fewer frames than this: the smoothing in time is 1 frame wide, not chosen.
SHORT_TAKE = 8


def _cross_validated_sigma(centers: np.ndarray, choices) -> float:
    """Of ``choices`` (frames), the Gaussian width whose average of the other frames best
    predicts each frame's centre (``centers [T, 3]``; least mean squared error; the first of
    equals). A take shorter than ``SHORT_TAKE`` frames is too short to tell noise from motion
    (a 4-frame dress chose 2 frames for its hem, and its frame 2 came out 0.019 of the
    diagonal off at the 95th percentile against 0.0145 with 1): it gets 1 frame."""
    frames = len(centers)
    if frames < SHORT_TAKE:
        return 1.0
    offset = np.arange(frames)[None, :] - np.arange(frames)[:, None]
    errors = []
    for sigma in choices:
        weight = np.exp(-0.5 * (offset / sigma) ** 2)
        np.fill_diagonal(weight, 0.0)
        predicted = (weight @ centers) / weight.sum(axis=1, keepdims=True)
        errors.append(float(np.mean(np.sum((predicted - centers) ** 2, axis=1))))
    return float(choices[int(np.argmin(errors))])


def _orthonormal(normals: np.ndarray, axes: np.ndarray):
    """Unit normals and axes made orthonormal to them again after blending."""
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    major = axes[:, 0] - np.einsum("tj,tj->t", axes[:, 0], normals)[:, None] * normals
    major /= np.maximum(np.linalg.norm(major, axis=1, keepdims=True), 1e-300)
    minor = np.cross(normals, major)
    return normals, np.stack([major, minor], axis=1)


def read_keyframes(path) -> list[tuple[int, Ellipse]]:
    """Keyframe ellipses from a JSON file (B.2): ``{"keyframes": [{"frame": 12, "points":
    [[x, y, z], ...]}, ...]}``, each entry at least six points a user picked along one garment
    boundary in that frame (input units); each becomes the least-squares ellipse of its points.
    Raises :class:`InputError` naming the file and the entry for anything else."""
    import json
    from pathlib import Path

    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such keyframes file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"{path}: not a readable JSON file ({error})") from None
    entries = data.get("keyframes") if isinstance(data, dict) else None
    if not isinstance(entries, list):
        raise InputError(f'{path}: expected {{"keyframes": [{{"frame": ..., "points": [...]}}, ...]}}')
    keyframes = []
    for index, entry in enumerate(entries):
        where = f"{path}: keyframe {index}"
        if not isinstance(entry, dict) or "frame" not in entry or "points" not in entry:
            raise InputError(f'{where} needs "frame" and "points"')
        frame = entry["frame"]
        if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
            raise InputError(f"{where}: frame must be an integer >= 0, got {frame!r}")
        try:
            points = np.asarray(entry["points"], dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{where}: points must be [[x, y, z], ...] numbers") from None
        if points.ndim != 2 or points.shape[1] != 3 or len(points) < 6 or not np.isfinite(points).all():
            raise InputError(f"{where}: points must be at least six finite [x, y, z], got shape {list(points.shape)}")
        batch = fit_ellipses(points[None])
        if not batch.valid[0]:
            raise InputError(f"{where}: no ellipse fits these points (collinear or repeated?)")
        keyframes.append((frame, batch[0]))
    return keyframes
