"""Calibrated pinhole cameras: the model, projection, back-projection and ``cameras.json``.

The convention is OpenCV's: a camera maps a world point ``x`` to camera coordinates
``x_cam = R x + t`` (``R`` a rotation, world to camera), looks along ``+z``, and the pixel is
``(u, v) = (fx x/z + cx, fy y/z + cy)`` with ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]``:
``u`` to the right, ``v`` down, row 0 at the top, pixel centres at integer coordinates (pixel
``(i, j)``, row ``i``, column ``j``, is centred at ``(u, v) = (j, i)`` and covers
``[j - 0.5, j + 0.5) x [i - 0.5, i + 0.5)``). Depth is the camera-space ``z`` (not the distance
along the ray). Lens distortion is not modelled: undistort images before giving them to fourd.

The file ``cameras.json`` beside the frames holds::

    {"cameras": [{"name": "cam_0", "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
                  "R": [[...], [...], [...]], "t": [tx, ty, tz],
                  "width": W, "height": H}, ...]}

Examples
--------
>>> cam = Camera("c", K=[[100, 0, 31.5], [0, 100, 23.5], [0, 0, 1]], R=np.eye(3), t=[0, 0, 2],
...              width=64, height=48)
>>> uv, depth = project(cam, [[0.0, 0.0, 0.0], [0.1, -0.2, 0.0]])
>>> uv.round(3).tolist(), depth.tolist()
([[31.5, 23.5], [36.5, 13.5]], [2.0, 2.0])
>>> unproject(cam, uv, depth).round(6).tolist()
[[0.0, 0.0, 0.0], [0.1, -0.2, 0.0]]
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fourd.errors import InputError

logger = logging.getLogger("fourd.appearance.cameras")

#: The calibration file's name in an input folder.
CAMERAS_FILE = "cameras.json"

#: How far ``R`` may be from a rotation (``|R R^T - I|`` max entry) before it is refused.
ROTATION_TOLERANCE = 1e-4


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated pinhole camera (OpenCV convention, see the module docstring).

    Attributes
    ----------
    name : str
        The camera's name (its folder under ``video/``).
    K : ndarray float64 [3, 3]
        Intrinsics, pixels: ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, ``fx, fy > 0``.
    R : ndarray float64 [3, 3]
        World-to-camera rotation (orthonormal, determinant +1).
    t : ndarray float64 [3]
        World-to-camera translation, input units (``x_cam = R x + t``).
    width, height : int
        Image size in pixels.
    """

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int

    def __post_init__(self):
        name = str(self.name)
        if not name or name != name.strip() or "/" in name or "\\" in name or name in (".", ".."):
            raise InputError(f"camera name {self.name!r} cannot name a folder")
        object.__setattr__(self, "name", name)
        for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            try:
                value = np.array(getattr(self, key), dtype=np.float64)
            except (TypeError, ValueError):
                raise InputError(f"camera {name}: {key} is not numeric") from None
            if value.shape != shape:
                raise InputError(
                    f"camera {name}: {key} must have shape {list(shape)}, got {list(value.shape)}"
                )
            if not np.isfinite(value).all():
                raise InputError(f"camera {name}: {key} holds NaN or infinite values")
            value.setflags(write=False)
            object.__setattr__(self, key, value)
        K = self.K
        if K[0, 0] <= 0 or K[1, 1] <= 0 or K[1, 0] or K[2, 0] or K[2, 1] or K[2, 2] != 1:
            raise InputError(
                f"camera {name}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0"
            )
        R = self.R
        if np.abs(R @ R.T - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
            raise InputError(f"camera {name}: R is not a rotation (orthonormal, determinant +1)")
        for key in ("width", "height"):
            value = getattr(self, key)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise InputError(f"camera {name}: {key} must be a positive integer, got {value!r}")
            object.__setattr__(self, key, int(value))

    @property
    def center(self) -> np.ndarray:
        """The camera's centre in world coordinates, ``-R^T t`` [3]."""
        return -self.R.T @ self.t

    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction (the camera's +z) in world coordinates [3]."""
        return self.R[2].copy()


def project(camera: Camera, points) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates and depth of world points.

    Parameters
    ----------
    camera : Camera
    points : array [P, 3]
        World points, input units.

    Returns
    -------
    uv : ndarray float64 [P, 2]
        ``(u, v)``: column and row, pixel centres at integers; NaN for points at or behind the
        camera (``depth <= 0``).
    depth : ndarray float64 [P]
        Camera-space ``z`` (input units).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    local = points @ camera.R.T + camera.t
    depth = local[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        normalised = local[:, :2] / depth[:, None]
    uv = normalised @ camera.K[:2, :2].T + camera.K[:2, 2]
    uv[depth <= 0] = np.nan
    return uv, depth


def rays(camera: Camera, uv) -> np.ndarray:
    """Unit world directions of the rays through pixel coordinates ``uv [P, 2]``; ``[P, 3]``."""
    local = _normalised(camera, uv)
    directions = local @ camera.R  # R^T applied to each row
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


def _normalised(camera: Camera, uv) -> np.ndarray:
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    K = camera.K
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return np.stack([x, y, np.ones(len(uv))], axis=1)


def unproject(camera: Camera, uv, depth) -> np.ndarray:
    """World points at pixel coordinates ``uv [P, 2]`` and camera-space depth ``depth [P]``.

    The inverse of :func:`project`: ``unproject(c, *project(c, x)) == x`` for points in front
    of the camera. Returns ``[P, 3]``, input units.
    """
    depth = np.asarray(depth, dtype=np.float64).reshape(-1)
    local = _normalised(camera, uv) * depth[:, None]
    return (local - camera.t) @ camera.R


def in_image(camera: Camera, uv) -> np.ndarray:
    """Which pixel coordinates ``uv [P, 2]`` fall inside the image (pixel areas), bool [P]."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    with np.errstate(invalid="ignore"):
        return (
            (uv[:, 0] >= -0.5)
            & (uv[:, 0] < camera.width - 0.5)
            & (uv[:, 1] >= -0.5)
            & (uv[:, 1] < camera.height - 0.5)
        )


def look_at(
    name: str, position, target, up, *, focal: float, width: int, height: int
) -> Camera:
    """A camera at ``position`` looking at ``target`` with image ``up`` (world vector) pointing
    to the top of the image; ``focal`` in pixels, principal point at the image centre
    (``((width - 1) / 2, (height - 1) / 2)``)."""
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    norm = np.linalg.norm(right)
    if norm < 1e-9:
        raise InputError(f"camera {name}: up is parallel to the viewing direction")
    right /= norm
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    K = np.array([[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0], [0, 0, 1]])
    return Camera(name, K, R, -R @ position, width, height)


# ----------------------------------------------------------------------------- cameras.json


def cameras_to_json(cameras) -> dict:
    """The ``cameras.json`` content of a list of cameras (plain JSON types)."""
    return {
        "cameras": [
            {
                "name": c.name,
                "K": c.K.tolist(),
                "R": c.R.tolist(),
                "t": c.t.tolist(),
                "width": c.width,
                "height": c.height,
            }
            for c in cameras
        ]
    }


def cameras_from_json(data, path: str | os.PathLike | None = None) -> tuple[Camera, ...]:
    """Cameras from parsed ``cameras.json`` content; InputError naming ``path`` when wrong."""
    if not isinstance(data, dict) or not isinstance(data.get("cameras"), list):
        raise InputError('expected {"cameras": [{"name", "K", "R", "t", "width", "height"}, ...]}', path)
    entries = data["cameras"]
    if not entries:
        raise InputError('"cameras" is empty', path)
    cameras = []
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise InputError(f"camera {i} is not an object", path)
        missing = [k for k in ("name", "K", "R", "t", "width", "height") if k not in entry]
        if missing:
            raise InputError(f"camera {i} lacks {', '.join(missing)}", path)
        try:
            cameras.append(
                Camera(
                    entry["name"], entry["K"], entry["R"], entry["t"], entry["width"], entry["height"]
                )
            )
        except InputError as error:
            raise InputError(f"camera {i}: {error.problem}", path) from None
        except (TypeError, ValueError) as error:
            raise InputError(f"camera {i}: {error}", path) from None
    names = [c.name for c in cameras]
    duplicate = sorted({n for n in names if names.count(n) > 1})
    if duplicate:
        raise InputError(f"camera names repeat: {', '.join(duplicate)}", path)
    return tuple(cameras)


def read_cameras(path: str | os.PathLike) -> tuple[Camera, ...]:
    """Read ``cameras.json`` (see the module docstring); InputError naming the file when bad."""
    from fourd.io.meshfiles import read_text

    path = Path(path)
    try:
        data = json.loads(read_text(path))
    except json.JSONDecodeError as error:
        raise InputError(f"is not valid JSON ({error.msg} at line {error.lineno})", path) from None
    return cameras_from_json(data, path)


def write_cameras(path: str | os.PathLike, cameras) -> None:
    """Write ``cameras.json`` atomically."""
    from fourd.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(cameras_to_json(cameras), indent=1) + "\n")
