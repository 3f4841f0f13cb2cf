"""Time-varying point clouds: :class:`Frame` and :class:`PointCloudSequence`."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from fourd.errors import InputError

if TYPE_CHECKING:
    from fourd.io.video import Video

NORMAL_TOLERANCE = 1e-3


def as_points(array, name: str, *, width: int = 3, allow_empty: bool = False) -> np.ndarray:
    """Return ``array`` as a C-contiguous float64 ``[P, width]`` array with finite values.

    Raises :class:`InputError` naming ``name`` when the shape or values are wrong.
    """
    try:
        values = np.ascontiguousarray(array, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name} is not numeric ({error})") from None
    if values.ndim != 2 or values.shape[1] != width:
        raise InputError(f"{name} must have shape [N, {width}], got {list(values.shape)}")
    if len(values) == 0 and not allow_empty:
        raise InputError(f"{name} is empty (zero points)")
    if np.isfinite(values).all():
        return values
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise InputError(
            f"{name} has {int(bad.sum())} rows with NaN or infinite values (first at row {int(np.argmax(bad))})"
        )
    return values


def _frame_faces(faces, count: int) -> np.ndarray | None:
    """``faces`` as int64 ``[F, 3]`` indexing ``count`` points; ``None`` when there are none."""
    try:
        values = np.asarray(faces)
    except (TypeError, ValueError) as error:
        raise InputError(f"faces are not numeric ({error})") from None
    if values.size == 0:
        return None
    if not np.issubdtype(values.dtype, np.integer):
        raise InputError(f"faces must hold integer vertex indices, got {values.dtype}")
    if values.ndim != 2 or values.shape[1] != 3:
        raise InputError(f"faces must have shape [F, 3], got {list(values.shape)}")
    if values.min() < 0 or values.max() >= count:
        raise InputError(f"faces index points outside the frame's {count} points")
    return np.ascontiguousarray(values, dtype=np.int64)


def check_increasing(times: np.ndarray, names: Sequence[str]) -> None:
    """:class:`InputError` naming the first frame whose time does not follow its
    predecessor's strictly (``names`` [T] name the frames)."""
    steps = np.diff(times)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise InputError(
            f"times must increase strictly: {names[i + 1]} has time {times[i + 1]} after {times[i]}"
        )


@dataclass(frozen=True, eq=False)
class Frame:
    """One scan: points at one time.

    Attributes
    ----------
    points : ndarray, float64 [P, 3]
        Positions, in input units.
    normals : ndarray, float64 [P, 3] or None
        Unit normals, if the scanner gave them.
    colors : ndarray, float64 [P, 3] or None
        Colours in [0, 1].
    sensors : ndarray, float64 [K, 3] or None
        Positions of the scanner(s) that saw this frame.
    time : float
        Time stamp (frame index by default).
    faces : ndarray, int64 [F, 3] or None
        Triangles over ``points`` when the frame is a mesh (a per-frame mesh, e.g. a PLY with
        faces); ``None`` for a point cloud (also for a file with an empty face list).
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    sensors: np.ndarray | None = None
    time: float = 0.0
    faces: np.ndarray | None = None

    def __post_init__(self):
        points = as_points(self.points, "points")
        object.__setattr__(self, "points", points)
        for name in ("normals", "colors"):
            value = getattr(self, name)
            if value is None:
                continue
            value = as_points(value, name)
            if len(value) != len(points):
                raise InputError(f"{name} has {len(value)} rows but there are {len(points)} points")
            object.__setattr__(self, name, value)
        if self.normals is not None:
            lengths = np.linalg.norm(self.normals, axis=1)
            if np.any(np.abs(lengths - 1.0) > NORMAL_TOLERANCE):
                raise InputError(
                    f"normals must be unit length (found lengths from {lengths.min():.3g} to {lengths.max():.3g})"
                )
        if self.sensors is not None:
            object.__setattr__(self, "sensors", as_points(self.sensors, "sensors"))
        time = float(self.time)
        if not np.isfinite(time):
            raise InputError(f"time must be finite, got {self.time!r}")
        object.__setattr__(self, "time", time)
        if self.faces is not None:
            object.__setattr__(self, "faces", _frame_faces(self.faces, len(points)))

    def __len__(self) -> int:
        return len(self.points)


@dataclass(frozen=True, eq=False)
class PointCloudSequence:
    """Ordered frames with strictly increasing times.

    Attributes
    ----------
    frames : tuple of Frame
    names : tuple of str
        Where each frame came from (file names), for messages; defaults to ``frame_<i>``.
    video : fourd.io.video.Video or None
        The calibrated multi-view video of the capture (cameras and one image per camera and
        frame, read lazily), when there is one; methods that use appearance take it from here
        and work without it.
    """

    frames: tuple[Frame, ...]
    names: tuple[str, ...] = field(default=())
    video: Video | None = None

    def __post_init__(self):
        frames = tuple(self.frames)
        if not frames:
            raise InputError("the sequence has no frames")
        for i, frame in enumerate(frames):
            if not isinstance(frame, Frame):
                raise InputError(f"frame {i} is a {type(frame).__name__}, not a fourd.Frame")
        names = tuple(self.names) or tuple(f"frame_{i}" for i in range(len(frames)))
        if len(names) != len(frames):
            raise InputError(f"{len(names)} names for {len(frames)} frames")
        check_increasing(np.array([f.time for f in frames]), names)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "names", names)
        if self.video is not None:
            from fourd.io.video import Video

            if not isinstance(self.video, Video):
                raise InputError(f"video must be a fourd.io.video.Video, got {type(self.video).__name__}")
            if self.video.frame_count != len(frames):
                raise InputError(
                    f"the video has {self.video.frame_count} images per camera but there are "
                    f"{len(frames)} frames"
                )

    @classmethod
    def from_arrays(
        cls,
        points: Sequence[np.ndarray] | np.ndarray,
        *,
        times: Sequence[float] | None = None,
        normals: Sequence[np.ndarray] | None = None,
        sensors: np.ndarray | Sequence[np.ndarray] | None = None,
    ) -> PointCloudSequence:
        """Build a sequence from per-frame point arrays (``[T, P, 3]`` or a list of ``[P_t, 3]``).

        ``sensors`` is either one ``[K, 3]`` array (fixed scanners) or one per frame.
        """
        count = len(points)
        times = np.arange(count, dtype=float) if times is None else np.asarray(times, float)
        if len(times) != count:
            raise InputError(f"{len(times)} times for {count} frames")
        fixed = sensors is not None and np.ndim(sensors) == 2
        frames = []
        for i in range(count):
            frames.append(
                Frame(
                    points=points[i],
                    normals=None if normals is None else normals[i],
                    sensors=sensors if fixed else (None if sensors is None else sensors[i]),
                    time=times[i],
                )
            )
        return cls(tuple(frames))

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self) -> Iterator[Frame]:
        return iter(self.frames)

    def __getitem__(self, index):
        if isinstance(index, slice):
            video = None if self.video is None else self.video.select(index)
            return PointCloudSequence(self.frames[index], self.names[index], video)
        return self.frames[index]

    @property
    def times(self) -> np.ndarray:
        """Frame times, float64 ``[T]``."""
        return np.array([f.time for f in self.frames])

    @property
    def has_sensors(self) -> bool:
        return all(f.sensors is not None for f in self.frames)

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds over all frames, ``[2, 3]`` (min, max)."""
        lo = np.min([f.points.min(axis=0) for f in self.frames], axis=0)
        hi = np.max([f.points.max(axis=0) for f in self.frames], axis=0)
        return np.stack([lo, hi])

    def diagonal(self) -> float:
        """Length of the diagonal of :meth:`bounds`."""
        lo, hi = self.bounds()
        return float(np.linalg.norm(hi - lo))

    def select(self, start: int | None = None, stop: int | None = None, step: int | None = None):
        """Frames ``start:stop:step`` (the command line's ``--frames A:B:S``)."""
        return self[slice(start, stop, step)]
