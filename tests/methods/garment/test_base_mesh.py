"""The base-mesh parameterisation of a garment (thesis 3.6.2) on the generated T-shirt."""

import numpy as np
import pytest

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.rotations import procrustes
from fourd.methods.garment.base_mesh import (
    base_edges,
    base_mesh,
    closed_surface,
    map_through_base,
    parameterize_onto_base,
    vertex_base_coordinates,
)
from fourd.methods.garment.boundary_tracking import initial_ellipses
from fourd.synth.garments import tshirt


@pytest.fixture(scope="module")
def shirt():
    return tshirt(20, 0)


def _opened(vertices, faces, reference=None):
    """The T-shirt's four openings and their anchors (one mean radius out along each opening's
    normal), in the order of the ``reference`` centres when given."""
    loops = [loop for loop in boundary_loops(faces, len(vertices)) if len(loop) >= 6]
    ellipses = initial_ellipses(vertices, faces, 4)
    centres = np.array([e.center for e in ellipses])
    order = np.arange(4) if reference is None else [int(np.argmin(np.linalg.norm(centres - c, axis=1))) for c in reference]
    ellipses = [ellipses[k] for k in order]
    loops = [loops[int(np.argmin([np.linalg.norm(vertices[loop].mean(axis=0) - e.center) for loop in loops]))]
             for e in ellipses]
    anchors = np.array([e.center + e.radii.mean() * e.normal for e in ellipses])
    return loops, anchors, np.array([e.center for e in ellipses])


def _parameterized(vertices, faces, base, reference=None, guides=None, reach=0.0):
    loops, anchors, centres = _opened(vertices, faces, reference)
    closed_vertices, closed_faces, apex = closed_surface(vertices, faces, loops, anchors)
    result = parameterize_onto_base(closed_vertices, closed_faces, apex, base, guides=guides, reach=reach)
    return closed_vertices, closed_faces, apex, result, anchors, centres


def test_four_anchors_make_a_tetrahedron_turned_outward():
    anchors = np.array([[0.0, 1.0, 0.1], [0.0, -1.0, 0.0], [-1.0, 0.2, -0.1], [1.0, 0.2, 0.05]])
    base = base_mesh(anchors)
    corners = anchors[base.faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.all(np.einsum("fd,fd->f", normals, corners.mean(axis=1) - anchors.mean(axis=0)) > 0)
    assert len(base_edges(base)) == 6
    with pytest.raises(InputError, match="3 or 4 openings"):
        base_mesh(anchors[:2])


def _orientations(result, base):
    """Each row's triangle in its facet's plane, signed against the facet's normal."""
    corners = np.einsum("rck,rkd->rcd", result.corners, base.vertices[base.faces[result.chart]])
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    facet = base.vertices[base.faces[result.chart]]
    facet_normal = np.cross(facet[:, 1] - facet[:, 0], facet[:, 2] - facet[:, 0])
    return np.einsum("rd,rd->r", normal, facet_normal)


def test_the_shirt_is_cut_into_four_charts_each_mapped_one_to_one(shirt):
    vertices, faces = shirt.vertices[0], shirt.faces
    _, anchors, _ = _opened(vertices, faces)
    base = base_mesh(anchors)
    loops, _, _ = _opened(vertices, faces)
    closed_vertices, closed_faces, apex = closed_surface(vertices, faces, loops, anchors)
    fixed = parameterize_onto_base(closed_vertices, closed_faces, apex, base, slide=False)
    assert sorted(set(fixed.chart.tolist())) == [0, 1, 2, 3]
    # with the borders on the base edges each face lies in its chart's facet (a border face
    # also has a row in the facet across, unfolded there)
    own = fixed.chart == fixed.charts.chart[fixed.face]
    assert np.array_equal(np.unique(fixed.face[own]), np.arange(len(closed_faces)))
    assert np.all(fixed.corners[own] >= -1e-9)
    # every triangle keeps its orientation in its facet: the map is one to one
    assert np.all(_orientations(fixed, base) > 0)
    # a vertex on a chart border names one base point from every chart it is in
    points = np.einsum("fck,fkd->fcd", fixed.corners[own], base.vertices[base.faces[fixed.chart[own]]])
    for path in fixed.charts.paths:
        for vertex in path[1:-1]:
            at = points[closed_faces[fixed.face[own]] == vertex]
            assert np.ptp(at, axis=0).max() < 1e-9
    assert np.allclose(points[closed_faces[fixed.face[own]] == apex[0]], base.vertices[0])
    assert 1.0 <= fixed.stretch < 1.3
    # sliding across the borders keeps the map one to one and about as little stretched
    slid = parameterize_onto_base(closed_vertices, closed_faces, apex, base)
    assert 1.0 <= slid.stretch < 1.2
    assert np.all(_orientations(slid, base) > 0)
    assert np.all(slid.vertex_facet >= 0) and np.all(slid.vertex_barycentric >= 0)
    anchor_points = np.einsum("ak,akd->ad", slid.vertex_barycentric[apex], base.vertices[base.faces[slid.vertex_facet[apex]]])
    assert np.allclose(anchor_points, base.vertices)


def test_a_moved_copy_maps_onto_itself_through_the_base(shirt):
    vertices, faces = shirt.vertices[0], shirt.faces
    _, anchors, centres = _opened(vertices, faces)
    base = base_mesh(anchors)
    closed_vertices, closed_faces, _, first, _, _ = _parameterized(vertices, faces, base)
    angle = 0.7
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    moved = 1.3 * vertices @ turn.T + [0.2, -0.1, 0.4]
    moved_vertices, moved_faces, _, second, _, _ = _parameterized(moved, faces, base, reference=1.3 * centres @ turn.T + [0.2, -0.1, 0.4])
    facets, barycentric = vertex_base_coordinates(first, len(vertices))
    points, _, _ = map_through_base(facets, barycentric, moved_vertices, moved_faces, second)
    assert np.abs(points - moved).max() < 1e-6 * np.ptp(moved)
    # the same surface cut along the first one's paths (same connectivity): the same map
    along = parameterize_onto_base(moved_vertices, moved_faces, np.arange(len(vertices), len(vertices) + 4), base,
                                   paths=first.charts.paths)
    assert [np.array_equal(a, b) for a, b in zip(along.charts.paths, first.charts.paths, strict=True)] == [True] * 6
    points, _, _ = map_through_base(facets, barycentric, moved_vertices, moved_faces, along)
    assert np.abs(points - moved).max() < 1e-6 * np.ptp(moved)


def test_a_nearby_pose_maps_close_to_its_true_points_through_the_base(shirt):
    faces = shirt.faces
    _, anchors, centres = _opened(shirt.vertices[0], faces)
    base = base_mesh(anchors)
    closed_vertices, closed_faces, _, first, _, _ = _parameterized(shirt.vertices[0], faces, base)
    later = shirt.vertices[10]
    loops, later_anchors, _ = _opened(later, faces, centres)
    # the first frame's paths brought over by the anchors' similarity guide the later ones
    move = procrustes(anchors, later_anchors, with_scale=True)
    guides = [move.scale * closed_vertices[path] @ move.rotation.T + move.translation for path in first.charts.paths]
    reach = 0.3 * np.median(np.linalg.norm(later_anchors[:, None] - later_anchors[None], axis=2)[np.triu_indices(4, 1)])
    later_vertices, later_faces, _, second, _, _ = _parameterized(later, faces, base, centres, guides, reach)
    facets, barycentric = vertex_base_coordinates(first, len(later))
    points, _, _ = map_through_base(facets, barycentric, later_vertices, later_faces, second)
    error = np.linalg.norm(points - later, axis=1) / shirt.diagonal()
    assert np.median(error) < 0.004 and np.quantile(error, 0.95) < 0.015


def test_openings_and_anchors_must_agree(shirt):
    vertices, faces = shirt.vertices[0], shirt.faces
    loops, anchors, _ = _opened(vertices, faces)
    with pytest.raises(InputError, match="3 opening loops for 4 anchors"):
        closed_surface(vertices, faces, loops[:3], anchors)
