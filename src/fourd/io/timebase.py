"""The time base of a written result: what its ``times`` count and at which frame rate.

A result's ``times`` are in the input's units: frame numbers (the default ``0, 1, 2, ...``, or
a ``times.txt`` of whole numbers such as ``fourd synth`` writes) or seconds (a ``times.txt``
of capture time stamps). The formats want one or the other:

=============  ==============================================================================
``.glb``       seconds (animation sampler input, shifted to start at 0 when negative)
``.abc``       seconds (the ``TimeSampling`` of the samples)
``.usd``       time codes at ``timeCodesPerSecond`` (= ``framesPerSecond`` = the frame rate)
``.pc2``       frames (start frame and frames per sample)
=============  ==============================================================================

:func:`time_base` resolves the two unknowns once: the unit of the times (given, or told from
the times: whole numbers are frame numbers, anything else is seconds) and the frame rate
(given, or :data:`DEFAULT_FPS` for frame numbers, or measured from the seconds and snapped to
the nearest whole number or NTSC rate (23.976, 29.97, 59.94, 119.88) when that is within
:data:`SNAP_TOLERANCE`). Every writer then converts with
:meth:`TimeBase.seconds` and :meth:`TimeBase.frames`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fourd.errors import InputError

#: Frames per second when times are frame numbers and no rate is given (a common capture and
#: video rate; ``--fps`` sets another).
DEFAULT_FPS = 30.0
#: The units a result's times may be in.
TIME_UNITS = ("frames", "seconds")
#: The rates besides whole numbers that a measured rate snaps to.
NTSC_RATES = (24000 / 1001, 30000 / 1001, 60000 / 1001, 120000 / 1001)
#: A measured rate snaps to the nearest whole number or NTSC rate within this relative
#: distance (under half the 1/1001 gap between 24 and 23.976, 30 and 29.97).
SNAP_TOLERANCE = 4e-4

__all__ = ["DEFAULT_FPS", "TIME_UNITS", "TimeBase", "time_base", "time_unit_of"]


@dataclass(frozen=True)
class TimeBase:
    """How to read a result's ``times``.

    Attributes
    ----------
    unit : {"frames", "seconds"}
        What the times count.
    fps : float
        Frames per second of the written timeline (positive).
    """

    unit: str
    fps: float

    def seconds(self, times) -> np.ndarray:
        """``times`` [T] in seconds (float64)."""
        times = np.asarray(times, dtype=np.float64)
        return times / self.fps if self.unit == "frames" else times

    def frames(self, times) -> np.ndarray:
        """``times`` [T] as frame numbers at :attr:`fps` (float64; values within 1e-6 of a
        whole number become that number, so 0.1 s at 30 fps is frame 3, not 2.9999999)."""
        times = np.asarray(times, dtype=np.float64)
        frames = times if self.unit == "frames" else times * self.fps
        whole = np.round(frames)
        return np.where(np.abs(frames - whole) <= 1e-6 * np.maximum(1.0, np.abs(whole)), whole, frames)


def time_unit_of(times) -> str:
    """``"frames"`` when every time is a whole number (frame numbers), else ``"seconds"``.

    Examples
    --------
    >>> time_unit_of([0, 1, 2, 5]), time_unit_of([0.0, 0.04, 0.08])
    ('frames', 'seconds')
    """
    times = np.asarray(times, dtype=np.float64)
    return "frames" if np.all(times == np.round(times)) else "seconds"


def _measured_fps(seconds: np.ndarray) -> float:
    """Frames per second of time stamps: the median step numbers the frames (so dropped
    frames count as gaps), a least-squares line through (frame number, time) gives the rate
    (so stamps rounded to a few decimals still measure it closely)."""
    steps = np.diff(seconds)
    if not len(steps):
        return DEFAULT_FPS
    step = float(np.median(steps))
    numbers = np.round((seconds - seconds[0]) / step)
    if np.ptp(numbers) > 0:
        step = float(np.polyfit(numbers, seconds, 1)[0])
    rate = 1.0 / step
    candidates = [*NTSC_RATES, float(round(rate))] if rate >= 0.5 else list(NTSC_RATES)
    nearest = min(candidates, key=lambda standard: abs(rate - standard))
    return nearest if abs(rate - nearest) <= SNAP_TOLERANCE * nearest else rate


def time_base(times, *, fps: float | None = None, unit: str | None = None) -> TimeBase:
    """Resolve the unit and the frame rate of ``times`` (see the module docstring).

    Parameters
    ----------
    times : array [T]
        Strictly increasing frame times of a result.
    fps : float, optional
        Frames per second. With frame numbers it gives them their duration (default
        :data:`DEFAULT_FPS`); with seconds it is the rate of the frame-based formats' timeline
        (USD time codes, ``.pc2`` frames), measured from the times when not given.
    unit : {"frames", "seconds"}, optional
        What ``times`` count; by default :func:`time_unit_of` (whole numbers are frames).

    Raises
    ------
    InputError
        ``fps`` not a positive finite number, or an unknown ``unit``.

    Examples
    --------
    >>> time_base([0, 1, 2])
    TimeBase(unit='frames', fps=30.0)
    >>> base = time_base([10.0, 10.04, 10.08])
    >>> base.fps, base.frames([10.0, 10.04]).tolist()
    (25.0, [250.0, 251.0])
    >>> time_base([0, 1, 2], fps=24).seconds([0, 1, 2]).tolist()
    [0.0, 0.041666666666666664, 0.08333333333333333]
    """
    if fps is not None:
        try:
            fps = float(fps)
        except (TypeError, ValueError):
            raise InputError(f"fps must be a number, got {fps!r}") from None
        if not (np.isfinite(fps) and fps > 0):
            raise InputError(f"fps must be a positive number, got {fps:g}")
    if unit is None:
        unit = time_unit_of(times)
    if unit not in TIME_UNITS:
        raise InputError(f"the time unit must be 'frames' or 'seconds', got {unit!r}")
    if fps is None:
        fps = DEFAULT_FPS if unit == "frames" else _measured_fps(np.asarray(times, np.float64))
    return TimeBase(unit, fps)
