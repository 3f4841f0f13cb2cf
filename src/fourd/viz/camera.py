"""The pinhole camera of the software renderer: where it stands, where it looks, and one that
frames given bounds (:func:`fit_camera`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fourd.errors import InputError


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera looking from ``eye`` at ``target``; ``fov`` is vertical, degrees."""

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray | tuple = (0.0, 1.0, 0.0)
    fov: float = 30.0

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (3,) or not np.isfinite(value).all():
                raise InputError(f"camera {name} must be 3 finite numbers, got {value!r}")
            object.__setattr__(self, name, value)
        if not 1.0 <= self.fov <= 170.0:
            raise InputError(f"camera fov must be in [1, 170] degrees, got {self.fov}")
        if np.linalg.norm(self.target - self.eye) == 0:
            raise InputError("camera eye and target coincide")

    def basis(self) -> np.ndarray:
        """Rows: right, up, forward (unit vectors, world coordinates)."""
        forward = self.target - self.eye
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        if np.linalg.norm(right) < 1e-9:  # looking along up: pick any perpendicular
            right = np.cross(forward, [1.0, 0.0, 0.0])
        right = right / np.linalg.norm(right)
        return np.stack([right, np.cross(right, forward), forward])

    def project(self, points: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates ``[M, 2]`` (x right, y down, pixel centres at +0.5) and depth ``[M]``
        (distance along the view axis; <= 0 behind the camera)."""
        local = (np.asarray(points, dtype=np.float64) - self.eye) @ self.basis().T
        depth = local[:, 2]
        focal = 0.5 * height / math.tan(math.radians(self.fov) * 0.5)
        safe = np.where(depth > 1e-12, depth, 1e-12)
        xy = np.empty((len(local), 2))
        xy[:, 0] = 0.5 * width + focal * local[:, 0] / safe
        xy[:, 1] = 0.5 * height - focal * local[:, 1] / safe
        return xy, depth

    def orbit(self, degrees: float) -> Camera:
        """The camera turned by ``degrees`` about the vertical axis through the target."""
        a = math.radians(degrees)
        c, s = math.cos(a), math.sin(a)
        rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        return Camera(self.target + rot @ (self.eye - self.target), self.target, self.up, self.fov)


def fit_camera(
    bounds: np.ndarray,
    *,
    azimuth: float = 35.0,
    elevation: float = 20.0,
    fov: float = 30.0,
    aspect: float = 1.0,
    margin: float = 1.05,
) -> Camera:
    """A 3/4 view (Y up) that keeps the box ``bounds [2, 3]`` in the picture from any angle.

    ``azimuth`` turns from +Z towards +X, ``elevation`` lifts above the XZ plane (degrees).
    The camera is the nearest (along the view direction) at which all eight corners of the box
    project inside the picture, shrunk by ``margin``; a fixed camera from the bounds of a
    whole sequence keeps every frame in view.
    """
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or not np.isfinite(bounds).all():
        raise InputError(f"bounds must be finite with shape [2, 3], got {list(bounds.shape)}")
    if not (aspect > 0 and 1.0 <= fov <= 170.0 and margin > 0):
        raise InputError(
            f"need aspect > 0, fov in [1, 170], margin > 0; got {aspect}, {fov}, {margin}"
        )
    center = bounds.mean(axis=0)
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
    radius = radius if radius > 0 else 1.0
    half = math.radians(fov) * 0.5
    half = min(half, math.atan(math.tan(half) * aspect))
    distance = margin * radius / math.sin(half)
    az, el = math.radians(azimuth), math.radians(elevation)
    direction = np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    camera = Camera(center + distance * direction, center, np.array([0.0, 1.0, 0.0]), fov)
    # Tighten: the nearest distance (bisection) at which the projected box corners still fit.
    corners = np.array(
        [[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    tan_v = math.tan(math.radians(fov) * 0.5)
    basis = camera.basis()

    def fits(d):
        local = (corners - (center + d * direction)) @ basis.T
        if local[:, 2].min() <= 1e-6 * distance:
            return False
        extent = max(
            np.abs(local[:, 0] / local[:, 2]).max() / (tan_v * aspect),
            np.abs(local[:, 1] / local[:, 2]).max() / tan_v,
        )
        return extent * margin <= 1.0

    lo_d, hi_d = 0.0, distance
    for _ in range(30):
        mid = 0.5 * (lo_d + hi_d)
        lo_d, hi_d = (lo_d, mid) if fits(mid) else (mid, hi_d)
    camera = Camera(center + hi_d * direction, center, camera.up, fov)
    return camera
