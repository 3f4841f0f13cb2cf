"""The colour field of a frame's points, the lamps' shading fit, and the per-vertex shift the
colours ask for."""

import numpy as np
import pytest

from fourd.appearance.lighting import fit_lighting
from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import ColorField
from fourd.errors import InputError


def _paint(points):
    """A printed pattern: blobs of about 0.25 units in two colours."""
    x, y = points[:, 0], points[:, 1]
    a = 0.5 + 0.35 * np.sin(7 * x + 1.0) * np.cos(6 * y)
    b = 0.5 + 0.3 * np.cos(5 * x - 2 * y)
    return np.column_stack([a, b, 0.5 * (a + b)])


def _plane(count, rng, size=1.0):
    xy = rng.uniform(-size, size, (count, 2))
    return np.column_stack([xy, np.zeros(count)])


def test_a_translated_textured_plane_gives_back_the_translation():
    rng = np.random.default_rng(0)
    moved_by = np.array([0.03, -0.02, 0.0])
    vertices = _plane(1500, rng, 0.7)
    normals = np.tile([0.0, 0.0, 1.0], (len(vertices), 1))
    frame0 = _plane(40000, rng)
    reference = ColorField(frame0, np.tile([0.0, 0, 1], (len(frame0), 1)), _paint(frame0)).sample(vertices)
    # frame 1: the printed plane slid by moved_by (the colour at p is the paint at p - moved_by)
    frame1 = _plane(40000, rng)
    colors1 = np.clip(_paint(frame1 - moved_by) + rng.normal(0, 0.01, (len(frame1), 3)), 0, 1)
    field = ColorField(frame1, np.tile([0.0, 0, 1], (len(frame1), 1)), colors1)
    result = photometric_shift(vertices, normals, reference, field, radius=0.15)
    sure = np.isfinite(result.uncertainty) & (result.uncertainty < 0.01)
    assert sure.mean() > 0.5
    error = np.linalg.norm(result.shift[sure] - moved_by, axis=1)
    assert np.median(error) < 0.003  # a tenth of the move
    assert np.abs(result.shift[:, 2]).max() < 1e-9  # within the tangent plane


def test_uniform_colour_pins_nothing_down():
    rng = np.random.default_rng(1)
    vertices = _plane(800, rng, 0.7)
    normals = np.tile([0.0, 0.0, 1.0], (len(vertices), 1))
    fields = []
    for _ in range(2):
        points = _plane(30000, rng)
        colors = np.clip(0.5 + rng.normal(0, 0.01, (len(points), 3)), 0, 1)
        fields.append(ColorField(points, np.tile([0.0, 0, 1], (len(points), 1)), colors))
    result = photometric_shift(vertices, normals, fields[0].sample(vertices), fields[1], radius=0.15)
    # the noise has a structure tensor of its own; what is left of it after the noise's share
    # pins nothing down
    assert (result.uncertainty < 0.05).mean() < 0.02


def test_the_lamps_shading_is_divided_out():
    rng = np.random.default_rng(2)
    normals = rng.normal(size=(30000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lamp = np.array([0.3, 0.8, 0.52]) / np.linalg.norm([0.3, 0.8, 0.52])
    shading = 0.25 + 0.6 * np.clip(normals @ lamp, 0, None)
    albedo = rng.choice([0.4, 0.6], size=(len(normals), 1)) * np.ones(3)
    colors = albedo * shading[:, None]
    lighting = fit_lighting([np.zeros_like(normals)], [normals], [colors])
    recovered = lighting.deshade(colors, normals)[:, 0]
    # one common factor away from the albedo, within a few percent
    ratio = recovered / albedo[:, 0]
    assert np.std(ratio) / np.mean(ratio) < 0.04


def test_bad_inputs_are_input_errors():
    with pytest.raises(InputError, match="one shape"):
        ColorField(np.zeros((20, 3)), np.zeros((20, 3)), np.zeros((19, 3)))
    with pytest.raises(InputError, match="coloured points"):
        fit_lighting([np.zeros((5, 3))], [np.zeros((5, 3))], [None])
