"""A virtual depth scanner: fixed pinhole depth cameras ray-casting the true surface.

The default setting is the benchmark's scan protocol (``shared/BASELINES.md``):

- ``K = 3`` cameras on a ring around the centre ``c`` of the truth's bounding box over all
  frames (diagonal ``D``), at horizontal distance ``1.6 D`` from ``c``, raised by ``0.25`` of
  that distance (Y is up), ``360 / K`` degrees apart with the first at 0.3 rad, each looking at
  ``c``;
- ``256 x 256`` rays per camera through the pixel centres of a square of side ``1.2 D``
  centred on ``c`` and facing the camera; the first hit on the true mesh of each frame
  (trimesh's Embree intersector when embreex is installed, else a built-in numba caster that
  finds the same hits, see :func:`ray_backend`);
- Gaussian noise of ``0.002 D`` along each ray;
- ``2 %`` of the points replaced by outliers uniform in that bounding box (over all frames).

A point-sequence truth (an :class:`~fourd.AnimatedMesh` without faces, e.g. ``dfaust-hopping``)
has no surface to hit: per frame a random ``hpr_fraction`` of its points is drawn once, each
camera keeps the ones hidden-point removal (Katz, Tal, Basri 2007) finds visible and that lie
in its image square, and the union over the cameras gets the same noise (along the ray from the
first camera that sees the point) and outliers.

With ``appearance="skin"`` or ``"cloth"`` every point also gets a colour: the albedo of its
material point (:mod:`fourd.synth.albedo`, on the rest surface, so it moves with the skin) times
Lambertian shading by fixed lamps (:mod:`fourd.synth.shading`), plus sensor noise
``color_noise``; outliers get random colours. With ``video=True`` the sequence also carries the
rig's calibrated video (:mod:`fourd.synth.filming`): per camera and frame an image of the
textured, shaded scene (occluder included), on the scanner's pixel grid by default.

With ``mode="remeshed"`` the frames are per-frame meshes with perfect geometry instead
(:mod:`fourd.synth.remesh`): each frame's truth surface remeshed on its own by marching cubes
of its signed distance at the scan's ray spacing at the centre (``field * D / resolution``),
on a grid shifted by a random fraction of a cell every frame (so every frame has a
triangulation of its own), each vertex projected onto the truth triangles. No noise, no
outliers, no occlusion: a method's correspondence error on them is its cross-parameterisation
alone (issue 51).

Every frame is a pure function of the truth frame, the options and ``(seed, frame index)``
(:func:`scan_frame`), so frames can be scanned independently and in any order. Colours and
images draw from their own random streams: switching them on leaves the points unchanged.

References
----------
S. Katz, A. Tal, R. Basri, "Direct Visibility of Point Sets", SIGGRAPH 2007 (section 2:
spherical flipping and the convex hull).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import trimesh
from numba import njit
from scipy.spatial import ConvexHull

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.progress import progress
from fourd.sequence import Frame, PointCloudSequence

logger = logging.getLogger("fourd.synth.scanner")

#: What a scan gives per frame (:attr:`ScanOptions.mode`): depth-camera points, or the truth
#: surface remeshed on its own.
SCAN_MODES = ("depth", "remeshed")

#: Outlier label of a point (see :class:`FrameScan`).
SURFACE, UNIFORM_OUTLIER, CLUSTER_OUTLIER = 0, 1, 2


@dataclass(frozen=True)
class ScanOptions:
    """Settings of the virtual scanner; the defaults are the benchmark protocol.

    Attributes
    ----------
    cameras : int
        Number of cameras on the ring (>= 1).
    resolution : int
        Rays per image side (``resolution**2`` rays per camera).
    noise : float
        Standard deviation of the depth noise along each ray, as a fraction of the truth's
        bounding-box diagonal.
    outliers : float
        Fraction of each frame's points replaced by points uniform in the truth's bounding box
        over all frames (the box the rig is built around).
    structured_outliers : float
        Fraction of each frame's points replaced by small clusters (about 50 points each,
        standard deviation ``cluster_size`` of the diagonal) at random places in the box.
    drop_frames : tuple of int
        Truth frame indices left out of the scan (a frame cannot be empty, so a dropped frame is
        omitted; the other frames keep their times).
    occluder : bool
        A sphere of radius ``0.12 D`` sweeping across the view of camera 0, ``0.6 D`` in front
        of the centre, blocking rays. Its own points are not kept (it is not part of the truth).
    hpr_fraction : float
        Point-sequence truths: the fraction of points drawn per frame before hidden-point
        removal.
    hpr_radius : float
        Point-sequence truths: the flipping radius ``R`` as a multiple of the larger of the
        points' bounding-box diagonal and their largest distance from the camera (Katz et al.
        section 2.1 use ``R = max |p| 10^gamma``). The default 200 gives about 24,000 points per
        frame on ``dfaust-hopping``, the count BASELINES.md reports for its protocol (100 gives
        about 22,300).
    distance, elevation, first_angle, field : float
        The rig: horizontal distance (multiple of the diagonal), height (fraction of that
        distance), angle of camera 0 (radians, in the XZ plane), side of the imaged square at
        the centre (multiple of the diagonal).
    cluster_size : float
        Standard deviation of a structured-outlier cluster, fraction of the diagonal.
    ray_backend : {"auto", "embree", "numba"}
        Ray caster (see :func:`ray_backend`); both give the same first hits.
    appearance : {None, "skin", "cloth", "uniform"}
        Surface colour of the truth (:mod:`fourd.synth.albedo`); None: points without colour.
        The pattern is chosen by ``seed``.
    color_noise : float
        Standard deviation of the colour noise, fraction of full scale (points and images).
    lighting : {"lamps", "diffuse"}
        ``"lamps"``: the studio's fixed directional lamps (:class:`fourd.synth.shading.Lamps`).
        ``"diffuse"``: a uniform diffuse sky (:func:`fourd.synth.shading.diffuse_studio`, the
        garment studio of Popa's thesis), where brightness says how deep a point lies.
    video : bool
        Also film the scene: the sequence's ``video`` holds one image per camera and frame
        (:mod:`fourd.synth.filming`); without an ``appearance`` the surface is ``"cloth"``.
    video_resolution : int or None
        Image side in pixels (square images of the scanner's view); None: ``resolution``, so
        that each image pixel is one of the depth camera's rays.
    mode : {"depth", "remeshed"}
        ``"depth"``: the depth cameras above. ``"remeshed"``: per-frame meshes of the truth
        surface itself (module docstring), ``field * D / resolution`` apart; ``noise``,
        ``outliers``, ``structured_outliers`` and ``occluder`` are set to none (perfect
        geometry), and colours and video are not available (yet).
    seed : int
        Frame ``t`` draws from ``numpy.random.default_rng([seed, t])`` (colours from
        ``[seed, t, 1]``, images from ``[seed, t, 2]``).
    """

    cameras: int = 3
    resolution: int = 256
    noise: float = 0.002
    outliers: float = 0.02
    structured_outliers: float = 0.0
    drop_frames: tuple[int, ...] = ()
    occluder: bool = False
    hpr_fraction: float = 0.3
    hpr_radius: float = 200.0
    distance: float = 1.6
    elevation: float = 0.25
    first_angle: float = 0.3
    field: float = 1.2
    cluster_size: float = 0.01
    ray_backend: str = "auto"
    appearance: str | None = None
    color_noise: float = 0.01
    lighting: str = "lamps"
    video: bool = False
    video_resolution: int | None = None
    mode: str = "depth"
    seed: int = 0

    def __post_init__(self):
        if int(self.cameras) != self.cameras or self.cameras < 1:
            raise InputError(f"cameras must be a positive integer, got {self.cameras!r}")
        if int(self.resolution) != self.resolution or self.resolution < 1:
            raise InputError(f"resolution must be a positive integer, got {self.resolution!r}")
        object.__setattr__(self, "cameras", int(self.cameras))
        object.__setattr__(self, "resolution", int(self.resolution))
        for name in ("noise", "cluster_size"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"{name} must be finite and >= 0, got {value!r}")
        for name in ("outliers", "structured_outliers"):
            value = getattr(self, name)
            if not 0.0 <= value < 1.0:
                raise InputError(f"{name} must be a fraction in [0, 1), got {value!r}")
        if self.outliers + self.structured_outliers >= 1.0:
            raise InputError("outliers + structured_outliers must be below 1")
        if not 0.0 < self.hpr_fraction <= 1.0:
            raise InputError(f"hpr_fraction must be in (0, 1], got {self.hpr_fraction!r}")
        for name in ("hpr_radius", "distance", "field"):
            if not getattr(self, name) > 0:
                raise InputError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.ray_backend not in ("auto", "embree", "numba"):
            raise InputError(f"ray_backend must be auto, embree or numba, got {self.ray_backend!r}")
        drop = tuple(int(i) for i in np.atleast_1d(np.asarray(self.drop_frames, dtype=np.int64)))
        if any(i < 0 for i in drop):
            raise InputError(f"drop_frames must hold frame indices >= 0, got {drop}")
        object.__setattr__(self, "drop_frames", tuple(sorted(set(drop))))
        from fourd.synth.albedo import check_appearance

        object.__setattr__(self, "appearance", check_appearance(self.appearance))
        if not np.isfinite(self.color_noise) or self.color_noise < 0:
            raise InputError(f"color_noise must be finite and >= 0, got {self.color_noise!r}")
        if self.lighting not in ("lamps", "diffuse"):
            raise InputError(f"lighting must be 'lamps' or 'diffuse', got {self.lighting!r}")
        object.__setattr__(self, "video", bool(self.video))
        if self.video and self.appearance is None:  # film a textured surface by default
            object.__setattr__(self, "appearance", "cloth")
        if self.video_resolution is not None:
            if int(self.video_resolution) != self.video_resolution or self.video_resolution < 8:
                raise InputError(
                    f"video_resolution must be an integer >= 8, got {self.video_resolution!r}"
                )
            object.__setattr__(self, "video_resolution", int(self.video_resolution))
        if self.mode not in SCAN_MODES:
            raise InputError(f"mode must be one of {', '.join(SCAN_MODES)}, got {self.mode!r}")
        if self.mode == "remeshed":
            if self.appearance is not None or self.video:
                raise InputError("the remeshed scan mode has no colours or video yet")
            for name in ("noise", "outliers", "structured_outliers"):
                object.__setattr__(self, name, 0.0)
            object.__setattr__(self, "occluder", False)


class CameraRig(NamedTuple):
    """Fixed pinhole cameras looking at ``centre``.

    Attributes
    ----------
    positions : ndarray [K, 3]
        Camera centres.
    forward, right, up : ndarray [K, 3]
        Unit viewing direction (towards ``centre``) and the image axes.
    centre : ndarray [3]
        The point every camera looks at.
    width : float
        Side of the imaged square, centred on ``centre`` and facing each camera.
    """

    positions: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    centre: np.ndarray
    width: float


class FrameScan(NamedTuple):
    """One scanned frame with what the scanner knows about each point.

    Attributes
    ----------
    index : int
        The truth frame index.
    points : ndarray float64 [P, 3]
    camera : ndarray int [P]
        Camera whose ray produced the point (-1 for outliers).
    label : ndarray int8 [P]
        ``SURFACE`` (0), ``UNIFORM_OUTLIER`` (1) or ``CLUSTER_OUTLIER`` (2).
    clean : ndarray float64 [P, 3]
        The noise-free surface point of each point (outliers: the outlier itself).
    colors : ndarray float64 [P, 3] or None
        Recorded colour in [0, 1] (with ``appearance``; outliers: random colours).
    """

    index: int
    points: np.ndarray
    camera: np.ndarray
    label: np.ndarray
    clean: np.ndarray
    colors: np.ndarray | None = None


def camera_rig(
    bounds: np.ndarray,
    cameras: int = 3,
    *,
    distance: float = 1.6,
    elevation: float = 0.25,
    first_angle: float = 0.3,
    field: float = 1.2,
) -> CameraRig:
    """The ring of cameras around a bounding box (Y up).

    Parameters
    ----------
    bounds : ndarray [2, 3]
        Minimum and maximum corner of the scene (over all frames).
    cameras : int
        Number of cameras, ``360 / cameras`` degrees apart in the XZ plane.
    distance : float
        Horizontal distance from the centre, multiple of the diagonal ``D``.
    elevation : float
        Height above the centre as a fraction of the horizontal distance.
    first_angle : float
        Angle of camera 0 in radians (``x = cos``, ``z = sin``).
    field : float
        Side of the imaged square at the centre, multiple of ``D``.

    Returns
    -------
    CameraRig
    """
    bounds = np.asarray(bounds, dtype=float)
    if bounds.shape != (2, 3) or not np.isfinite(bounds).all():
        raise InputError(f"bounds must be a finite [2, 3] array, got shape {list(bounds.shape)}")
    centre = bounds.mean(axis=0)
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    if diagonal <= 0:
        raise InputError("the scene's bounding box is a single point")
    angles = first_angle + 2.0 * np.pi * np.arange(cameras) / cameras
    radius = distance * diagonal
    positions = centre + np.stack(
        [radius * np.cos(angles), np.full(cameras, elevation * radius), radius * np.sin(angles)], 1
    )
    forward = centre - positions
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    up = np.cross(right, forward)
    return CameraRig(positions, forward, right, up, centre, field * diagonal)


def camera_rays(rig: CameraRig, camera: int, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Rays of one camera through the pixel centres of its square.

    Returns
    -------
    origins : ndarray [R, 3]
        The camera position, repeated (``R = resolution**2``).
    directions : ndarray [R, 3]
        Unit directions, row-major over the image (row = up, column = right).
    """
    offsets = ((np.arange(resolution) + 0.5) / resolution - 0.5) * rig.width
    rows, columns = np.meshgrid(offsets[::-1], offsets, indexing="ij")
    targets = (
        rig.centre
        + columns.reshape(-1, 1) * rig.right[camera]
        + rows.reshape(-1, 1) * rig.up[camera]
    )
    directions = targets - rig.positions[camera]
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.broadcast_to(rig.positions[camera], directions.shape)
    return np.ascontiguousarray(origins), directions


def hidden_point_removal(
    points: np.ndarray, viewpoint: np.ndarray, *, radius: float = 200.0
) -> np.ndarray:
    """Indices of the points visible from ``viewpoint`` (Katz, Tal, Basri 2007).

    Spherical flipping about ``viewpoint`` with radius ``R = radius * max(diameter, max |p|)``
    (``diameter``: the points' bounding-box diagonal; ``|p|``: distances from the viewpoint),
    then the convex hull of the flipped points and the viewpoint: the points on the hull are
    the visible ones. Points just past the silhouette may be kept (a property of the method).

    Parameters
    ----------
    points : ndarray [P, 3]
    viewpoint : ndarray [3]
    radius : float
        Flipping radius as a multiple of that scale (larger: more points count as visible).

    Returns
    -------
    ndarray int [V]
        Sorted indices into ``points``.

    References
    ----------
    Katz, Tal, Basri, "Direct Visibility of Point Sets", SIGGRAPH 2007, section 2.
    """
    points = np.asarray(points, dtype=float)
    if len(points) < 4:
        return np.arange(len(points))
    relative = points - np.asarray(viewpoint, dtype=float)
    norms = np.maximum(np.linalg.norm(relative, axis=1, keepdims=True), 1e-300)
    diameter = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    big = radius * max(diameter, float(norms.max()))
    flipped = relative + 2.0 * (big - norms) * relative / norms
    hull = ConvexHull(np.vstack([flipped, np.zeros((1, 3))]))
    visible = hull.vertices[hull.vertices < len(points)]
    return np.sort(visible)


def _embree_intersector(mesh: trimesh.Trimesh):
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    return RayMeshIntersector(mesh)


@njit(cache=True)
def _first_hits(vertices, faces, origin, right, up, forward, focal, width, n, directions):
    """Nearest hit of each pixel ray of one camera (``depth [n*n]``, ``triangle [n*n]``, -1 =
    miss): every triangle in front of the camera is projected to find the pixels whose rays may
    cross it (its image bounding box plus one pixel), then each such ray is tested exactly
    (Moller-Trumbore, double precision, edges inclusive) and the nearest hit kept."""
    depth = np.full(n * n, np.inf)
    triangle = np.full(n * n, -1, dtype=np.int64)
    ox, oy, oz = origin[0], origin[1], origin[2]
    for m in range(faces.shape[0]):
        jmin, jmax, imin, imax = np.inf, -np.inf, np.inf, -np.inf
        behind = False
        for c in range(3):
            px = vertices[faces[m, c], 0] - ox
            py = vertices[faces[m, c], 1] - oy
            pz = vertices[faces[m, c], 2] - oz
            z = px * forward[0] + py * forward[1] + pz * forward[2]
            if z <= 0.0:
                behind = True
                break
            a = (px * right[0] + py * right[1] + pz * right[2]) * focal / z
            b = (px * up[0] + py * up[1] + pz * up[2]) * focal / z
            jc = (a / width + 0.5) * n - 0.5
            ic = n - 1 - ((b / width + 0.5) * n - 0.5)
            jmin, jmax = min(jmin, jc), max(jmax, jc)
            imin, imax = min(imin, ic), max(imax, ic)
        if behind:
            continue
        j0 = max(0, int(np.floor(jmin)) - 1)
        j1 = min(n - 1, int(np.ceil(jmax)) + 1)
        i0 = max(0, int(np.floor(imin)) - 1)
        i1 = min(n - 1, int(np.ceil(imax)) + 1)
        if j0 > j1 or i0 > i1:
            continue
        a0, a1, a2 = faces[m, 0], faces[m, 1], faces[m, 2]
        v0x, v0y, v0z = vertices[a0, 0], vertices[a0, 1], vertices[a0, 2]
        e1x, e1y, e1z = vertices[a1, 0] - v0x, vertices[a1, 1] - v0y, vertices[a1, 2] - v0z
        e2x, e2y, e2z = vertices[a2, 0] - v0x, vertices[a2, 1] - v0y, vertices[a2, 2] - v0z
        tx, ty, tz = ox - v0x, oy - v0y, oz - v0z
        qx = ty * e1z - tz * e1y
        qy = tz * e1x - tx * e1z
        qz = tx * e1y - ty * e1x
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                r = i * n + j
                dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
                px = dy * e2z - dz * e2y
                py = dz * e2x - dx * e2z
                pz = dx * e2y - dy * e2x
                det = e1x * px + e1y * py + e1z * pz
                if det == 0.0:
                    continue
                inverse = 1.0 / det
                u = (tx * px + ty * py + tz * pz) * inverse
                if u < 0.0 or u > 1.0:
                    continue
                v = (dx * qx + dy * qy + dz * qz) * inverse
                if v < 0.0 or u + v > 1.0:
                    continue
                t = (e2x * qx + e2y * qy + e2z * qz) * inverse
                if 0.0 < t < depth[r]:
                    depth[r] = t
                    triangle[r] = m
    return depth, triangle


def ray_backend(name: str = "auto") -> str:
    """The ray caster ``name`` resolves to: ``"embree"`` (trimesh's Embree intersector, when
    embreex is installed) or ``"numba"`` (the built-in caster, exact and about as fast for one
    camera image); ``"auto"`` is the numba caster, so that a scan is the same whether or not
    embreex is installed."""
    if name == "auto":
        return "numba"
    if name == "embree" and not trimesh.ray.has_embree:
        raise InputError("ray_backend='embree' needs embreex: pip install 'fourd[fast]'")
    return name


def _occluder_centre(rig: CameraRig, diagonal: float, phase: float) -> np.ndarray:
    """Centre of the occluder at normalised time ``phase``: 0.6 D in front of the scene's centre
    towards camera 0, sweeping from -0.5 D to +0.5 D along that camera's right axis."""
    return rig.centre - 0.6 * diagonal * rig.forward[0] + (phase - 0.5) * diagonal * rig.right[0]


def _truth_frames(truth) -> tuple[int, np.ndarray, bool]:
    if isinstance(truth, AnimatedMesh):
        return truth.frame_count, truth.bounds(), len(truth.faces) == 0
    if isinstance(truth, MeshSequence):
        return truth.frame_count, truth.bounds(), False
    raise InputError(
        f"the truth must be an AnimatedMesh or a MeshSequence, got {type(truth).__name__}"
    )


def _cast(vertices, faces, rig, options, diagonal, phase):
    """First hits of every camera: ``(points [P, 3], camera [P], directions [P, 3],
    triangle [P])``."""
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    surface_faces = len(faces)
    if options.occluder:
        ball = trimesh.creation.icosphere(subdivisions=3, radius=0.12 * diagonal)
        centre = _occluder_centre(rig, diagonal, phase)
        faces = np.concatenate([faces, np.asarray(ball.faces) + len(vertices)])
        vertices = np.concatenate([vertices, np.asarray(ball.vertices) + centre])
    backend = ray_backend(options.ray_backend)
    if backend == "embree":
        intersector = _embree_intersector(trimesh.Trimesh(vertices, faces, process=False))
    points, cameras, directions, triangles = [], [], [], []
    for k in range(len(rig.positions)):
        origins, rays = camera_rays(rig, k, options.resolution)
        if backend == "embree":
            locations, ray_index, triangle = intersector.intersects_location(
                origins, rays, multiple_hits=False
            )
            order = np.argsort(ray_index, kind="stable")
            locations = np.asarray(locations, dtype=float)[order]
            ray_index, triangle = ray_index[order], triangle[order]
        else:
            focal = float(np.linalg.norm(rig.centre - rig.positions[k]))
            depth, hit = _first_hits(
                vertices, faces, rig.positions[k], rig.right[k], rig.up[k], rig.forward[k],
                focal, float(rig.width), options.resolution, rays,
            )  # fmt: skip
            ray_index = np.flatnonzero(hit >= 0)
            triangle = hit[ray_index]
            locations = rig.positions[k] + depth[ray_index, None] * rays[ray_index]
        keep = triangle < surface_faces
        points.append(locations[keep])
        directions.append(rays[ray_index[keep]])
        cameras.append(np.full(int(keep.sum()), k))
        triangles.append(np.asarray(triangle[keep], dtype=np.int64))
    return (
        np.concatenate(points),
        np.concatenate(cameras),
        np.concatenate(directions),
        np.concatenate(triangles),
    )


def _in_view(points: np.ndarray, rig: CameraRig, camera: int) -> np.ndarray:
    """Which points project inside camera ``camera``'s image square, bool [P]."""
    relative = points - rig.positions[camera]
    depth = relative @ rig.forward[camera]
    focal = float(np.linalg.norm(rig.centre - rig.positions[camera]))
    scale = focal / np.maximum(depth, 1e-300)
    half = rig.width / 2.0
    a = np.abs(relative @ rig.right[camera]) * scale
    b = np.abs(relative @ rig.up[camera]) * scale
    return (depth > 0) & (a <= half) & (b <= half)


def _visible_points(points, rig, options, rng):
    """Point truth: a random subset, hidden-point removal per camera, union:
    ``(points [P, 3], camera [P], directions [P, 3], index [P])`` (``index`` into the truth's
    points)."""
    count = max(1, int(round(options.hpr_fraction * len(points))))
    subset = np.sort(rng.choice(len(points), size=count, replace=False))
    sample = points[subset]
    camera = np.full(len(sample), -1)
    for k in range(len(rig.positions) - 1, -1, -1):  # lowest camera index wins
        visible = np.zeros(len(sample), dtype=bool)
        visible[hidden_point_removal(sample, rig.positions[k], radius=options.hpr_radius)] = True
        camera[visible & _in_view(sample, rig, k)] = k
    seen = camera >= 0
    sample, camera = sample[seen], camera[seen]
    directions = sample - rig.positions[camera]
    directions /= np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), 1e-300)
    return sample, camera, directions, subset[seen]


def scan_frame(
    truth, index: int, options: ScanOptions | None = None, *, rig: CameraRig | None = None
) -> FrameScan:
    """Scan truth frame ``index``: a pure function of the frame, the options and the seed.

    Parameters
    ----------
    truth : AnimatedMesh or MeshSequence
    index : int
        Frame index in ``truth``.
    options : ScanOptions, optional
    rig : CameraRig, optional
        Defaults to :func:`camera_rig` of the truth's bounds over all frames.

    Returns
    -------
    FrameScan
    """
    options = ScanOptions() if options is None else options
    if options.mode != "depth":
        raise InputError(f"scan_frame scans with depth cameras; mode {options.mode!r} frames come "
                         "from remeshed_frame")
    frame_count, bounds, point_truth = _truth_frames(truth)
    if not 0 <= index < frame_count:
        raise InputError(f"frame index {index} is outside the truth's {frame_count} frames")
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    if rig is None:
        rig = camera_rig(
            bounds,
            options.cameras,
            distance=options.distance,
            elevation=options.elevation,
            first_angle=options.first_angle,
            field=options.field,
        )
    rng = np.random.default_rng([options.seed, index])
    vertices, faces = truth.frame(index)
    phase = index / max(frame_count - 1, 1)
    if point_truth:
        clean, camera, directions, hit = _visible_points(vertices, rig, options, rng)
    else:
        clean, camera, directions, hit = _cast(vertices, faces, rig, options, diagonal, phase)
    if len(clean) == 0:
        raise InputError(f"frame {index}: no camera ray hits the scene (nothing to scan)")
    colors = None
    if options.appearance is not None:
        colors = _point_colors(truth, index, options, vertices, faces, clean, directions, hit)
    points = clean + rng.normal(scale=options.noise * diagonal, size=(len(clean), 1)) * directions
    label = np.zeros(len(points), dtype=np.int8)
    count = len(points)
    uniform = int(round(options.outliers * count))
    clustered = int(round(options.structured_outliers * count))
    chosen = rng.permutation(count)[: uniform + clustered]
    lower, upper = bounds
    if uniform:
        picked = chosen[:uniform]
        points[picked] = rng.uniform(lower, upper, size=(uniform, 3))
        label[picked] = UNIFORM_OUTLIER
    if clustered:
        picked = chosen[uniform:]
        clusters = max(1, int(np.ceil(clustered / 50)))
        centres = rng.uniform(lower, upper, size=(clusters, 3))
        member = rng.integers(0, clusters, size=clustered)
        points[picked] = centres[member] + rng.normal(
            scale=options.cluster_size * diagonal, size=(clustered, 3)
        )
        label[picked] = CLUSTER_OUTLIER
    outlier = label != SURFACE
    camera = np.where(outlier, -1, camera)
    clean = np.where(outlier[:, None], points, clean)
    if colors is not None and outlier.any():
        stray = np.random.default_rng([options.seed, index, 3])
        colors[outlier] = stray.uniform(0.0, 1.0, size=(int(outlier.sum()), 3))
    return FrameScan(index, points, camera, label, clean, colors)


def remeshed_frame(truth, index: int, options: ScanOptions | None = None):
    """Truth frame ``index`` remeshed on its own (``mode="remeshed"``): a pure function of the
    frame, the options and the seed.

    The grid's cell edge is ``options.field * D / options.resolution`` (the rays' spacing at
    the rig's centre, ``D`` the truth's diagonal over all frames); its origin moves by a
    fraction of a cell drawn from ``default_rng([seed, index, 4])``, so two frames of the same
    pose are triangulated differently.

    Returns
    -------
    fourd.synth.remesh.Remeshed
        The mesh, with each vertex's truth triangle and barycentric coordinates.
    """
    from fourd.synth.remesh import remesh_surface

    options = ScanOptions() if options is None else options
    frame_count, bounds, point_truth = _truth_frames(truth)
    if point_truth:
        raise InputError("the remeshed scan mode needs a truth with faces (this one is points)")
    if not 0 <= index < frame_count:
        raise InputError(f"frame index {index} is outside the truth's {frame_count} frames")
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    offset = np.random.default_rng([options.seed, index, 4]).random(3)
    vertices, faces = truth.frame(index)
    return remesh_surface(
        vertices, faces, spacing=options.field * diagonal / options.resolution, offset=offset,
        seed=options.seed,
    )


def _point_colors(truth, index, options, vertices, faces, clean, directions, hit):
    """Recorded colours of the clean hits of one frame (see :mod:`fourd.synth.paint`)."""
    from fourd.geometry.normals import pca_normals, vertex_normals
    from fourd.synth.albedo import albedo
    from fourd.synth.paint import hit_colors, truth_paint
    from fourd.synth.shading import shaded_colors

    paint = truth_paint(truth, options.appearance, options.seed, lamps=studio_lamps(options.lighting))
    rng = np.random.default_rng([options.seed, index, 1])
    if len(faces):
        normals = vertex_normals(vertices, faces)
        return hit_colors(
            paint, vertices, faces, normals, hit, clean, directions, noise=options.color_noise, rng=rng
        )
    base = albedo(paint.rest[hit], paint.kind, bounds=paint.bounds, seed=paint.seed)
    normals = pca_normals(clean, min(16, len(clean))).normals
    normals[np.einsum("ij,ij->i", normals, directions) > 0] *= -1.0
    return shaded_colors(base, normals, noise=options.color_noise, rng=rng, lamps=paint.lamps)


def studio_lamps(lighting: str):
    """The :class:`~fourd.synth.shading.Lamps` of a ``lighting`` name (``ScanOptions``)."""
    from fourd.synth.shading import Lamps, diffuse_studio

    return diffuse_studio() if lighting == "diffuse" else Lamps()


def scan_options(options: ScanOptions | None = None, **overrides) -> ScanOptions:
    """A :class:`ScanOptions` from an options object and/or keyword overrides."""
    if options is not None and not isinstance(options, ScanOptions):
        raise InputError(f"options must be a ScanOptions, got {type(options).__name__}")
    from fourd.options import with_overrides

    return with_overrides(ScanOptions, options, what="scan", **overrides)


def scan(truth, options: ScanOptions | None = None, **overrides) -> PointCloudSequence:
    """Scan every frame of a ground truth with the virtual depth cameras.

    Parameters
    ----------
    truth : AnimatedMesh or MeshSequence
        Mesh truths are ray-cast; an AnimatedMesh without faces is a point truth (hidden-point
        removal).
    options : ScanOptions, optional
        All settings; keyword arguments (``cameras=3, resolution=256, noise=0.002,
        outliers=0.02, structured_outliers=0.0, drop_frames=(), occluder=False,
        hpr_fraction=0.3, appearance=None, video=False, seed=0`` and the other
        :class:`ScanOptions` fields) override it.

    Returns
    -------
    PointCloudSequence
        One frame per truth frame not in ``drop_frames``, with ``time = truth.times[t]`` and
        ``sensors`` = the camera positions ``[K, 3]``; named ``frame_<t>`` by truth index.
        With ``mode="remeshed"`` every frame is a mesh (``faces``; :func:`remeshed_frame`).
        With ``appearance`` the frames have ``colors``; with ``video`` the sequence has
        ``video`` (the rig's cameras, one image per camera and kept frame).

    Examples
    --------
    >>> from fourd.synth import scene, scan
    >>> scans = scan(scene("squash-ball", frames=2), resolution=64)
    >>> len(scans), scans[0].sensors.shape
    (2, (3, 3))
    """
    options = scan_options(options, **overrides)
    frame_count, bounds, _ = _truth_frames(truth)
    rig = camera_rig(
        bounds,
        options.cameras,
        distance=options.distance,
        elevation=options.elevation,
        first_angle=options.first_angle,
        field=options.field,
    )
    bad = [i for i in options.drop_frames if i >= frame_count]
    if bad:
        raise InputError(f"drop_frames {bad} are outside the truth's {frame_count} frames")
    kept = [t for t in range(frame_count) if t not in set(options.drop_frames)]
    if not kept:
        raise InputError("drop_frames removes every frame")
    frames, names, images = [], [], []
    if options.mode == "remeshed":
        for t in progress(kept, desc="remeshing", total=len(kept)):
            mesh = remeshed_frame(truth, t, options)
            frames.append(
                Frame(points=mesh.vertices, faces=mesh.faces, sensors=rig.positions, time=truth.times[t])
            )
            names.append(f"frame_{t:04d}")
        return PointCloudSequence(tuple(frames), tuple(names))
    for t in progress(kept, desc="scanning", total=len(kept)):
        result = scan_frame(truth, t, options, rig=rig)
        frames.append(
            Frame(
                points=result.points, colors=result.colors, sensors=rig.positions, time=truth.times[t]
            )
        )
        names.append(f"frame_{t:04d}")
        if options.video:
            from fourd.synth.filming import film_frame

            images.append(film_frame(truth, t, options, rig=rig))
    video = None
    if options.video:
        from fourd.io.video import Video
        from fourd.synth.filming import rig_cameras

        cameras = rig_cameras(rig, options.video_resolution or options.resolution)
        video = Video.from_arrays(cameras, np.stack(images, axis=1))
    return PointCloudSequence(tuple(frames), tuple(names), video)
