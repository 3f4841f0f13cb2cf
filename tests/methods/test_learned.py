"""Method learned: kinematic twice, the second pass with the stiffness the first one taught."""

import numpy as np
import pytest
import scipy.sparse as sp

from fourd import AnimatedMesh, synth
from fourd.methods import kinematic, learned
from fourd.methods.kinematic.arap_solve import _scaled_weights, slide_precompute


def test_edge_stiffness_scales_exactly_the_listed_edges_in_both_directions():
    weights = sp.csr_matrix(np.array([[0, 2.0, 3.0], [2.0, 0, 4.0], [3.0, 4.0, 0]]))
    scaled = _scaled_weights(weights, np.array([[2, 0]]), np.array([0.5])).toarray()
    assert np.allclose(scaled, [[0, 2.0, 1.5], [2.0, 0, 4.0], [1.5, 4.0, 0]])


def test_a_stiffness_of_one_changes_nothing():
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    plain = slide_precompute(rest, faces)
    edges = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    same = slide_precompute(rest, faces, (edges, np.ones(6)))
    assert np.allclose(plain.laplacian.toarray(), same.laplacian.toarray())


@pytest.mark.slow
def test_the_second_pass_tracks_the_same_template_with_other_weights():
    truth = synth.scene("bending-arm", frames=4)
    scans = synth.scan(truth, resolution=96, seed=0)
    first = kinematic.reconstruct(scans)
    result = learned.reconstruct(scans)
    assert isinstance(result, AnimatedMesh)
    assert np.array_equal(result.rest, first.rest) and np.array_equal(result.faces, first.faces)
    assert not np.allclose(result.vertices[-1], first.vertices[-1])
    assert np.allclose(result.vertices[0], first.vertices[0], atol=1e-9)
