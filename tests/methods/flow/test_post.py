"""The flow's postprocessing: refinement, Laplace solve, implicit function, meshes."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from flow_scenes import (
    _check_closed_manifold,
    _fast_ball_field,
)

from fourd.methods.flow import (
    FlowField,
    Options,
)
from fourd.methods.flow.post import (
    _linear_weights,
    _stencil_csr,
    _upsample,
    drop_cavities,
)


@pytest.mark.parametrize("refine", [2, 3])
def test_upsample_is_scipys_linear_interpolation(refine):
    """The postprocessing's refinement of the coarse signed distance: ``map_coordinates`` with
    ``order=1, mode="nearest"`` at the fine nodes' coarse coordinates."""
    from scipy import ndimage

    coarse = np.random.default_rng(5).normal(size=(5, 6, 7))
    fine = np.empty(tuple(refine * n for n in coarse.shape), dtype=np.float32)
    axes = [_linear_weights(n, refine) for n in coarse.shape]
    _upsample(coarse, *axes[0], *axes[1], *axes[2], fine)
    coords = np.meshgrid(*[(np.arange(n) + 0.5) / refine - 0.5 for n in fine.shape], indexing="ij")
    expected = ndimage.map_coordinates(coarse, coords, order=1, mode="nearest")
    assert abs(fine - expected).max() < 1e-6


def test_stencil_rows_take_their_weights_from_the_slots():
    """The postprocessing's Laplace matrix from its slot table: the diagonal in slot 4, the
    temporal edges weighted by the slice's time weights, spatial ones by ``-smoothness``, empty
    slots skipped, entries in slot order."""
    columns = -np.ones((3, 9), dtype=np.int32)
    columns[:, 4] = [0, 1, 2]
    columns[0, 8] = 1  # row 0 (slice 0) -> next slice
    columns[1, 0] = 0  # row 1 (slice 1) -> previous slice
    columns[1, 6] = 2  # row 1: a spatial neighbour
    columns[2, 2] = 1  # row 2: a spatial neighbour
    nodes = np.array([3, 10 + 3, 10 + 5])  # 10 nodes per slice
    data, indices, indptr = _stencil_csr(
        columns, np.array([5.0, 6.0, 7.0]), nodes, 10, 0.5, np.array([0.2])
    )
    matrix = sp.csr_matrix((data, indices, indptr), shape=(3, 3)).toarray()
    assert np.array_equal(matrix, [[5.0, -0.1, 0.0], [-0.1, 6.0, -0.5], [0.0, -0.5, 7.0]])
    assert list(indices) == [0, 1, 0, 1, 2, 1, 2]


def test_a_part_faster_than_its_thickness_keeps_its_data_on_the_zero_level():
    field, grid, points = _fast_ball_field(Options().time_smoothness)
    for s, pts in enumerate(points):
        assert np.abs(field.value(pts, grid.times[s])).mean() < 0.2 * grid.h
    # the paper's 4D Laplace term (temporal edges like spatial ones) pulls the ball's data
    # towards the empty space of the neighbouring frames
    field, grid, points = _fast_ball_field(1.0)
    assert field.value(points[2], grid.times[2]).mean() > 0.5 * grid.h


def test_field_outside_grid_is_positive():
    values = -np.ones((2, 3, 3, 3), dtype=np.float32)
    field = FlowField(values, np.zeros(3), 1.0, np.array([0.0, 1.0]))
    assert field.value(np.array([[1.0, 1.0, 1.0]]), 0.5)[0] < 0
    assert field.value(np.array([[10.0, 1.0, 1.0]]), 0.5)[0] > 0


def test_redistanced_is_a_signed_distance_without_pockets():
    from fourd.methods.flow.post import extract_mesh, redistanced

    h, n = 0.05, 40
    grid = np.stack(np.meshgrid(*[-1.0 + h * np.arange(n)] * 3, indexing="ij"), axis=-1)
    radius = np.linalg.norm(grid, axis=-1)
    # a flat, non-distance-like field (gradient 0.2) with a small stray inside pocket
    values = 0.2 * (radius - 0.5)
    pocket = np.linalg.norm(grid - np.array([0.8, 0.8, 0.8]), axis=-1) < 0.08
    values[pocket] = -0.01
    field = FlowField(values[None], np.full(3, -1.0), h, np.array([0.0]))
    mesh = extract_mesh(field, 0, min_component=0.02)
    sdf = redistanced(field, np.array([0]), [mesh])
    truth = radius - 0.5
    near = np.abs(truth) < 2 * h
    assert np.abs(sdf.values[0][near] - truth[near]).max() < 0.15 * h
    assert np.abs(sdf.values[0] - truth).max() < 0.6 * h  # far: distance to the nearest vertex
    assert (sdf.values[0][pocket] > 0).all()
    probe = np.array([[0.3, 0.2, 0.1], [0.6, -0.1, 0.2]])
    gradient = sdf.gradient(probe, 0.0)[:, :3]
    assert np.allclose(np.linalg.norm(gradient, axis=1), 1.0, atol=0.1)


def test_mesh_distance_signs_a_hollow_ball_from_its_mesh_alone():
    """Two nested spheres (a hollow ball: the inner one faces inward): the grid's pieces are
    signed from the meshes alone, the shell's inside negative, the hollow positive."""
    from fourd.methods.flow.post import mesh_distance

    outer = trimesh.creation.icosphere(subdivisions=4, radius=0.6)
    inner = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    inner.invert()
    both = trimesh.util.concatenate([outer, inner])
    h = 0.04  # more than the meshes' edges (0.02-0.04)
    field = mesh_distance(both.vertices, both.faces, 2.0, h)
    assert field.times.tolist() == [2.0] and field.spacing == h
    nodes = field.nodes()
    radius = np.linalg.norm(nodes, axis=1)
    truth = np.maximum(radius - 0.6, 0.3 - radius)  # negative only between the spheres
    values = field.values[0].ravel()
    near = np.abs(truth) < 2 * h
    assert np.abs(values[near] - truth[near]).max() < 0.15 * h
    assert np.abs(values - truth).max() < 0.6 * h  # far: distance to the nearest vertex
    clear = np.abs(truth) > 0.15 * h
    assert np.array_equal(values[clear] < 0, truth[clear] < 0)
    assert (field.bounds()[0] <= -0.6 - 4 * h + 1e-9).all()


def test_a_flat_piece_touching_the_solid_is_dropped():
    """Closed pieces enclosing nothing that touch a sphere at one vertex (four coplanar
    points) or on one edge (a doubled flat triangle; marching cubes once left a doubled quad on
    two edges at resolution 64): each is a component of its own, below ``min_component``, and
    the mesh that is left is closed and manifold."""
    from fourd.geometry.meshes import component_volumes, remove_small_components

    sphere = trimesh.creation.icosphere(subdivisions=2)
    tip = int(np.argmax(sphere.vertices[:, 0]))  # (1, 0, 0) lies on the sphere
    flat = np.array([[1.5, 0.5, 0.0], [1.5, -0.5, 0.0], [2.0, 0.0, 0.0]])
    vertices = np.vstack([sphere.vertices, flat])
    n = len(sphere.vertices)
    p, q, r = n, n + 1, n + 2
    piece = np.array([[tip, p, q], [tip, q, r], [tip, r, p], [p, r, q]])
    faces = np.vstack([sphere.faces, piece])
    labels, volumes = component_volumes(vertices, faces)
    assert len(volumes) == 2 and abs(volumes).min() < 1e-12
    kept, kept_faces = remove_small_components(vertices, faces, min_fraction=0.02, measure="volume")
    assert len(kept_faces) == len(sphere.faces)
    _check_closed_manifold(kept, kept_faces)
    # a doubled flat triangle on one of the sphere's edges (that edge then has four faces)
    a, b = sphere.faces[0][:2]
    vertices = np.vstack([sphere.vertices, 1.5 * sphere.vertices[[a, b]].mean(axis=0)])
    faces = np.vstack([sphere.faces, [[a, b, n], [b, a, n]]])
    labels, volumes = component_volumes(vertices, faces)
    assert len(volumes) == 2 and abs(volumes).min() < 1e-12
    kept, kept_faces = remove_small_components(vertices, faces, min_fraction=0.02, measure="volume")
    assert len(kept_faces) == len(sphere.faces)
    _check_closed_manifold(kept, kept_faces)


def test_drop_cavities_keeps_the_solid_and_small_parts():
    """A cavity inside the solid (no outside scanner can see one) is dropped by
    ``drop_cavities``; the outer surface and a separate small-but-kept part stay."""
    from fourd.methods.flow.post import extract_mesh

    h, n = 0.05, 44
    grid = np.stack(np.meshgrid(*[-1.1 + h * np.arange(n)] * 3, indexing="ij"), axis=-1)
    radius = np.linalg.norm(grid, axis=-1)
    shell = np.maximum(radius - 0.7, 0.3 - radius)  # a ball of radius 0.7 around a hollow
    island = np.linalg.norm(grid - np.array([0.85, 0.85, 0.85]), axis=-1) - 0.15
    field = FlowField(np.minimum(shell, island)[None], np.full(3, -1.1), h, np.array([0.0]))
    volumes = {}
    mesh = extract_mesh(field, 0, min_component=0.005)
    for cavities in (False, True):
        vertices, faces = mesh if cavities else drop_cavities(*mesh)[:2]
        parts = trimesh.Trimesh(vertices, faces, process=False).split(only_watertight=True)
        volumes[cavities] = sorted(round(float(p.volume), 2) for p in parts)
    ball, hollow, small = 4 / 3 * np.pi * np.array([0.7**3, 0.3**3, 0.15**3])
    assert len(volumes[True]) == 3 and volumes[True][0] < 0
    assert np.allclose(volumes[True], [-hollow, small, ball], atol=0.02)
    assert np.allclose(volumes[False], [small, ball], atol=0.02)
