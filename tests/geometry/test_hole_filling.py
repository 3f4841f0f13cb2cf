import numpy as np
import pytest
import trimesh

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.hole_filling import fill_holes, membrane_positions, small_holes
from fourd.geometry.polygon_triangulation import signed_area, triangle_areas, triangulate_polygon


def _capped_sphere(cut):
    sphere = trimesh.creation.icosphere(4)
    keep = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] < cut
    return np.asarray(sphere.vertices), np.asarray(sphere.faces)[keep]


def test_a_filled_hole_closes_the_mesh_with_faces_turned_like_their_neighbours():
    vertices, faces = _capped_sphere(0.8)
    filled = fill_holes(vertices, faces)
    mesh = trimesh.Trimesh(filled.vertices, filled.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    np.testing.assert_array_equal(filled.vertices[: len(vertices)], vertices)  # old vertices kept
    assert filled.filled.sum() == len(filled.vertices) - len(vertices) > 0


def test_the_smooth_membrane_follows_the_surface_where_the_flat_one_creases():
    """A spherical cap removed: the C1 membrane bulges like the sphere (within 2.5% of its
    radius), the C0 membrane stays near the flat disk of the hole (thesis Figure 3.8)."""
    vertices, faces = _capped_sphere(0.8)
    deviation = {}
    for smooth in (False, True):
        filled = fill_holes(vertices, faces, smooth=smooth)
        deviation[smooth] = np.abs(np.linalg.norm(filled.vertices[filled.filled], axis=1) - 1).max()
    assert deviation[True] < 0.025 < 0.15 < deviation[False]


def test_only_the_small_holes_when_asked():
    vertices, faces = _capped_sphere(0.8)
    bottom = vertices[faces].mean(axis=1)[:, 2] > -0.9  # a second, smaller hole at the bottom
    loops = boundary_loops(faces[bottom], len(vertices))
    filled = fill_holes(vertices, faces[bottom], max_loop=min(len(loop) for loop in loops))
    remaining = boundary_loops(filled.faces, len(filled.vertices))
    assert len(loops) == 2 and len(remaining) == 1 and len(remaining[0]) == max(len(loop) for loop in loops)


def test_the_membrane_follows_every_frame_of_a_moving_rim():
    """Frames of a capped sphere moved rigidly (turned and shifted) and one scaled: the
    membrane of each frame is frame 0's moved the same way (the membrane is a linear function
    of the rim, invariant under similarities)."""
    vertices, faces = _capped_sphere(0.8)
    filled = fill_holes(vertices, faces)
    angle = 0.7
    turn = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    truth = np.stack([filled.vertices, filled.vertices @ turn.T + [0.3, -1.0, 2.0], 1.5 * filled.vertices])
    start = truth.copy()
    start[:, filled.filled] = 0.0  # unknown: only the rim and the rest count
    placed = membrane_positions(start, filled.faces, filled.filled, filled.holes)
    np.testing.assert_allclose(placed, truth, atol=1e-9)
    # the C1 terms' weight: 1 is the C1 membrane, 0 the flat one, between lies between
    heights = {}
    for smooth in (0.0, 0.3, 1.0):
        filled = fill_holes(vertices, faces, smooth=smooth)
        heights[smooth] = filled.vertices[filled.filled, 2].max()
    flat = fill_holes(vertices, faces, smooth=False)
    np.testing.assert_allclose(heights[0.0], flat.vertices[flat.filled, 2].max())
    assert heights[0.0] < heights[0.3] < heights[1.0] < 1.025  # measured 0.807, 0.970, 1.018


def test_small_holes_are_the_holes_of_a_body_not_the_outline_of_a_sheet():
    vertices, faces = _capped_sphere(0.8)  # a cap missing: its flat disk 10% of the rest
    assert len(small_holes(vertices, faces, max_fraction=0.12)) == 1
    assert small_holes(vertices, faces, max_fraction=0.08) == []
    grid = trimesh.creation.box().subdivide().subdivide()  # an open box: a sheet bent up
    top = grid.vertices[grid.faces].mean(axis=1)[:, 2] < 0.49
    assert small_holes(grid.vertices, grid.faces[top], max_fraction=0.1) == []  # its opening: a fifth
    plane = trimesh.creation.box(extents=(1, 1, 0.01))
    sheet = plane.faces[plane.vertices[plane.faces].mean(axis=1)[:, 2] > 0]  # one side: all outline
    assert small_holes(plane.vertices, sheet, max_fraction=0.5) == []


def test_polygon_triangulation_keeps_the_outline_and_covers_it():
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    radius = 1 + 0.4 * np.cos(5 * angles)  # a star: strongly concave
    polygon = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    points, faces = triangulate_polygon(polygon, 0.1)
    np.testing.assert_array_equal(points[:40], polygon)
    areas = triangle_areas(points, faces)
    assert (areas > 0).all() and abs(areas.sum() - signed_area(polygon)) < 1e-9
    with pytest.raises(InputError):
        triangulate_polygon(polygon[::-1], 0.1)  # clockwise


@pytest.mark.parametrize("kept", [0, 1, 2])
def test_a_face_poking_into_a_hole_does_not_make_the_filled_mesh_non_manifold(kept):
    """A hole around a face that juts into it (seen in assembly's dfaust-hopping result: 4
    sides of 4 faces): one face of an icosphere split at its centre, two of the three parts
    removed. The loop of four vertices has a chord that is a side of the kept part already;
    the filled mesh must still be closed, manifold and oriented."""
    from fourd.metrics.topology import topology

    sphere = trimesh.creation.icosphere(2)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    a, b, c = faces[0]
    centre = len(vertices)
    vertices = np.vstack([vertices, vertices[faces[0]].mean(axis=0) * 1.01])
    parts = np.array([[a, b, centre], [b, c, centre], [c, a, centre]])
    faces = np.vstack([faces[1:], parts[kept]])
    filled = fill_holes(vertices, faces)
    found = topology(filled.faces, len(filled.vertices))
    assert found.closed_manifold and found.oriented, found
