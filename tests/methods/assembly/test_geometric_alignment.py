"""The coarse non-rigid alignment the geometric anchors come from (``alignment.py``)."""

from __future__ import annotations

import numpy as np
from assembly_shapes import remeshed_frames, rigid_copy

from fourd.geometry.normals import vertex_normals
from fourd.methods.assembly.alignment import geometric_anchors, nonrigid_icp


def _errors(pair, alignment):
    """Aligned positions' and anchors' distances to the true images, in source edges."""
    aligned = np.linalg.norm(alignment.aligned - pair.truth, axis=1) / pair.edge
    anchors = alignment.anchors
    points = np.einsum("nk,nkd->nd", anchors.target_barycentric,
                       pair.target_vertices[pair.target_faces[anchors.target_faces]])
    at_anchors = np.linalg.norm(points - pair.truth[anchors.source], axis=1) / pair.edge
    return aligned, at_anchors


def test_a_bent_arm_moves_as_a_whole():
    """bending-arm frames 0 and 5, remeshed apart: the forearm swings several of its widths.
    Three nearest-point steps left a tenth of the vertices 15 edges off (95th percentile); the
    stiff ARAP-ICP brings the forearm along (about 4)."""
    pair = remeshed_frames(frame=5)
    alignment = geometric_anchors(pair.source_vertices, pair.source_faces, pair.target_vertices, pair.target_faces)
    aligned, at_anchors = _errors(pair, alignment)
    assert np.percentile(aligned, 95) < 6.0
    assert np.percentile(at_anchors, 95) < 6.0
    assert len(alignment.anchors.source) > 0.03 * len(pair.source_vertices)


def test_a_small_step_stays_within_an_edge():
    pair = remeshed_frames(frame=1)
    alignment = geometric_anchors(pair.source_vertices, pair.source_faces, pair.target_vertices, pair.target_faces)
    aligned, at_anchors = _errors(pair, alignment)
    assert np.median(aligned) < 1.0 and np.median(at_anchors) < 1.0


def test_nonrigid_icp_keeps_a_registered_copy_in_place():
    """Started on its rigidly moved copy, the source stays there (the ARAP term's rest shape
    is the copy's, every pull points at itself)."""
    pair = rigid_copy()
    normals = vertex_normals(pair.target_vertices, pair.target_faces)
    placed = nonrigid_icp(pair.source_vertices, pair.source_faces, pair.target_vertices, normals,
                          pair.target_vertices, iterations=10)
    assert np.abs(placed - pair.target_vertices).max() < 1e-6 * pair.edge
