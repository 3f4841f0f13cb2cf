"""Anchor set refinement (thesis 5.4.4): the source registered in the target's frame by its
Laplacian coordinates, and anchors added where it lands on the target, none over a hole."""

from __future__ import annotations

import numpy as np
import pytest
from assembly_shapes import remeshed_frames, rigid_copy

from fourd.methods.assembly import (
    RefineOptions,
    anchors_at_vertices,
    refine_anchors,
    register_by_laplacian,
)


def _near(points, index, radius):
    return np.linalg.norm(points - points[index], axis=1) < radius


def test_registration_recovers_a_rigid_motion_exactly():
    pair = rigid_copy()
    hole = _near(pair.source_vertices, 5, 0.9)  # 130 of 642 vertices
    placed = register_by_laplacian(pair.source_vertices, pair.source_faces, ~hole, pair.truth)
    np.testing.assert_array_equal(placed[~hole], pair.truth[~hole])
    assert np.abs(placed - pair.truth).max() < 1e-9 * pair.edge  # measured: 3e-13 edges
    # several frames at once (one factorisation): each as it comes alone
    moved = pair.truth + np.array([0.0, 0.0, 0.3])
    both = register_by_laplacian(pair.source_vertices, pair.source_faces, ~hole, np.stack([pair.truth, moved]))
    assert both.shape == (2,) + pair.truth.shape
    np.testing.assert_allclose(both[0], placed, rtol=0, atol=1e-12)
    single = register_by_laplacian(pair.source_vertices, pair.source_faces, ~hole, moved)
    np.testing.assert_allclose(both[1], single, rtol=0, atol=1e-12)


def test_registration_fills_a_hole_in_a_bent_frame_near_the_truth():
    pair = remeshed_frames()  # bending-arm frames 0 and 3, each remeshed on its own
    hole = _near(pair.source_vertices, 500, 6.0 * pair.edge)  # at the bend
    placed = register_by_laplacian(pair.source_vertices, pair.source_faces, ~hole, pair.truth)
    error = np.linalg.norm(placed - pair.truth, axis=1)[hole] / pair.edge
    # measured: median 0.20, 95th percentile 0.53 source edges (182 vertices; cotangent
    # 0.12 / 0.35); away from the bend (vertex 100) 0.02 / 0.06
    assert np.median(error) < 0.3 and np.percentile(error, 95) < 0.8
    floating = register_by_laplacian(pair.source_vertices, pair.source_faces,
                                      np.zeros(len(hole), dtype=bool), pair.truth)
    assert np.isnan(floating).all()  # nothing to hold it: nowhere
    with pytest.raises(ValueError, match="one row per source vertex"):
        register_by_laplacian(pair.source_vertices, pair.source_faces, hole[:-1], pair.truth)


def test_anchors_are_added_where_the_surfaces_touch_and_not_over_a_hole():
    pair = rigid_copy()
    vertices = pair.source_vertices
    hole = _near(vertices, 5, 0.5)  # the target has no surface here
    sparse = _near(vertices, 300, 0.5)  # the target is here, the anchors and the map are not
    assert not (hole & sparse).any()
    target_faces = pair.target_faces[~hole[pair.target_faces].any(axis=1)]
    unmapped = hole | sparse
    mapped = np.flatnonzero(~unmapped)
    identity = anchors_at_vertices(mapped, mapped, target_faces)
    faces = np.full(len(vertices), -1)
    bary = np.zeros((len(vertices), 3))
    faces[mapped], bary[mapped] = identity.target_faces, identity.target_barycentric
    ids = pair.anchors.source[~unmapped[pair.anchors.source]]
    anchors = anchors_at_vertices(ids, ids, target_faces)
    options = RefineOptions(spacing=2.0)
    result = refine_anchors(vertices, pair.source_faces, pair.target_vertices, target_faces, anchors,
                            faces, bary, options)
    assert len(result.added) >= 3
    assert sparse[result.added].all() and not hole[result.added].any()
    assert len(result.anchors.source) == len(anchors.source) + len(result.added)
    np.testing.assert_array_equal(result.anchors.source[: len(ids)], ids)
    added = result.anchors.subset(np.arange(len(result.anchors.source)) >= len(ids))
    points = added.target_points(pair.target_vertices, target_faces)
    assert np.abs(points - pair.truth[result.added]).max() < 1e-6 * pair.edge
    # over the hole the registered source lies off the target (the rim is an edge away)
    assert np.nanmin(result.distance[hole]) > options.touch * pair.edge
    assert np.nanmax(result.distance[sparse]) < 1e-6 * pair.edge
    # the added anchors keep the spacing among themselves and from the anchors there were
    every = vertices[result.anchors.source]
    for vertex in result.added:
        gaps = np.linalg.norm(every - vertices[vertex], axis=1)
        assert np.sort(gaps)[1] >= options.spacing * pair.edge


def test_refine_options_are_checked():
    with pytest.raises(ValueError, match="touch"):
        RefineOptions(touch=0.0)
    with pytest.raises(ValueError, match="iterations"):
        RefineOptions(iterations=-1)
