"""The holes of a garment's closed surface re-triangulated and re-projected on the base (thesis
3.6.2)."""

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.hole_filling import membrane_positions
from fourd.methods.garment.base_holes import (
    base_mean_value_weights,
    delaunay_flips,
    reparameterize_holes,
)
from fourd.methods.garment.base_mesh import base_mesh
from fourd.methods.garment.boundary_tracking import initial_ellipses
from fourd.synth.garments import tshirt

# one facet, its plane the base's: no unfolding
HOME_ONLY = (np.eye(2)[None, None], np.zeros((1, 1, 2)))


def _signed_areas(corners):
    first, second = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    return first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]


def test_a_long_edge_is_flipped_to_the_short_diagonal_unless_it_is_fixed():
    uv = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.2], [1.0, -0.2]])
    faces = np.array([[0, 1, 2], [1, 0, 3]])
    home = np.zeros(4, dtype=np.int64)
    flipped, count = delaunay_flips(faces, np.ones(2, bool), home, uv, *HOME_ONLY)
    assert count == 1
    assert {tuple(sorted(f)) for f in flipped.tolist()} == {(0, 2, 3), (1, 2, 3)}
    corners = uv[flipped]
    assert np.all(_signed_areas(corners) > 0)  # both new triangles keep the orientation
    kept, count = delaunay_flips(faces, np.ones(2, bool), home, uv, *HOME_ONLY, fixed={(0, 1)})
    assert count == 0 and np.array_equal(kept, faces)
    # a quadrilateral that is not convex on the base is not flipped
    dart = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.2], [2.5, -0.1]])
    _, count = delaunay_flips(faces, np.ones(2, bool), home, dart, *HOME_ONLY)
    assert count == 0


def test_the_membrane_with_the_base_embeddings_weights_reproduces_an_affine_surface():
    # the base's mean-value weights have linear precision: a hole in a surface that is an
    # affine image of its base embedding is filled exactly, however irregular the sampling;
    # the uniform weights of the thesis' first membrane are not
    rng = np.random.default_rng(3)
    angle = rng.uniform(0, 2 * np.pi, 400)
    radius = np.sqrt(rng.uniform(0, 1, 400)) ** 1.5  # denser towards the centre
    uv = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    faces = Delaunay(uv).simplices.astype(np.int64)
    corners = uv[faces]
    turned = _signed_areas(corners) < 0
    faces[turned] = faces[turned][:, ::-1]
    affine = np.array([[1.0, 0.3], [-0.2, 0.7], [0.5, -0.4]])
    surface = uv @ affine.T + [0.1, 0.2, 0.3]
    filled = np.linalg.norm(uv, axis=1) < 0.5
    rim = np.unique(faces[filled[faces].any(axis=1)])
    rim = rim[~filled[rim]]
    start = surface.copy()
    start[filled] += rng.normal(scale=0.1, size=(filled.sum(), 3))
    weights = base_mean_value_weights(faces, np.zeros(len(uv), np.int64), uv, *HOME_ONLY, len(uv))
    assert np.allclose(weights.sum(axis=1), 1.0)
    placed = membrane_positions(start[None], faces, filled, [rim], weights=weights)[0]
    assert np.abs(placed - surface).max() < 1e-9
    uniform = membrane_positions(start[None], faces, filled, [rim])[0]
    assert np.abs(uniform - surface).max() > 1e-3


def test_a_hole_in_the_shirt_is_re_triangulated_on_the_base_and_stays_on_the_garment():
    shirt = tshirt(2, 0)
    vertices, faces = shirt.vertices[0], shirt.faces
    ellipses = initial_ellipses(vertices, faces, 4)
    anchors = np.array([e.center + e.radii.mean() * e.normal for e in ellipses])
    # a hole through the front of the torso, half-way up
    middle = np.abs(vertices[:, 1] - (0.4 * vertices[:, 1].min() + 0.6 * vertices[:, 1].max())) < 0.03
    centre = vertices[middle][np.argmax(vertices[middle, 2])]
    cut = np.linalg.norm(vertices[faces].mean(axis=1) - centre, axis=1) < 0.12
    used = np.unique(faces[~cut])
    index = np.full(len(vertices), -1)
    index[used] = np.arange(len(used))
    holed, holed_faces = vertices[used], index[faces[~cut]]
    loops = boundary_loops(holed_faces, len(holed))
    assert len(loops) == 5
    openings = [loops[int(np.argmin([np.linalg.norm(holed[loop].mean(axis=0) - e.center) for loop in loops]))]
                for e in ellipses]
    result = reparameterize_holes(holed, holed_faces, openings, anchors, base_mesh(anchors))
    # closed, genus 0: every edge in two faces, V - E + F = 2
    edges = np.sort(np.concatenate([result.faces[:, [0, 1]], result.faces[:, [1, 2]], result.faces[:, [2, 0]]]), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert np.all(uses == 2)
    assert len(result.vertices) - len(uses) + len(result.faces) == 2
    assert sum(result.flips) > 0 and len(result.stretches) >= 2
    assert np.isfinite(result.parameterization.stretch) and result.parameterization.stretch < 1.2
    # the re-projected membrane lies on the cut-out front (within 2% of the diagonal)
    distance, _ = cKDTree(vertices).query(result.vertices[result.filled])
    assert result.filled.sum() > 50
    assert np.median(distance) < 0.01 * shirt.diagonal()
