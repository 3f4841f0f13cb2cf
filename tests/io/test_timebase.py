"""The time base: what a result's times count, at which rate, and the conversions."""

import numpy as np
import pytest

from fourd.errors import InputError
from fourd.io.timebase import DEFAULT_FPS, TimeBase, time_base, time_unit_of


def test_whole_numbers_are_frames_at_the_default_or_given_rate():
    assert time_base(np.arange(5.0)) == TimeBase("frames", DEFAULT_FPS)
    assert time_base([3, 4, 6], fps=24) == TimeBase("frames", 24.0)
    base = time_base([0, 12, 24], fps=24)
    assert base.seconds([0, 12, 24]).tolist() == [0.0, 0.5, 1.0]
    assert base.frames([0, 12, 24]).tolist() == [0.0, 12.0, 24.0]


@pytest.mark.parametrize(
    "rate, expected",
    [(25.0, 25.0), (30000 / 1001, 30000 / 1001), (24.0, 24.0), (60.0, 60.0), (0.4, 0.4),
     (1 / 0.37, 1 / 0.37)],
)
def test_seconds_measure_their_rate_and_snap_to_standard_ones(rate, expected):
    rng = np.random.default_rng(0)
    times = 2.5 + np.arange(12) / rate + rng.normal(scale=1e-5 / rate, size=12)
    base = time_base(np.round(times, 4))  # time stamps as a capture writes them
    assert base.unit == "seconds"
    assert base.fps == pytest.approx(expected, rel=1e-3)
    if expected in (25.0, 30000 / 1001, 24.0, 60.0):
        assert base.fps == expected  # snapped exactly
    assert np.array_equal(base.seconds(times), times)


def test_dropped_frames_do_not_change_the_measured_rate():
    times = np.round(np.delete(np.arange(20), [3, 4, 9]) / 25.0 + 100.0, 3)
    assert time_base(times).fps == 25.0
    assert time_base(times).frames(times)[:4].tolist() == [2500.0, 2501.0, 2502.0, 2505.0]


def test_frames_of_seconds_snap_to_whole_numbers():
    base = time_base([0.0, 0.1, 0.2, 0.3])
    assert base.fps == 10.0
    assert base.frames([0.0, 0.1, 0.2, 0.3]).tolist() == [0.0, 1.0, 2.0, 3.0]
    assert time_base([0.0, 0.1], fps=24).frames([0.05]).tolist() == [pytest.approx(1.2)]


def test_the_unit_can_be_forced_and_is_checked():
    assert time_base([0, 1, 2], unit="seconds").fps == 1.0
    assert time_base([0, 1, 2], unit="seconds").frames([0, 1, 2]).tolist() == [0.0, 1.0, 2.0]
    assert time_base([0.5, 1.5], unit="frames").seconds([0.5, 1.5]).tolist() == [
        pytest.approx(0.5 / 30),
        pytest.approx(1.5 / 30),
    ]
    assert time_base([0.0]).fps == DEFAULT_FPS and time_base([0.25]).fps == DEFAULT_FPS
    with pytest.raises(InputError, match="'frames' or 'seconds'"):
        time_base([0, 1], unit="minutes")
    for bad in (0, -24, float("nan"), float("inf"), "fast"):
        with pytest.raises(InputError, match="fps must be"):
            time_base([0, 1], fps=bad)


def test_time_unit_of():
    assert time_unit_of([-2.0, 0.0, 7.0]) == "frames"
    assert time_unit_of([0.0, 0.5]) == "seconds"
