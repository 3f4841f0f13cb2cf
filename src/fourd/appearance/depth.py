"""A frame's points as one calibrated camera sees them: visibility, and pixels lifted to 3D.

:func:`splat_depth` z-buffers the points into the camera's image: each point covers the pixels
within ``radius`` pixels of its own (a disc of integer offsets), and each pixel keeps the
nearest depth and that point's index. :func:`frame_view` keeps the points the camera sees (at
most ``tolerance`` behind the z-buffer at their pixel). :func:`lift` puts a pixel back into 3D:
the ``k`` seen points that project nearest to it are fitted with a plane (PCA) and the pixel's
ray is cut with that plane. A lift is refused (NaN) where fewer than ``k`` points project
within ``reach`` pixels (holes, outside the silhouette), where the neighbours do not lie on one
plane within ``tolerance / 2`` (depth edges, where two surfaces meet in the image), where
the ray grazes the plane (less than about 6 degrees), or where the cut lies farther than
``tolerance`` from every neighbour (an extrapolation, near silhouettes). The plane averages the neighbours' noise,
so lifted points lie on the surface closer than the scan's own points do.

Depth is the camera-space ``z`` (:mod:`fourd.appearance.cameras`); lengths in input units.

Examples
--------
>>> from fourd.appearance.cameras import look_at, project
>>> cam = look_at("c", [0, 0, 5], [0, 0, 0], [0, 1, 0], focal=50, width=32, height=32)
>>> g = np.linspace(-1, 1, 80)
>>> x, y = np.meshgrid(g, g)
>>> plane = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
>>> float(splat_depth(cam, plane).depth[16, 16])
5.0
>>> view = frame_view(cam, plane, tolerance=0.1)
>>> uv, _ = project(cam, [[0.1, 0.2, 0.0]])
>>> lift(view, uv, tolerance=0.1).round(6).tolist()
[[0.1, 0.2, 0.0]]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.appearance.cameras import Camera, in_image, project, rays
from fourd.errors import InputError

#: Smallest ``|cos|`` between a lifted ray and the fitted plane's normal.
GRAZING = 0.1


class DepthMap(NamedTuple):
    """A z-buffer of points in one camera.

    Attributes
    ----------
    depth : ndarray float64 [H, W]
        Nearest camera-space depth per pixel; ``inf`` where no point falls.
    index : ndarray int64 [H, W]
        Index of that point into the splatted points; -1 where empty.
    """

    depth: np.ndarray
    index: np.ndarray


class FrameView(NamedTuple):
    """The points of one frame that one camera sees.

    Attributes
    ----------
    camera : Camera
    points : ndarray float64 [V, 3]
        The seen points.
    uv : ndarray float64 [V, 2]
        Their pixel coordinates.
    index : ndarray int64 [V]
        Their indices into the frame's points.
    tree : scipy.spatial.cKDTree
        Over ``uv``.
    depth : DepthMap
        The z-buffer of all the frame's points.
    """

    camera: Camera
    points: np.ndarray
    uv: np.ndarray
    index: np.ndarray
    tree: cKDTree
    depth: DepthMap


def _offsets(radius: float) -> np.ndarray:
    reach = int(np.floor(radius))
    dy, dx = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    keep = dx**2 + dy**2 <= radius**2 + 1e-9
    return np.stack([dy[keep], dx[keep]], axis=1)


def splat_depth(camera: Camera, points, *, radius: float = 1.0) -> DepthMap:
    """Z-buffer ``points [P, 3]`` into ``camera``'s image; each covers the pixels whose centres
    lie within ``radius`` pixels (integer offsets) of its nearest pixel centre."""
    if not radius >= 0:
        raise InputError(f"splat radius must be >= 0, got {radius!r}")
    uv, z = project(camera, points)
    height, width = camera.height, camera.width
    front = np.flatnonzero(in_image(camera, uv) & (z > 0))
    front = front[np.argsort(z[front], kind="stable")]  # nearest first
    centre = np.rint(uv[front]).astype(np.int64)
    offsets = _offsets(radius)
    # [P, O] candidates, point-major so that a nearer point's pixels come first
    i = (centre[:, 1][:, None] + offsets[:, 0][None, :]).ravel()
    j = (centre[:, 0][:, None] + offsets[:, 1][None, :]).ravel()
    owner = np.repeat(front, len(offsets))
    inside = (i >= 0) & (i < height) & (j >= 0) & (j < width)
    pixel = (i * width + j)[inside]
    owner = owner[inside]
    _, first = np.unique(pixel, return_index=True)  # the first, so the nearest, per pixel
    depth_map = np.full(height * width, np.inf)
    index_map = np.full(height * width, -1, dtype=np.int64)
    depth_map[pixel[first]] = z[owner[first]]
    index_map[pixel[first]] = owner[first]
    return DepthMap(depth_map.reshape(height, width), index_map.reshape(height, width))


def visible_points(camera: Camera, depth_map: DepthMap, points, *, tolerance: float) -> np.ndarray:
    """Which ``points [P, 3]`` the camera sees: in the image, in front, and at most
    ``tolerance`` (input units) behind the depth map at their nearest pixel; bool ``[P]``."""
    uv, z = project(camera, points)
    seen = in_image(camera, uv) & (z > 0)
    at = np.flatnonzero(seen)
    pixel = np.rint(uv[at]).astype(np.int64)
    i = np.clip(pixel[:, 1], 0, camera.height - 1)
    j = np.clip(pixel[:, 0], 0, camera.width - 1)
    seen[at] = z[at] <= depth_map.depth[i, j] + tolerance
    return seen


def frame_view(camera: Camera, points, *, tolerance: float, radius: float = 1.0) -> FrameView:
    """The points of a frame that ``camera`` sees (:func:`visible_points` on the z-buffer of
    splat ``radius`` pixels), ready for :func:`lift`."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    depth_map = splat_depth(camera, points, radius=radius)
    index = np.flatnonzero(visible_points(camera, depth_map, points, tolerance=tolerance))
    uv, _ = project(camera, points[index])
    return FrameView(camera, points[index], uv, index, cKDTree(uv), depth_map)


def lift(view: FrameView, uv, *, tolerance: float, k: int = 8, reach: float = 3.0) -> np.ndarray:
    """3D points ``[P, 3]`` of pixel positions ``uv [P, 2]`` on the surface ``view`` sees (see
    the module docstring); NaN rows where refused.

    Parameters
    ----------
    view : FrameView
    uv : array [P, 2]
    tolerance : float
        Neighbours farther than ``tolerance / 2`` from their fitted plane, or a cut farther
        than ``tolerance`` from all of them, refuse the lift.
    k : int
        Neighbours fitted (at least 3).
    reach : float
        Largest pixel distance of a neighbour.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    result = np.full((len(uv), 3), np.nan)
    if len(view.points) < k or not len(uv):
        return result
    finite = np.flatnonzero(np.isfinite(uv).all(axis=1))
    distance, neighbour = view.tree.query(uv[finite], k=k, distance_upper_bound=reach)
    full = np.isfinite(distance).all(axis=1)
    at = finite[full]
    near = view.points[neighbour[full]]  # [Q, k, 3]
    centroid = near.mean(axis=1)
    spread = near - centroid[:, None, :]
    _, vectors = np.linalg.eigh(spread.transpose(0, 2, 1) @ spread)
    normal = vectors[:, :, 0]
    flat = np.abs(spread @ normal[:, :, None])[:, :, 0].max(axis=1) <= 0.5 * tolerance
    origin = view.camera.center
    direction = rays(view.camera, uv[at])
    cosine = np.einsum("qj,qj->q", direction, normal)
    good = flat & (np.abs(cosine) >= GRAZING)
    step = np.einsum("qj,qj->q", centroid - origin, normal)[good] / cosine[good]
    lifted = origin + step[:, None] * direction[good]
    gap = np.linalg.norm(near[good] - lifted[:, None, :], axis=2).min(axis=1)
    close = gap <= tolerance
    result[at[good][close]] = lifted[close]
    return result
