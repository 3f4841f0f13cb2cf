"""The low-passed surface (fourd.geometry.low_pass): folds go, broad shapes stay."""

import numpy as np

from fourd.geometry.low_pass import low_pass_surface


def _sheet(wavelength, amplitude=0.02, n=81):
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    z = amplitude * np.sin(2 * np.pi * x / wavelength)
    vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return vertices, faces


def test_a_plane_stays_in_its_plane_and_away_from_its_border_where_it_is():
    vertices, faces = _sheet(0.25, amplitude=0.0)
    smooth = low_pass_surface(vertices, faces, 0.3)
    assert np.abs(smooth[:, 2]).max() < 1e-12  # an open border only slides within the plane
    inner = np.all(np.abs(vertices[:, :2] - 0.5) < 0.2, axis=1)
    assert np.abs(smooth[inner] - vertices[inner]).max() < 2e-3


def test_a_sinusoid_keeps_the_share_of_its_amplitude_the_filter_says():
    for wavelength, cutoff in ((0.125, 0.25), (0.25, 0.25), (0.5, 0.25)):
        vertices, faces = _sheet(wavelength)
        smooth = low_pass_surface(vertices, faces, cutoff)
        inner = (vertices[:, 0] > 0.3) & (vertices[:, 0] < 0.7) & (vertices[:, 1] > 0.3) & (vertices[:, 1] < 0.7)
        kept = np.abs(smooth[inner, 2]).max() / 0.02
        expected = 1 / (1 + (cutoff / wavelength) ** 4)
        assert abs(kept - expected) < 0.08, (wavelength, kept, expected)


def test_values_on_the_surface_are_low_passed_like_its_shape():
    vertices, faces = _sheet(0.25, amplitude=0.0)
    x = vertices[:, 0]
    fine = 0.01 * np.sin(2 * np.pi * x / 0.125)  # a fold-sized ripple of a displacement
    broad = np.column_stack([np.full(len(x), 0.03), 0.02 * x, np.zeros(len(x))])  # a drift
    smooth = low_pass_surface(vertices, faces, 0.25, values=broad + fine[:, None])
    inner = np.all(np.abs(vertices[:, :2] - 0.5) < 0.2, axis=1)
    assert np.abs(smooth[inner] - broad[inner]).max() < 0.1 * 0.01 + 1e-3  # the ripple goes
    curved, _ = _sheet(0.5)
    assert np.allclose(low_pass_surface(curved, faces, 0.25, values=curved),
                       low_pass_surface(curved, faces, 0.25))
