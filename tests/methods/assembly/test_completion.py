"""Pasting target-only geometry into the union mesh (thesis 5.6, second half): the patch glued
along the whole rim of a hole it fills, or along the part of the rim it runs beside when it
fills the hole only in part; the result manifold and consistently oriented either way."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.marching import compact
from fourd.methods.assembly import paste_target_only, place_pasted


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


def _tube(along: int = 48, around: int = 24):
    """A tube of radius 0.25 along x from -1 to 1, open at both ends: vertices, faces."""
    x, angle = np.meshgrid(np.linspace(-1.0, 1.0, along), np.linspace(0.0, 2 * np.pi, around, endpoint=False),
                           indexing="ij")
    vertices = np.stack([x.ravel(), 0.25 * np.cos(angle).ravel(), 0.25 * np.sin(angle).ravel()], axis=1)
    ids = np.arange(along * around).reshape(along, around)
    a, b = ids[:-1], np.roll(ids, -1, axis=1)[:-1]
    c, d = ids[1:], np.roll(ids, -1, axis=1)[1:]
    faces = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    return vertices, faces


def _bent(vertices, bend, twist):
    """The tube bent by ``bend`` radians along an arc and twisted by ``twist`` about its axis."""
    s = vertices[:, 0] + 1.0
    k = max(bend / 2.0, 1e-9)
    centre = np.stack([np.sin(k * s) / k, (1.0 - np.cos(k * s)) / k, np.zeros_like(s)], axis=1)
    normal = np.stack([-np.sin(k * s), np.cos(k * s), np.zeros_like(s)], axis=1)
    a = twist * s / 2.0
    y = vertices[:, 1] * np.cos(a) - vertices[:, 2] * np.sin(a)
    z = vertices[:, 1] * np.sin(a) + vertices[:, 2] * np.cos(a)
    return centre + y[:, None] * normal + z[:, None] * [0.0, 0.0, 1.0]


def test_pasted_geometry_follows_its_surroundings_back_through_every_earlier_frame():
    """A patch on the inside of a tube that bends by 200 degrees and twists by 180 over nine
    frames, known only in the last: placed in the eight before it from the tube around it, it
    lies on the truth in each."""
    vertices, faces = _tube()
    frames = np.array([_bent(vertices, np.radians(200) * t / 8, np.radians(180) * t / 8) for t in range(9)])
    centres = vertices[faces].mean(axis=1)
    patch = (np.abs(centres[:, 0]) < 0.5) & (centres[:, 1] > 0.05)
    known = np.zeros(len(vertices), dtype=bool)
    known[faces[~patch].ravel()] = True
    points = frames[:-1].copy()
    points[:, ~known] = 0.0
    placed = place_pasted(frames[-1], faces, known, points)
    edge = np.linalg.norm(vertices[faces[:, 0]] - vertices[faces[:, 1]], axis=1).mean()
    error = np.linalg.norm(placed[:, ~known] - frames[:-1, ~known], axis=2) / edge
    np.testing.assert_array_equal(placed[:, known], frames[:-1, known])
    # measured: 0.056 / 0.14 edges median / largest in the first frame, the farthest back
    assert (~known).sum() > 150
    assert np.median(error[0]) < 0.1 and error.max() < 0.25
