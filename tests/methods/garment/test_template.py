"""The garment template from a photo (thesis 3.7): silhouette, triangulation, sewing and
inflation that keeps edge lengths."""

import numpy as np
import pytest

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.meshes import vertex_components
from fourd.methods.garment import (
    TemplateOptions,
    edge_strain,
    outline_from_photo,
    template_from_pattern,
    template_from_photo,
    triangulate_outline,
)
from fourd.synth.garments import pattern_outline, pattern_photo

FAST = TemplateOptions(edge=0.06)


def _area(polygon):
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


def test_the_photo_gives_back_the_outline():
    outline, openings = pattern_outline("tshirt", with_openings=True)
    image, calibration = pattern_photo(outline, openings)
    traced = outline_from_photo(image, calibration)
    assert abs(_area(traced) / _area(outline) - 1) < 0.02


def test_the_triangulation_covers_the_outline_with_even_triangles():
    outline = pattern_outline("tshirt")
    points, faces, _ = triangulate_outline(outline, 0.05)
    a, b, c = (points[faces[:, k]] for k in range(3))
    u, v = b - a, c - a
    areas = 0.5 * (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    assert (areas > 0).all()  # counter-clockwise, none flipped
    assert abs(areas.sum() / _area(outline) - 1) < 0.02
    lengths = np.linalg.norm(np.concatenate([b - a, c - b, a - c]), axis=1)
    assert 0.6 < np.median(lengths) / 0.05 < 1.4


@pytest.mark.parametrize("name, loops", [("tshirt", 4), ("dress", 2)])
def test_the_template_has_the_garments_openings_and_keeps_its_edge_lengths(name, loops):
    outline, openings = pattern_outline(name, with_openings=True)
    image, calibration = pattern_photo(outline, openings)
    template = template_from_photo(image, calibration, FAST)
    assert len(boundary_loops(template.faces, len(template.vertices))) == loops
    assert vertex_components(template.faces, len(template.vertices))[0] == 1
    strain = np.abs(edge_strain(template))
    assert np.median(strain) < 0.02 and np.quantile(strain, 0.95) < 0.06
    assert np.ptp(template.vertices[:, 2]) > 0.2  # inflated, not flat


def test_a_square_open_at_two_ends_inflates_to_a_tube_of_twice_its_width():
    square = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]])
    openings = [square[[0, 1]], square[[2, 3]]]  # bottom and top open, the sides sewn
    template = template_from_pattern(square, openings, FAST)
    middle = np.abs(template.vertices[:, 1] - 0.5) < 0.04
    ring = template.vertices[middle]
    angles = np.arctan2(ring[:, 2] - ring[:, 2].mean(), ring[:, 0] - ring[:, 0].mean())
    ordered = ring[np.argsort(angles)]
    girth = np.linalg.norm(np.diff(np.vstack([ordered, ordered[:1]])[:, [0, 2]], axis=0), axis=1).sum()
    assert abs(girth / 1.0 - 1) < 0.08  # front and back: twice the width


def test_a_photo_without_openings_is_an_input_error():
    outline = pattern_outline("dress")
    image, calibration = pattern_photo(outline)
    with pytest.raises(InputError, match="openings"):
        template_from_photo(image, calibration, FAST)
