import numpy as np
import pytest

from fourd.errors import InputError
from fourd.synth.shading import Lamps, shaded_colors, shading


def test_shading_changes_with_the_normal_and_not_with_the_position():
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(200, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    shade = shading(normals)
    assert shade.std() > 0.1  # a patch that turns changes brightness
    lamps = Lamps()
    facing_key = lamps.directions[:1]
    assert shading(facing_key)[0] == pytest.approx(lamps.ambient + lamps.intensities[0] + lamps.intensities[1:] @ np.clip(lamps.directions[1:] @ facing_key[0], 0, None))
    assert shading(-facing_key)[0] < shading(facing_key)[0]
    assert np.all(shade >= lamps.ambient)


def test_single_lamp_is_lambert():
    lamps = Lamps(directions=[[0, 0, 1]], intensities=[1.0], ambient=0.0)
    angles = np.deg2rad([0, 60, 90, 120])
    normals = np.stack([np.sin(angles), np.zeros(4), np.cos(angles)], 1)
    np.testing.assert_allclose(shading(normals, lamps), [1.0, 0.5, 0.0, 0.0], atol=1e-12)


def test_shaded_colors_multiply_clip_and_add_noise():
    albedo = np.array([[1.0, 0.5, 0.0]])
    lamps = Lamps(directions=[[0, 0, 1]], intensities=[1.0], ambient=0.2)
    np.testing.assert_allclose(shaded_colors(albedo, [[0, 0, 1]], lamps=lamps), [[1.0, 0.6, 0.0]])
    noisy = shaded_colors(np.full((500, 3), 0.5), np.tile([0, 0, 1.0], (500, 1)), noise=0.01, rng=np.random.default_rng(0), lamps=lamps)
    assert abs(noisy.mean() - 0.6) < 0.002 and 0.008 < noisy.std() < 0.012
    with pytest.raises(InputError, match="rng"):
        shaded_colors(albedo, [[0, 0, 1]], noise=0.1)


def test_bad_lamps():
    with pytest.raises(InputError):
        Lamps(directions=[[0, 0, 0]], intensities=[1.0])
    with pytest.raises(InputError):
        Lamps(directions=[[0, 0, 1]], intensities=[1.0, 2.0])
    with pytest.raises(InputError):
        Lamps(ambient=-1)
