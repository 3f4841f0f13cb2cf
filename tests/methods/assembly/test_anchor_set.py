"""Cleaning an anchor set (thesis 5.4.1): the forward-backward check drops wrong anchors and
keeps right ones; spreading leaves anchors at a roughly uniform density."""

from __future__ import annotations

import numpy as np
import pytest
from assembly_shapes import remeshed_frames, rigid_copy, spread, true_map
from scipy.spatial import cKDTree

from fourd.geometry.surface_walk import face_unit_normals, walk_on_surface
from fourd.methods.assembly import Anchors, consistent_anchors, returned_points, spread_anchors


def _anchors_of(pair, faces, bary, ids):
    return Anchors(ids, faces[ids], bary[ids])


def test_the_round_trip_drops_wrong_anchors_and_keeps_right_ones():
    pair = remeshed_frames()  # bending-arm frames 0 and 3, each remeshed on its own
    ids = spread(pair.source_vertices, 90)
    wrong = np.zeros(len(ids), dtype=bool)
    wrong[::3] = True
    true_faces, true_bary = true_map(pair)
    step = np.random.default_rng(4).normal(size=(len(ids), 3))
    normal = face_unit_normals(pair.target_vertices, pair.target_faces)[true_faces[ids]]
    step -= np.einsum("ad,ad->a", step, normal)[:, None] * normal
    step *= 3.0 * pair.edge / np.linalg.norm(step, axis=1, keepdims=True)
    slid = walk_on_surface(pair.target_vertices, pair.target_faces, true_faces[ids], true_bary[ids], step)
    faces = np.where(wrong, slid.faces, true_faces[ids])
    bary = np.where(wrong[:, None], slid.barycentric, true_bary[ids])
    anchors = Anchors(ids, faces, bary)
    off = np.linalg.norm(anchors.target_points(pair.target_vertices, pair.target_faces) - pair.truth[ids], axis=1)
    assert off[wrong].min() > 2.0 * pair.edge  # they are wrong
    returned = returned_points(anchors, pair.target_faces, pair.back)  # the true backward map
    keep = consistent_anchors(anchors, pair.source_vertices, returned, 0.5 * pair.edge)
    np.testing.assert_array_equal(keep, ~wrong)
    # measured: the right ones return within 0.09 edges (the closest target point to the true
    # image is off it by the remeshes' distance from the truth between their vertices)
    gap = np.linalg.norm(returned - pair.source_vertices[ids], axis=1) / pair.edge
    assert gap[~wrong].max() < 0.2
    with pytest.raises(ValueError, match="tolerance"):
        consistent_anchors(anchors, pair.source_vertices, returned, 0.0)


def test_spreading_every_vertex_leaves_a_uniform_cover():
    pair = rigid_copy()
    faces, bary = true_map(pair)
    everything = _anchors_of(pair, faces, bary, np.arange(len(faces)))
    spacing = 3.0 * pair.edge
    kept = spread_anchors(everything, pair.source_vertices, spacing)
    points = pair.source_vertices[everything.source[kept]]
    gaps, _ = cKDTree(points).query(points, k=2)
    assert gaps[:, 1].min() >= spacing  # no two closer than the spacing
    reach, _ = cKDTree(points).query(pair.source_vertices)
    assert reach.max() < spacing  # every vertex has one within the spacing (maximal)
    # roughly uniform: the distance to the nearest other kept anchor varies little
    # (measured: 1.11 +- 0.07 spacings, at most 1.26)
    assert gaps[:, 1].std() < 0.15 * gaps[:, 1].mean() and gaps[:, 1].max() < 2.0 * spacing


def test_spreading_thins_a_crowd_to_the_density_elsewhere():
    pair = rigid_copy()
    faces, bary = true_map(pair)
    rng = np.random.default_rng(5)
    cap = pair.source_vertices[:, 2] > 0.4
    ids = np.flatnonzero(cap | (rng.random(len(faces)) < 0.25))  # crowded in the cap
    anchors = _anchors_of(pair, faces, bary, ids)
    spacing = 3.0 * pair.edge
    kept = spread_anchors(anchors, pair.source_vertices, spacing)
    everywhere = spread_anchors(_anchors_of(pair, faces, bary, np.arange(len(faces))), pair.source_vertices, spacing)
    in_cap = cap[ids[kept]].sum()
    uniform_in_cap = cap[everywhere].sum()
    assert abs(in_cap - uniform_in_cap) <= 0.3 * uniform_in_cap
    share_before = cap[ids].mean()
    share_after = cap[ids[kept]].mean()
    assert share_after < 0.7 * share_before  # measured: 0.60 -> 0.32 (10 kept, 13 if uniform)


def test_spreading_keeps_the_kept_and_prefers_the_higher_priority():
    pair = rigid_copy()
    faces, bary = true_map(pair)
    ids = np.arange(len(faces))
    anchors = _anchors_of(pair, faces, bary, ids)
    keep = np.zeros(len(ids), dtype=bool)
    nearest = int(np.argsort(np.linalg.norm(pair.source_vertices - pair.source_vertices[0], axis=1))[1])
    keep[[0, nearest]] = True  # an edge apart: both stay
    spacing = 3.0 * pair.edge
    kept = spread_anchors(anchors, pair.source_vertices, spacing, keep=keep)
    assert kept[[0, nearest]].all()
    near = np.linalg.norm(pair.source_vertices - pair.source_vertices[0], axis=1) < spacing
    assert kept[near].sum() == 2  # nothing else near the kept ones
    priority = -np.linalg.norm(pair.source_vertices - pair.source_vertices[7], axis=1)
    chosen = spread_anchors(anchors, pair.source_vertices, spacing, priority=priority)
    assert chosen[7]  # the highest priority always stays
    with pytest.raises(ValueError, match="spacing"):
        spread_anchors(anchors, pair.source_vertices, 0.0)
