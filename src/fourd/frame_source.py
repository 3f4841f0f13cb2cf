"""A sequence of frames read when asked: :class:`FrameSource`.

A whole capture (hundreds of frames, tens of thousands of points each) does not fit in memory
as a :class:`~fourd.PointCloudSequence`; the streamed methods (:mod:`fourd.methods.kinematic.stream`)
read it a window of frames at a time. A source knows every frame's time and name up front and
reads a frame's points only when :meth:`FrameSource.read` asks for them; its video, when it
has one, is read the same way (a folder's images are decoded when used).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fourd.errors import InputError
from fourd.io.video import Video
from fourd.sequence import Frame, PointCloudSequence, check_increasing


@dataclass(frozen=True, eq=False)
class FrameSource:
    """Frames read one at a time by ``read_frame``.

    Attributes
    ----------
    times : ndarray float64 [T]
        Every frame's time, strictly increasing.
    names : tuple of str
        Where each frame comes from (file names), for messages.
    read_frame : callable(int) -> Frame
        Reads frame ``i`` (its ``time`` is replaced by ``times[i]``); a pure function of ``i``.
    video : fourd.io.video.Video or None
        The capture's calibrated video, one image per camera and frame.
    """

    times: np.ndarray
    names: tuple[str, ...]
    read_frame: Callable[[int], Frame]
    video: Video | None = None

    def __post_init__(self):
        times = np.asarray(self.times, dtype=np.float64).ravel()
        if len(times) == 0:
            raise InputError("the sequence has no frames")
        if not np.isfinite(times).all():
            raise InputError("frame times must be finite")
        names = tuple(self.names) or tuple(f"frame_{i}" for i in range(len(times)))
        if len(names) != len(times):
            raise InputError(f"{len(names)} names for {len(times)} frames")
        check_increasing(times, names)
        if self.video is not None and self.video.frame_count != len(times):
            raise InputError(
                f"the video has {self.video.frame_count} images per camera but there are "
                f"{len(times)} frames"
            )
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "names", names)

    def __len__(self) -> int:
        return len(self.times)

    def __getitem__(self, index: slice) -> FrameSource:
        """The frames ``index`` (a slice) as a source of their own."""
        if not isinstance(index, slice):
            raise TypeError("a FrameSource is sliced; read(i, i + 1) reads one frame")
        chosen = range(len(self))[index]
        return FrameSource(
            self.times[index],
            self.names[index],
            lambda i: self.read_frame(chosen[i]),
            None if self.video is None else self.video.select(index),
        )

    def read(self, start: int, stop: int) -> PointCloudSequence:
        """Frames ``start`` to ``stop - 1``, read now."""
        start, stop = max(0, int(start)), min(len(self), int(stop))
        if start >= stop:
            raise InputError(f"no frames between {start} and {stop} (the sequence has {len(self)})")
        frames = []
        for i in range(start, stop):
            frame = self.read_frame(i)
            if not isinstance(frame, Frame):
                raise InputError(
                    f"frame {i} ({self.names[i]}) is a {type(frame).__name__}, not a fourd.Frame"
                )
            frames.append(
                Frame(
                    frame.points,
                    frame.normals,
                    frame.colors,
                    frame.sensors,
                    self.times[i],
                    frame.faces,
                )
            )
        video = None if self.video is None else self.video.select(slice(start, stop))
        return PointCloudSequence(tuple(frames), self.names[start:stop], video)

    @classmethod
    def of(cls, sequence: PointCloudSequence) -> FrameSource:
        """The frames (and video) of a sequence already in memory (for tests and small
        captures)."""
        return cls(sequence.times, sequence.names, sequence.frames.__getitem__, sequence.video)

    @classmethod
    def of_frames(cls, frames: Sequence[Frame], names: Sequence[str] = ()) -> FrameSource:
        """A source over a list of frames, taking their times."""
        return cls(np.array([f.time for f in frames]), tuple(names), list(frames).__getitem__)
