"""Calibrated multi-view video beside the frames: ``cameras.json`` + ``video/<camera>/<frame>``.

Layout of an input folder with video (the camera convention is in
:mod:`fourd.appearance.cameras`)::

    scans/
      frame_0000.ply ...         the frames
      cameras.json               {"cameras": [{"name": "cam_0", "K", "R", "t", "width", "height"}, ...]}
      video/cam_0/0000.png ...   one image per frame, natural-sort order (PNG or JPEG)
      video/cam_1/...

Images stay on disk: :func:`read_video` checks that every camera has one image per frame and
that each image's header gives the size ``cameras.json`` states (reading the header only), and
:meth:`Video.image` decodes one image when it is asked for. An image that turns out corrupt
when decoded raises :class:`~fourd.errors.InputError` naming it then.

Examples
--------
>>> import tempfile
>>> from fourd.appearance.cameras import look_at
>>> cam = look_at("front", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=40, width=32, height=24)
>>> images = np.zeros((1, 2, 24, 32, 3), np.uint8)
>>> with tempfile.TemporaryDirectory() as folder:
...     write_video(folder, Video.from_arrays((cam,), images))
...     video = read_video(folder, frame_count=2)
...     video.frame_count, video.names, video.image("front", 1).shape
(2, ('front',), (24, 32, 3))
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fourd.appearance.cameras import CAMERAS_FILE, Camera, read_cameras, write_cameras
from fourd.errors import InputError

logger = logging.getLogger("fourd.io.video")

#: The folder of the images, beside ``cameras.json``.
VIDEO_FOLDER = "video"
#: Image file extensions read (lower case).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True, eq=False)
class Video:
    """The cameras of a capture and one image per camera and frame.

    Attributes
    ----------
    cameras : tuple of Camera
    images : tuple of tuple
        ``images[c][t]``: camera ``c``'s image of frame ``t``, either a path (decoded when asked
        for) or a uint8 array ``[height, width, 3]`` held in memory.
    """

    cameras: tuple[Camera, ...]
    images: tuple[tuple, ...]

    def __post_init__(self):
        cameras = tuple(self.cameras)
        images = tuple(tuple(row) for row in self.images)
        if not cameras:
            raise InputError("the video has no cameras")
        if not all(isinstance(c, Camera) for c in cameras):
            raise InputError("video cameras must be fourd.appearance.cameras.Camera objects")
        if len(images) != len(cameras):
            raise InputError(f"{len(images)} image lists for {len(cameras)} cameras")
        counts = {len(row) for row in images}
        if len(counts) != 1:
            raise InputError(f"cameras have different numbers of images: {sorted(counts)}")
        if 0 in counts:
            raise InputError("the video has no frames")
        object.__setattr__(self, "cameras", cameras)
        object.__setattr__(self, "images", images)

    @classmethod
    def from_arrays(cls, cameras, images) -> Video:
        """A video held in memory: ``images`` uint8 ``[C, T, H, W, 3]`` (or a list of per-camera
        lists of ``[H, W, 3]`` arrays), checked against the cameras' sizes."""
        cameras = tuple(cameras)
        rows = []
        for c, camera in enumerate(cameras):
            row = []
            for t, image in enumerate(images[c]):
                row.append(_checked(np.asarray(image), camera, f"camera {camera.name} frame {t}"))
            rows.append(tuple(row))
        return cls(cameras, tuple(rows))

    @property
    def frame_count(self) -> int:
        return len(self.images[0])

    @property
    def names(self) -> tuple[str, ...]:
        """Camera names, in order."""
        return tuple(c.name for c in self.cameras)

    def camera_index(self, camera: int | str) -> int:
        """Index of ``camera`` (an index or a name)."""
        if isinstance(camera, str):
            if camera not in self.names:
                raise InputError(f"no camera named {camera!r}; cameras: {', '.join(self.names)}")
            return self.names.index(camera)
        index = int(camera)
        if not 0 <= index < len(self.cameras):
            raise InputError(f"camera index {camera} outside 0..{len(self.cameras) - 1}")
        return index

    def image(self, camera: int | str, frame: int) -> np.ndarray:
        """Camera ``camera``'s (index or name) image of frame ``frame``: uint8 ``[H, W, 3]``
        (RGB, row 0 at the top); decoded from disk on each call when the video is a folder."""
        c = self.camera_index(camera)
        if not -self.frame_count <= int(frame) < self.frame_count:
            raise InputError(f"frame {frame} outside the video's {self.frame_count} frames")
        item = self.images[c][int(frame)]
        if isinstance(item, np.ndarray):
            return item
        return read_image(item, self.cameras[c])

    def select(self, index: slice) -> Video:
        """The frames ``index`` (a slice) of every camera."""
        return Video(self.cameras, tuple(row[index] for row in self.images))

    def fingerprint(self) -> tuple:
        """What identifies the video for a cache key (:func:`fourd.cache.stage_key`): the
        cameras, and every image held in memory or its file's path, size and modification
        time (a folder's images are not read for it)."""
        images = []
        for row in self.images:
            for item in row:
                if isinstance(item, np.ndarray):
                    images.append(item)
                else:
                    stat = os.stat(item)
                    images.append((str(item), stat.st_size, stat.st_mtime_ns))
        cameras = [(c.name, c.K, c.R, c.t, c.width, c.height) for c in self.cameras]
        return (cameras, images)


def _checked(image: np.ndarray, camera: Camera, where) -> np.ndarray:
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise InputError(f"{where}: an image must be [H, W, 3], got {list(image.shape)}")
    if image.shape[:2] != (camera.height, camera.width):
        raise InputError(
            f"{where}: the image is {image.shape[1]}x{image.shape[0]} but {CAMERAS_FILE} says "
            f"{camera.width}x{camera.height} for camera {camera.name}"
        )
    if image.dtype != np.uint8:
        if np.issubdtype(image.dtype, np.floating) and image.size and 0 <= image.min() and image.max() <= 1:
            image = np.round(image * 255.0)
        else:
            raise InputError(f"{where}: images must be uint8 (or floats in [0, 1]), got {image.dtype}")
    image = np.ascontiguousarray(image[:, :, :3], dtype=np.uint8)
    image.setflags(write=False)
    return image


def _open(path: Path):
    from PIL import Image, UnidentifiedImageError

    try:
        return Image.open(path)
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except UnidentifiedImageError:
        raise InputError("is not a readable image", path) from None
    except OSError as error:
        raise InputError(f"cannot be read ({error.strerror or error})", path) from None


def read_image(path: str | os.PathLike, camera: Camera | None = None) -> np.ndarray:
    """Decode one image as uint8 RGB ``[H, W, 3]``, its size checked against ``camera``."""
    path = Path(path)
    image = _open(path)
    try:
        with image:
            if camera is not None and image.size != (camera.width, camera.height):
                raise InputError(_size_problem(image.size, camera), path)
            array = np.asarray(image.convert("RGB"))
    except InputError:
        raise
    except (OSError, ValueError, SyntaxError) as error:  # truncated or corrupt data
        raise InputError(f"is not a readable image ({error})", path) from None
    return array


def _size_problem(size, camera: Camera) -> str:
    return (
        f"the image is {size[0]}x{size[1]} but {CAMERAS_FILE} says {camera.width}x{camera.height} "
        f"for camera {camera.name}"
    )


def _image_files(folder: Path) -> list[Path]:
    from fourd.io.frames import natural_key

    files = [
        p
        for p in folder.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES
    ]
    return sorted(files, key=lambda p: natural_key(p.name))


def read_video(folder: str | os.PathLike, *, frame_count: int | None = None) -> Video:
    """The video of an input folder: ``cameras.json`` and ``video/<camera>/`` (lazy images).

    Parameters
    ----------
    folder : path-like
        The input folder holding ``cameras.json`` and ``video/``.
    frame_count : int, optional
        The number of frames: every camera must have exactly this many images.

    Returns
    -------
    Video
        Paths to the images; only their headers have been read (size check).

    Raises
    ------
    InputError
        Naming the file: a bad ``cameras.json``, a missing ``video/<camera>/`` folder, a camera
        with a different number of images than frames, an image that cannot be opened or whose
        size disagrees with ``cameras.json``.
    """
    folder = Path(folder)
    cameras = read_cameras(folder / CAMERAS_FILE)
    root = folder / VIDEO_FOLDER
    if not root.is_dir():
        raise InputError(
            f"{CAMERAS_FILE} is here but there is no {VIDEO_FOLDER}/ folder of images", folder / CAMERAS_FILE
        )
    images = []
    for camera in cameras:
        where = root / camera.name
        if not where.is_dir():
            raise InputError(f"camera {camera.name} of {CAMERAS_FILE} has no image folder", where)
        try:
            files = _image_files(where)
        except OSError as error:
            raise InputError(f"cannot be listed ({error.strerror or error})", where) from None
        count = frame_count if frame_count is not None else len(images[0]) if images else None
        if count is not None and len(files) != count:
            raise InputError(
                f"holds {len(files)} images ({', '.join(IMAGE_SUFFIXES)}) but there are {count} frames",
                where,
            )
        if not files:
            raise InputError("holds no images", where)
        for path in files:
            with _open(path) as image:
                if image.size != (camera.width, camera.height):
                    raise InputError(_size_problem(image.size, camera), path)
        images.append(tuple(files))
    extra = sorted(
        p.name for p in root.iterdir() if p.is_dir() and p.name not in {c.name for c in cameras}
    )
    if extra:
        logger.warning("%s: ignoring folders of no camera in %s: %s", root, CAMERAS_FILE, ", ".join(extra))
    return Video(cameras, tuple(images))


def write_video(folder: str | os.PathLike, video: Video, names=None) -> None:
    """Write ``cameras.json`` and ``video/<camera>/<name>.png`` into ``folder`` (which exists).

    ``names`` are the image stems per frame (default ``0000``, ``0001``, ...). Each file is
    written atomically; callers writing a whole capture use :func:`fourd.io.atomic.atomic_dir`.
    """
    from PIL import Image

    from fourd.io.atomic import atomic_path

    folder = Path(folder)
    count = video.frame_count
    if names is None:
        width = max(4, len(str(count - 1)))
        names = [f"{t:0{width}d}" for t in range(count)]
    if len(names) != count:
        raise InputError(f"{len(names)} image names for {count} frames")
    write_cameras(folder / CAMERAS_FILE, video.cameras)
    for c, camera in enumerate(video.cameras):
        where = folder / VIDEO_FOLDER / camera.name
        where.mkdir(parents=True, exist_ok=True)
        for t in range(count):
            with atomic_path(where / f"{names[t]}.png") as tmp:
                Image.fromarray(video.image(c, t)).save(tmp, format="PNG")
