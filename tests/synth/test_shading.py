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


def test_under_a_diffuse_sky_a_valley_is_darker_than_a_ridge_and_a_plane_fully_lit():
    from fourd.geometry.normals import vertex_normals
    from fourd.synth.shading import accessibility

    n = 61
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    for amplitude in (0.0, 0.02):
        z = amplitude * np.cos(2 * np.pi * x / 0.2)
        vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
        normals = vertex_normals(vertices, faces)
        normals *= np.sign(normals[:, 2:3])  # up
        sky = accessibility(vertices, faces, normals, reach=0.1)
        inner = (np.abs(x.ravel() - 0.5) < 0.25) & (np.abs(y.ravel() - 0.5) < 0.25)
        if amplitude == 0:
            assert np.allclose(sky[inner], 1.0)
        else:
            ridge = inner & (np.cos(2 * np.pi * x.ravel() / 0.2) > 0.95)
            valley = inner & (np.cos(2 * np.pi * x.ravel() / 0.2) < -0.95)
            assert sky[ridge].min() > 0.95 and sky[valley].max() < sky[ridge].min() - 0.1


def test_an_unknown_lighting_is_an_input_error():
    from fourd.synth.scanner import scan_options

    with pytest.raises(InputError, match="lighting"):
        scan_options(lighting="sun")
