"""Dense optical flow between two images of one camera, and its forward-backward check.

The flow is OpenCV's: DIS (Kroeger et al., "Fast Optical Flow using Dense Inverse Search",
ECCV 2016; ``cv2.DISOpticalFlow_create``) by default, or Farneback's polynomial expansion
(``cv2.calcOpticalFlowFarneback``). Both run on 8-bit grey images. ``flow[i, j] = (du, dv)``
moves pixel ``(u, v) = (j, i)`` of the first image to ``(u + du, v + dv)`` in the second
(pixel centres at integers, :mod:`fourd.appearance.cameras`).

The forward-backward check (Popa 2009, thesis section 5.4.1, "optical flow pruning in 2D"):
a point sent forward with the forward flow and back with the backward flow must return within
``epsilon`` pixels of where it started; the distance it misses by is its forward-backward
error. Occlusions and flow errors make it large.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> texture = (rng.random((24, 24)) * 255).astype(np.uint8)
>>> import cv2
>>> first = cv2.resize(texture, (96, 96), interpolation=cv2.INTER_CUBIC)
>>> second = np.roll(first, 3, axis=1)                # everything moves 3 pixels right
>>> flow = optical_flow(first, second)
>>> [round(float(x), 1) + 0.0 for x in np.median(flow[20:76, 20:76], axis=(0, 1))]
[3.0, 0.0]
"""

from __future__ import annotations

import numpy as np

from fourd.errors import InputError

#: Flow methods.
FLOW_METHODS = ("dis", "farneback")
#: DIS presets, fastest to most accurate.
DIS_PRESETS = ("ultrafast", "fast", "medium")


def _cv2():
    try:
        import cv2
    except ImportError:  # pragma: no cover - a core dependency
        raise InputError(
            "optical flow needs OpenCV: pip install opencv-python-headless"
        ) from None
    return cv2


def gray(image) -> np.ndarray:
    """An 8-bit grey image ``[H, W]`` from an RGB ``[H, W, 3]`` (or grey) uint8 image."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise InputError(f"images must be uint8, got {image.dtype}")
    if image.ndim == 2:
        return np.ascontiguousarray(image)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise InputError(f"an image must be [H, W] or [H, W, 3], got {list(image.shape)}")
    return _cv2().cvtColor(np.ascontiguousarray(image[:, :, :3]), _cv2().COLOR_RGB2GRAY)


def optical_flow(first, second, *, method: str = "dis", preset: str = "medium") -> np.ndarray:
    """Dense flow from ``first`` to ``second`` (uint8 RGB or grey images of one size).

    Parameters
    ----------
    first, second : ndarray uint8 [H, W, 3] or [H, W]
    method : {"dis", "farneback"}
    preset : {"ultrafast", "fast", "medium"}
        DIS preset (ignored by Farneback).

    Returns
    -------
    ndarray float32 [H, W, 2]
        Displacement ``(du, dv)`` in pixels of each pixel of ``first``.
    """
    cv2 = _cv2()
    if method not in FLOW_METHODS:
        raise InputError(f"unknown flow method {method!r}; choose one of {', '.join(FLOW_METHODS)}")
    a, b = gray(first), gray(second)
    if a.shape != b.shape:
        raise InputError(f"flow between images of different sizes {a.shape} and {b.shape}")
    if method == "farneback":
        return cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 4, 15, 5, 5, 1.1, 0)
    if preset not in DIS_PRESETS:
        raise InputError(f"unknown DIS preset {preset!r}; choose one of {', '.join(DIS_PRESETS)}")
    code = {
        "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
        "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
        "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
    }[preset]
    dis = cv2.DISOpticalFlow_create(code)
    return dis.calc(a, b, None)


def sample_flow(flow, uv, *, channels: int = 2) -> np.ndarray:
    """The flow ``[H, W, 2]`` at sub-pixel positions ``uv [P, 2]`` (bilinear between pixel
    centres, clamped at the border); ``[P, 2]``."""
    from scipy.ndimage import map_coordinates

    flow = np.asarray(flow, dtype=np.float64)
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    coords = np.stack([uv[:, 1], uv[:, 0]])
    return np.stack(
        [map_coordinates(flow[:, :, k], coords, order=1, mode="nearest") for k in range(channels)],
        axis=1,
    ).reshape(len(uv), channels)


def sample_image(image, uv) -> np.ndarray:
    """Colours ``[P, C]`` (floats in [0, 1]) of a uint8 image ``[H, W, C]`` (or ``[H, W]``) at
    sub-pixel positions ``uv [P, 2]``, bilinear between pixel centres, clamped at the border."""
    image = np.asarray(image)
    planes = image[:, :, None] if image.ndim == 2 else image
    return sample_flow(planes.astype(np.float64) / 255.0, uv, channels=planes.shape[2])


def forward_backward(forward, backward, uv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Send ``uv [P, 2]`` forward and back.

    Parameters
    ----------
    forward : ndarray [H, W, 2]
        Flow from image 0 to image 1.
    backward : ndarray [H, W, 2]
        Flow from image 1 to image 0.
    uv : array [P, 2]
        Positions in image 0.

    Returns
    -------
    moved : ndarray [P, 2]
        Positions in image 1 (``uv + forward(uv)``).
    returned : ndarray [P, 2]
        Back in image 0 (``moved + backward(moved)``).
    error : ndarray [P]
        ``|returned - uv|``, pixels.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    moved = uv + sample_flow(forward, uv)
    returned = moved + sample_flow(backward, moved)
    return moved, returned, np.linalg.norm(returned - uv, axis=1)
