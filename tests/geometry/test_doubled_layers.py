"""Doubled layers: small pieces along a larger surface are found, other pieces are not."""

import numpy as np
import trimesh

from fourd.geometry.doubled_layers import doubled_layers
from fourd.geometry.hole_closing import close_small_holes
from fourd.metrics.topology import topology


def _ball():
    ball = trimesh.creation.icosphere(4)  # 5,120 faces, edges about 0.075
    return np.asarray(ball.vertices), np.asarray(ball.faces, dtype=np.int64)


def _patch_of(vertices, faces, lift, ring=2):
    """A copy of the faces within ``ring`` edges of vertex 0, pushed out by ``lift`` along
    the normal: an open disk ``lift`` off the ball."""
    chosen = np.zeros(len(vertices), dtype=bool)
    chosen[0] = True
    for _ in range(ring):
        chosen[faces[chosen[faces].any(axis=1)].ravel()] = True
    patch = faces[chosen[faces].all(axis=1)]
    used, local = np.unique(patch, return_inverse=True)
    points = vertices[used] * (1.0 + lift)
    return points, local.reshape(-1, 3)


def _with(vertices, faces, points, patch):
    return np.concatenate([vertices, points]), np.concatenate([faces, patch + len(vertices)])


def test_a_sliver_half_an_edge_off_a_ball_is_a_doubled_layer_and_the_ball_is_not():
    vertices, faces = _ball()
    points, patch = _patch_of(vertices, faces, lift=0.03)
    all_vertices, all_faces = _with(vertices, faces, points, patch)
    doubled = doubled_layers(all_vertices, all_faces)
    assert not doubled[: len(faces)].any()
    assert doubled[len(faces):].all()


def test_a_piece_far_from_every_surface_a_ball_against_it_and_a_lone_sheet_are_kept():
    vertices, faces = _ball()
    far, patch = _patch_of(vertices, faces, lift=0.5)  # about 7 edges out: surface nothing covers
    all_vertices, all_faces = _with(vertices, faces, far, patch)
    assert not doubled_layers(all_vertices, all_faces).any()
    small = trimesh.creation.icosphere(0)  # closed, 20 faces, 8 edges across, touching the ball
    against = np.asarray(small.vertices) * 0.3 + [0.0, 0.0, 1.31]
    all_vertices, all_faces = _with(vertices, faces, against, np.asarray(small.faces))
    assert not doubled_layers(all_vertices, all_faces).any()
    sheet, sheet_faces = _patch_of(vertices, faces, lift=0.0, ring=3)
    assert not doubled_layers(sheet, sheet_faces).any()


def test_a_bubble_within_an_edge_of_the_ball_is_a_doubled_layer():
    vertices, faces = _ball()
    bubble = trimesh.creation.icosphere(0)  # closed, 20 faces, under an edge across
    beside = np.asarray(bubble.vertices) * 0.015 + [0.0, 0.0, 1.03]
    all_vertices, all_faces = _with(vertices, faces, beside, np.asarray(bubble.faces))
    doubled = doubled_layers(all_vertices, all_faces)
    assert doubled[len(faces):].all() and not doubled[: len(faces)].any()


def test_closing_drops_the_doubled_layer_so_the_ball_with_a_hole_comes_out_watertight():
    """The case the rule is for: a body whose clipped-off sliver lies beside the hole it left.
    The hole is closed by a membrane and the sliver dropped, in every frame."""
    vertices, faces = _ball()
    points, patch = _patch_of(vertices, faces, lift=0.02, ring=2)
    holed = faces[~(faces == 0).any(axis=1)]  # the ball without the fan around vertex 0
    all_vertices, all_faces = _with(vertices, holed, points, patch)
    frames = np.stack([all_vertices, all_vertices * 1.1 + [0.2, 0.0, 0.0]])
    observed = np.ones(frames.shape[:2], dtype=bool)
    out_faces, out_vertices, _ = close_small_holes(all_faces, frames, observed, 0.25)
    for frame in out_vertices:
        found = topology(out_faces, len(frame))
        assert found.components == 1 and found.closed_manifold, found
