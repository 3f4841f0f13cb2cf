"""A synthetic whole capture of any length (issue 56's 1,000-frame target): a scene's motion
played forwards and backwards (ping-pong) and scanned a frame at a time when a streamed method
reads it, so the capture never sits in memory."""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.sequence import Frame
from fourd.synth.data import load_shared
from fourd.synth.scanner import camera_rig, scan_frame, scan_options
from fourd.synth.scenes import SHARED_SCENES, scene

#: Seeds of the scan noise differ between passes over the scene's frames by this prime.
PASS_SEED = 7919


class LongCapture(NamedTuple):
    """A capture of :func:`long_capture`: its ``source``, the scene's ``truth`` (its own frames)
    and ``index`` [T], the truth frame each capture frame shows."""

    source: FrameSource
    truth: AnimatedMesh
    index: np.ndarray


def pingpong(frames: int, count: int) -> np.ndarray:
    """Indices ``[frames]`` into ``count`` frames, forwards then backwards, repeated.

    >>> pingpong(8, 3).tolist()
    [0, 1, 2, 1, 0, 1, 2, 1]
    """
    if count < 2:
        return np.zeros(frames, dtype=np.int64)
    period = 2 * (count - 1)
    phase = np.arange(frames) % period
    return np.where(phase < count, phase, period - phase).astype(np.int64)


def long_capture(frames: int, *, scene_name: str = "crane", seed: int = 0, **scan) -> LongCapture:
    """``frames`` frames of scene ``scene_name`` (all its own frames at step 1 for the shared
    scenes, the default 20 for the procedural ones) played ping-pong, each scanned when read by the virtual depth cameras framing the
    whole scene (:func:`fourd.synth.scanner.scan_frame`; ``scan``: its options, e.g.
    ``resolution``). The noise differs between passes over the same truth frame. Frames have
    times 0, 1, 2, ..., no normals, and the cameras as sensors.

    Examples
    --------
    >>> capture = long_capture(5, scene_name="squash-ball", resolution=32)
    >>> len(capture.source), capture.index.tolist(), len(capture.source.read(3, 4)[0]) > 100
    (5, [0, 1, 2, 3, 4], True)
    """
    if int(frames) != frames or frames < 1:
        raise InputError(f"a long capture needs a positive whole number of frames, got {frames}")
    if scene_name in SHARED_SCENES:
        truth = scene(scene_name, frames=load_shared(scene_name).frame_count, step=1)
    else:
        truth = scene(scene_name)
    if not isinstance(truth, AnimatedMesh):
        raise InputError(f"scene {scene_name} changes topology: it has no correspondence truth")
    options = scan_options(None, seed=seed, **scan)
    rig = camera_rig(
        truth.bounds(),
        options.cameras,
        distance=options.distance,
        elevation=options.elevation,
        first_angle=options.first_angle,
        field=options.field,
    )
    index = pingpong(int(frames), truth.frame_count)
    passes = np.arange(frames) // max(truth.frame_count - 1, 1)

    def read(i: int) -> Frame:
        shot = scan_frame(
            truth, int(index[i]), replace(options, seed=seed + PASS_SEED * int(passes[i])), rig=rig
        )
        return Frame(points=shot.points, sensors=rig.positions, time=float(i))

    times = np.arange(frames, dtype=np.float64)
    return LongCapture(
        FrameSource(times, tuple(f"frame_{i:04d}" for i in range(frames)), read), truth, index
    )
