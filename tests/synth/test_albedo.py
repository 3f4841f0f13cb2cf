import numpy as np
import pytest

from fourd.errors import InputError
from fourd.synth.albedo import APPEARANCES, albedo, check_appearance

BOUNDS = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _points(count=20000, seed=0):
    return np.random.default_rng(seed).uniform(-1, 1, (count, 3))


@pytest.mark.parametrize("kind", APPEARANCES)
def test_albedo_is_a_deterministic_function_of_the_point(kind):
    points = _points(3000)
    a = albedo(points, kind, bounds=BOUNDS, seed=4)
    assert a.shape == (3000, 3) and np.all((a >= 0) & (a <= 1))
    np.testing.assert_array_equal(a[1000:], albedo(points[1000:], kind, bounds=BOUNDS, seed=4))
    assert not np.allclose(a, albedo(points, kind, bounds=BOUNDS, seed=5))  # the seed chooses


def test_skin_is_smooth_and_low_contrast_cloth_is_printed_and_high_contrast():
    points = _points()
    skin = albedo(points, "skin", bounds=BOUNDS, seed=0)
    cloth = albedo(points, "cloth", bounds=BOUNDS, seed=0)
    brightness = lambda a: a.mean(axis=1)  # noqa: E731
    assert brightness(skin).std() < 0.06 and brightness(cloth).std() > 0.15
    assert len(np.unique(np.round(cloth, 6), axis=0)) >= 5  # a palette of random colours
    # smooth: nearby points (half a per cent of the diagonal apart) have nearly the same skin colour
    step = albedo(points + 0.01, "skin", bounds=BOUNDS, seed=0)
    assert np.abs(step - skin).max() < 0.04
    # printed: cloth changes abruptly between nearby points somewhere
    assert np.abs(albedo(points + 0.01, "cloth", bounds=BOUNDS, seed=0) - cloth).max() > 0.3


def test_pattern_scales_with_the_bounds():
    points = _points(2000)
    a = albedo(points, "cloth", bounds=BOUNDS, seed=1)
    b = albedo(3.0 * points + 7.0, "cloth", bounds=3.0 * BOUNDS + 7.0, seed=1)
    np.testing.assert_array_equal(a, b)


def test_bad_kind_or_bounds():
    assert check_appearance(None) is None and check_appearance("none") is None
    with pytest.raises(InputError, match="unknown appearance"):
        albedo(_points(3), "velvet", bounds=BOUNDS)
    with pytest.raises(InputError, match="single point"):
        albedo(_points(3), "skin", bounds=np.zeros((2, 3)))
