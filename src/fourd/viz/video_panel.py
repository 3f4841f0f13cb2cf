"""The viewer's video panel: the input's camera images, downscaled and inlined as JPEG.

Each camera of the input's :class:`~fourd.io.video.Video` gets one image per result frame (the
input frame the viewer shows beside it), its longest side at most ``size`` pixels (never
enlarged), JPEG-encoded (Pillow, quality :data:`JPEG_QUALITY`) as a ``data:`` URL, so that the
page stays one self-contained file. The camera's calibration (``K``, ``R``, ``t`` in
:mod:`fourd.appearance.cameras`' convention, at the original size) goes with it: the page
projects the mesh with it to draw its outline over the image, scaling pixel coordinates by
``shownWidth / width`` and ``shownHeight / height``.

Examples
--------
>>> from fourd.appearance.cameras import look_at
>>> from fourd.io.video import Video
>>> cam = look_at("front", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=40, width=64, height=48)
>>> video = Video.from_arrays((cam,), np.zeros((1, 2, 48, 64, 3), np.uint8))
>>> panel = video_panel(video, [0, 1, 1], size=32)
>>> front = panel["cameras"][0]
>>> (front["shownWidth"], front["shownHeight"]), len(front["images"]), panel["downscaled"]
((32, 24), 3, True)
"""

from __future__ import annotations

import base64
import io
import logging

import numpy as np

from fourd.errors import InputError

log = logging.getLogger("fourd.viz.video_panel")

#: Default longest side, in pixels, of the images inlined into the page (``fourd view
#: --video-size``).
VIDEO_SIZE = 480

#: Smallest ``size`` accepted, pixels.
MIN_VIDEO_SIZE = 16

#: JPEG quality of the inlined images (Pillow's scale, 1-95).
JPEG_QUALITY = 85

#: Above this many bytes of inlined images the page is slow to open: a warning suggests a
#: smaller ``--video-size``.
VIDEO_BYTES_WARNING = 64_000_000


def shown_size(width: int, height: int, size: int) -> tuple[int, int]:
    """``(width, height)`` scaled so that the longest side is at most ``size`` pixels (never
    enlarged; each side at least 1)."""
    scale = min(1.0, size / max(width, height))
    return max(1, round(width * scale)), max(1, round(height * scale))


def jpeg_data_url(image: np.ndarray, shape: tuple[int, int]) -> str:
    """``image`` (uint8 ``[H, W, 3]``) resized to ``shape = (width, height)`` (Lanczos) as a
    ``data:image/jpeg;base64,...`` URL."""
    from PIL import Image

    picture = Image.fromarray(np.asarray(image, dtype=np.uint8))
    if picture.size != tuple(shape):
        picture = picture.resize(tuple(shape), Image.Resampling.LANCZOS)
    buffer = io.BytesIO()
    picture.save(buffer, format="JPEG", quality=JPEG_QUALITY)
    return "data:image/jpeg;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def video_panel(video, frames, *, size: int = VIDEO_SIZE) -> dict:
    """The page's ``video`` entry: per camera its calibration and one image per result frame.

    Parameters
    ----------
    video : fourd.io.video.Video
    frames : sequence of int [T]
        For each result frame, the video frame to show beside it (an image used twice is
        encoded once).
    size : int
        Longest side of the inlined images, pixels (at least :data:`MIN_VIDEO_SIZE`); larger
        images are downscaled, smaller ones kept as they are.

    Returns
    -------
    dict
        ``{"size", "downscaled", "cameras": [{"name", "width", "height", "shownWidth",
        "shownHeight", "K", "R", "t", "images": [data URL per result frame]}]}``; ``width``,
        ``height`` and ``K`` are the camera's own (the original images).
    """
    if isinstance(size, bool) or int(size) != size or size < MIN_VIDEO_SIZE:
        raise InputError(f"the video size must be an integer >= {MIN_VIDEO_SIZE} pixels, got {size!r}")
    frames = [int(t) for t in frames]
    cameras, total, downscaled = [], 0, False
    for c, camera in enumerate(video.cameras):
        shape = shown_size(camera.width, camera.height, int(size))
        downscaled |= shape != (camera.width, camera.height)
        encoded: dict[int, str] = {}
        for t in dict.fromkeys(frames):
            encoded[t] = jpeg_data_url(video.image(c, t), shape)
            total += len(encoded[t])
        cameras.append(
            {
                "name": camera.name,
                "width": camera.width,
                "height": camera.height,
                "shownWidth": shape[0],
                "shownHeight": shape[1],
                "K": camera.K.tolist(),
                "R": camera.R.tolist(),
                "t": camera.t.tolist(),
                "images": [encoded[t] for t in frames],
            }
        )
    if total > VIDEO_BYTES_WARNING:
        log.warning(
            "the video panel inlines %.0f MB of images: the page will be slow to open "
            "(a smaller --video-size, now %d, makes it lighter)",
            total / 1e6,
            size,
        )
    return {"size": int(size), "downscaled": downscaled, "cameras": cameras}
