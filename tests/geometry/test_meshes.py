"""Mesh helpers: enclosed volume, adjacency, components and their removal."""

import numpy as np
import pytest

from fourd.geometry.marching import marching_cubes
from fourd.geometry.meshes import (
    component_volumes,
    enclosed_volume,
    face_pieces,
    face_volumes,
    remove_small_components,
    vertex_adjacency,
    vertex_components,
)

# the unit cube [0, 1]^3, faces wound outwards
CUBE_VERTICES = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    dtype=float,
)
CUBE_FACES = np.array(
    [
        [0, 2, 1], [0, 3, 2],  # z = 0
        [4, 5, 6], [4, 6, 7],  # z = 1
        [0, 1, 5], [0, 5, 4],  # y = 0
        [3, 6, 2], [3, 7, 6],  # y = 1
        [0, 4, 7], [0, 7, 3],  # x = 0
        [1, 2, 6], [1, 6, 5],  # x = 1
    ]
)  # fmt: skip
TETRAHEDRON = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def _spheres(centres, radii, cells=48):
    g = np.linspace(-1.0, 1.0, cells)
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1)
    values = np.min(
        [np.linalg.norm(x - np.asarray(c), axis=-1) - r for c, r in zip(centres, radii, strict=True)],
        axis=0,
    )
    return marching_cubes(values, origin=np.full(3, -1.0), spacing=g[1] - g[0])


def test_the_unit_cube_encloses_volume_one_wherever_it_is():
    assert enclosed_volume(CUBE_VERTICES, CUBE_FACES) == pytest.approx(1.0, abs=1e-12)
    assert enclosed_volume(CUBE_VERTICES + [3.0, -2.0, 5.0], CUBE_FACES) == pytest.approx(1.0)
    assert face_volumes(CUBE_VERTICES, CUBE_FACES).sum() == pytest.approx(1.0, abs=1e-12)
    # inward winding: the signed sum turns negative, the enclosed volume stays positive
    assert face_volumes(CUBE_VERTICES, CUBE_FACES[:, ::-1]).sum() == pytest.approx(-1.0)
    assert enclosed_volume(CUBE_VERTICES, CUBE_FACES[:, ::-1]) == pytest.approx(1.0)


def test_a_sphere_encloses_four_thirds_pi_r_cubed():
    r = 0.6
    vertices, faces = _spheres([(0.0, 0.0, 0.0)], [r])
    exact = 4.0 / 3.0 * np.pi * r**3
    volume = enclosed_volume(vertices, faces)
    assert volume < exact  # an inscribed polyhedron
    assert volume > 0.98 * exact


def test_the_adjacency_of_a_tetrahedron_joins_every_pair_of_vertices():
    adjacency = vertex_adjacency(TETRAHEDRON, 4)
    np.testing.assert_array_equal(adjacency.toarray(), 1.0 - np.eye(4))
    assert adjacency.has_canonical_format
    count, labels = vertex_components(TETRAHEDRON, 5)  # vertex 4 belongs to no face
    assert count == 2
    np.testing.assert_array_equal(labels, [0, 0, 0, 0, 1])


def test_component_removal_keeps_the_big_sphere():
    vertices, faces = _spheres([(-0.4, 0.0, 0.0), (0.6, 0.0, 0.0)], [0.45, 0.15])
    count, _ = vertex_components(faces, len(vertices))
    assert count == 2
    for kept, kept_faces in (
        remove_small_components(vertices, faces, min_fraction=0.5),
        remove_small_components(vertices, faces, min_faces=len(faces) // 2),
        remove_small_components(vertices, faces, min_fraction=0.5, measure="volume"),
    ):
        assert vertex_components(kept_faces, len(kept))[0] == 1
        assert kept[:, 0].max() < 0.1  # only the sphere about x = -0.4
        assert enclosed_volume(kept, kept_faces) == pytest.approx(4 / 3 * np.pi * 0.45**3, rel=0.03)
    # nothing below the limit: the same arrays back
    same = remove_small_components(vertices, faces, min_fraction=0.001)
    assert same[0] is vertices and same[1] is faces
    with pytest.raises(ValueError, match="measure"):
        remove_small_components(vertices, faces, min_fraction=0.5, measure="area")


def test_closed_components_carry_their_signed_volumes():
    inner = CUBE_VERTICES * 0.5 + 0.25
    vertices = np.vstack([CUBE_VERTICES * 2.0 - 0.5, inner])
    faces = np.vstack([CUBE_FACES, CUBE_FACES[:, ::-1] + 8])  # a cube with a cavity
    labels, volumes = component_volumes(vertices, faces)
    assert len(volumes) == 2
    assert sorted(volumes) == pytest.approx([-0.125, 8.0])
    assert len(set(labels[:12])) == 1 and len(set(labels[12:])) == 1


def test_a_book_of_three_pages_is_one_piece_or_three_by_the_joining_rule():
    """A book of three pages on one spine (edge 0-1), each page two triangles, and a fourth
    triangle touching page one at a vertex only."""
    faces = np.array(
        [[0, 1, 2], [1, 3, 2], [1, 0, 4], [1, 4, 5], [0, 1, 6], [6, 1, 7], [3, 8, 9]]
    )
    count, labels = face_pieces(faces)
    assert count == 2 and len(set(labels[:6])) == 1 and labels[6] != labels[0]
    count, labels = face_pieces(faces, manifold_only=True)
    assert count == 4
    assert labels.tolist() == [0, 0, 1, 1, 2, 2, 3]  # numbered by each piece's first face
    # component_volumes joins by the manifold rule: the pages are components of their own
    vertices = np.random.default_rng(0).random((10, 3))
    assert component_volumes(vertices, faces)[0].tolist() == labels.tolist()
