"""Vertex colours carried from coloured input points."""

from __future__ import annotations

import numpy as np
import pytest

from fourd.animation import AnimatedMesh
from fourd.appearance import vertex_colors
from fourd.appearance.vertex_colors import frame_vertex_colors, nearest_observed_frame
from fourd.errors import InputError
from fourd.sequence import Frame, PointCloudSequence


def _scene():
    """Two vertices over three frames; the input points under them change colour per frame."""
    points = np.array([[0.0, 0, 0], [1.0, 0, 0], [5.0, 5, 5]])
    frames = []
    for t in range(3):
        colors = np.array([[t / 2, 0, 0], [0, t / 2, 0], [0, 0, 1.0]])
        frames.append(Frame(points + [0.1 * t, 0, 0], colors=colors, time=float(t)))
    vertices = np.stack([points[:2] + [0.1 * t, 0.01, 0] for t in range(3)])
    return PointCloudSequence(tuple(frames)), vertices


def test_each_frame_takes_its_nearest_points_colour():
    seq, vertices = _scene()
    colors = vertex_colors(AnimatedMesh(np.zeros((0, 3), int), vertices), seq)
    assert colors.shape == (3, 2, 3)
    assert np.allclose(colors[:, 0], [[0, 0, 0], [0.5, 0, 0], [1, 0, 0]])
    assert np.allclose(colors[:, 1], [[0, 0, 0], [0, 0.5, 0], [0, 1, 0]])


def test_filled_in_vertices_keep_the_colour_of_their_nearest_observed_frame():
    seq, vertices = _scene()
    vertices[1, 0] = [5.0, 5, 5]  # filled in far from its surface, near the blue point
    observed = np.ones((3, 2), bool)
    observed[1, 0] = False
    colors = vertex_colors(AnimatedMesh(np.zeros((0, 3), int), vertices, observed=observed), seq)
    assert np.allclose(colors[1, 0], [0, 0, 0])  # frame 0's colour (the tie goes earlier)


def test_output_frames_between_input_frames_take_the_nearest_coloured_one():
    seq, vertices = _scene()
    anim = AnimatedMesh(np.zeros((0, 3), int), vertices[[0, 2]], times=[0.2, 1.9])
    colors = vertex_colors(anim, seq)
    assert np.allclose(colors[:, 0], [[0, 0, 0], [1, 0, 0]])


def test_an_input_without_colours_is_refused():
    seq = PointCloudSequence((Frame(np.eye(3)),))
    with pytest.raises(InputError, match="no colours"):
        vertex_colors(AnimatedMesh(np.zeros((0, 3), int), np.eye(3)[None]), seq)


def test_nearest_observed_frame_both_ways_and_never():
    observed = np.array([[0, 0], [0, 0], [1, 0], [0, 0], [0, 0], [0, 0], [1, 0]], bool)
    assert nearest_observed_frame(observed)[:, 0].tolist() == [2, 2, 2, 2, 2, 6, 6]
    assert nearest_observed_frame(observed)[:, 1].tolist() == [-1] * 7


def test_one_frames_colours_are_that_row_of_all_frames_colours():
    seq, vertices = _scene()
    vertices[0, 0] = [5.0, 5, 5]  # filled in at frame 0: takes frame 1's colour
    observed = np.ones((3, 2), bool)
    observed[0, 0] = False
    anim = AnimatedMesh(np.zeros((0, 3), int), vertices, observed=observed)
    every = vertex_colors(anim, seq)
    for frame in (0, 2, -1):
        assert np.array_equal(frame_vertex_colors(anim, seq, frame), every[frame])
    assert np.allclose(frame_vertex_colors(anim, seq)[0], [0.5, 0, 0])
    with pytest.raises(InputError, match="outside"):
        frame_vertex_colors(anim, seq, 3)
