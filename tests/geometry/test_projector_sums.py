"""Per-vertex sums of weighted projectors against the dense normal equations."""

import numpy as np
import pytest

from fourd.geometry.projector_sums import projector_sums


def test_the_sums_give_the_least_squares_point_of_planes_lines_and_points():
    rng = np.random.default_rng(3)
    goal = np.array([0.3, -1.2, 2.0])
    # three planes through the goal, each given by a point elsewhere on it, pin the goal
    normals = np.eye(3)
    on_planes = goal + np.cross(normals, rng.normal(size=(3, 3)))
    planes = projector_sums(np.zeros(3, np.int64), on_planes, np.ones(3), 1, directions=normals, identity=0.0,
                            outer=1.0)
    assert np.allclose(np.linalg.solve(planes.blocks[0], planes.right[0]), goal)
    # so do two lines through it, each given by a point elsewhere on it
    tangents = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    lines = projector_sums(np.zeros(2, np.int64), goal + 5.0 * tangents, np.array([1.0, 2.0]), 1, directions=tangents,
                           outer=-1.0)
    assert np.allclose(np.linalg.solve(lines.blocks[0], lines.right[0]), goal)
    # a plane's term does not see a move along the plane
    plane = projector_sums(np.array([0]), goal[None], 2.0, 1, directions=normals[:1], identity=0.0, outer=1.0)
    assert np.allclose(plane.blocks[0] @ np.array([0, 1.0, 1.0]), 0.0)
    assert planes.counts.tolist() == [3] and lines.counts.tolist() == [2]


def test_the_sums_match_the_blocks_term_by_term_and_reject_bad_ids():
    rng = np.random.default_rng(0)
    vertices = rng.integers(0, 7, 40)
    points, directions = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    weights, identity, outer = rng.random(40), rng.random(40), rng.random(40)
    sums = projector_sums(vertices, points, weights, 7, directions=directions, identity=identity, outer=outer)
    q = weights[:, None, None] * (identity[:, None, None] * np.eye(3)
                                  + outer[:, None, None] * directions[:, :, None] * directions[:, None, :])
    blocks, right = np.zeros((7, 3, 3)), np.zeros((7, 3))
    np.add.at(blocks, vertices, q)
    np.add.at(right, vertices, np.einsum("kij,kj->ki", q, points))
    assert np.allclose(sums.blocks, blocks) and np.allclose(sums.right, right)
    assert np.array_equal(sums.counts, np.bincount(vertices, minlength=7))
    with pytest.raises(ValueError, match="vertex ids"):
        projector_sums(np.array([7]), points[:1], 1.0, 7)
