"""Pasting target-only geometry into the union mesh (thesis 5.6, second half): the patch glued
along the whole rim of a hole it fills, or along the part of the rim it runs beside when it
fills the hole only in part; the result manifold and consistently oriented either way."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.marching import compact
from fourd.methods.assembly import paste_target_only


def _ellipsoid():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    unit = np.asarray(sphere.vertices)
    bumps = 1.0 + 0.1 * np.sin(3.0 * unit[:, [0]]) * np.cos(2.0 * unit[:, [1]])
    return unit * [1.0, 0.7, 0.5] * bumps, np.asarray(sphere.faces, dtype=np.int64)


def _pasted(source_cut, target_cut):
    """The ellipsoid without the faces ``source_cut`` (centres [F, 3] -> bool) placed in the
    target frame (a small rigid motion), pasted with the moved ellipsoid without ``target_cut``."""
    vertices, faces = _ellipsoid()
    rotation = Rotation.from_rotvec([0.04, -0.03, 0.02]).as_matrix()
    moved = vertices @ rotation.T + [0.03, 0.02, -0.01]
    centres = vertices[faces].mean(axis=1)
    union, union_faces = compact(moved, faces[~source_cut(centres)])
    target, target_faces = compact(moved, faces[~target_cut(centres)])
    paste = paste_target_only(union, union_faces, target, target_faces)
    glued = trimesh.Trimesh(np.vstack([union, target[paste.target]]), paste.faces, process=False)
    edges = np.sort(glued.edges, axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert glued.is_winding_consistent and uses.max() == 2
    return paste, glued, union_faces, len(union)


def test_a_hole_the_target_fills_is_closed_along_its_whole_rim():
    paste, glued, _, _ = _pasted(lambda c: c[:, 0] > 0.7, lambda c: np.zeros(len(c), dtype=bool))
    assert paste.patches == 1 and paste.skipped == 0
    assert glued.is_watertight
    # the pasted vertices are the target's own, all in the source's hole
    assert (glued.vertices[-len(paste.target):, 0] > 0.6).all()


def test_a_hole_the_target_fills_in_part_is_glued_where_they_meet():
    paste, glued, union_faces, count = _pasted(
        lambda c: c[:, 0] > 0.7, lambda c: (c[:, 0] > 0.75) & (c[:, 1] > 0.1)
    )
    assert paste.patches == 1 and len(paste.target) > 0
    before = boundary_loops(union_faces, count)
    after = boundary_loops(paste.faces, len(glued.vertices))
    # measured: one loop of 76 vertices before, one of 48 after (what neither frame has)
    assert len(before) == len(after) == 1 and len(after[0]) < 0.8 * len(before[0])


def test_nothing_is_pasted_where_the_target_has_no_more():
    paste, _, union_faces, _ = _pasted(lambda c: c[:, 0] > 0.7, lambda c: c[:, 0] > 0.65)
    assert paste.patches == 0 and len(paste.target) == 0
    np.testing.assert_array_equal(paste.faces, union_faces)
