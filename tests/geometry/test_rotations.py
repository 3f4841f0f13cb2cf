import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fourd.geometry.laplacian import cotangent_weights, weights_laplacian
from fourd.geometry.rotations import (
    arap_right_hand_side,
    best_rotations,
    one_ring_rotations,
    procrustes,
)


def test_best_rotations_recovers_known_rotations_batched():
    rng = np.random.default_rng(0)
    R = Rotation.random(50, random_state=1).as_matrix()
    P = rng.normal(size=(50, 12, 3))
    Q = np.einsum("nab,nkb->nka", R, P)
    S = np.einsum("nka,nkb->nab", P, Q)  # sum p q^T
    found = best_rotations(S)
    assert np.abs(found - R).max() < 1e-9


def test_best_rotations_never_reflects():
    rng = np.random.default_rng(3)
    S = rng.normal(size=(200, 3, 3))
    S[:100] *= -1.0  # many with negative determinant
    R = best_rotations(S)
    assert np.abs(np.linalg.det(R) - 1.0).max() < 1e-9
    assert np.abs(np.einsum("nab,nac->nbc", R, R) - np.eye(3)).max() < 1e-9
    # optimality against the SVD answer
    U, _, Vt = np.linalg.svd(S)
    D = np.ones((200, 3))
    D[:, 2] = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    reference = np.einsum("nji,nj,nkj->nik", Vt, D, U)
    assert np.abs(R - reference).max() < 1e-8


def test_best_rotations_of_planar_patches_rank_2_covariances():
    # the covariances of surface vertices: edges in a plane, rotated (or reflected) copies
    rng = np.random.default_rng(4)
    R = Rotation.random(300, random_state=2).as_matrix()
    P = rng.normal(size=(300, 8, 3))
    P[..., 2] = 0.0
    Q = np.einsum("nab,nkb->nka", R, P) + 1e-4 * rng.normal(size=P.shape)
    Q[:100] *= -1.0  # reflected: negative or zero determinant
    S = np.einsum("nka,nkb->nab", P, Q)
    found = best_rotations(S)
    assert np.abs(np.linalg.det(found) - 1.0).max() < 1e-9
    assert np.abs(found[100:] - R[100:]).max() < 1e-3
    # as good as the sign-corrected SVD answer
    U, _, Vt = np.linalg.svd(S)
    D = np.ones((300, 3))
    D[:, 2] = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    reference = np.einsum("nji,nj,nkj->nik", Vt, D, U)
    objective = np.einsum("nab,nba->n", found, S)
    best = np.einsum("nab,nba->n", reference, S)
    assert np.all(objective >= best - 1e-9 * np.abs(best))


def test_single_matrix_and_procrustes():
    R = Rotation.from_rotvec([0.3, -0.2, 0.9]).as_matrix()
    X = np.random.default_rng(5).normal(size=(30, 3))
    Y = 1.7 * X @ R.T + np.array([1.0, 2.0, -3.0])
    fit = procrustes(X, Y, with_scale=True)
    assert np.abs(fit.rotation - R).max() < 1e-9
    assert abs(fit.scale - 1.7) < 1e-9 and fit.rms < 1e-9
    assert best_rotations(np.eye(3)).shape == (3, 3)
    with pytest.raises(ValueError):
        procrustes(X[:2], Y[:2])


def test_one_ring_rotations_recover_a_rigid_motion_and_a_bend():
    import scipy.sparse as sp
    import trimesh

    from fourd.geometry.meshes import vertex_adjacency

    sphere = trimesh.creation.icosphere(subdivisions=2)
    rest = np.asarray(sphere.vertices)
    weights = vertex_adjacency(np.asarray(sphere.faces), len(rest))
    R = Rotation.from_rotvec([0.4, -0.2, 0.9]).as_matrix()
    found = one_ring_rotations(weights, rest, rest @ R.T + [3.0, 1.0, 2.0])
    assert np.abs(found - R).max() < 1e-9
    # each half turned its own way: vertices away from the cut get their half's rotation
    other = Rotation.from_rotvec([0.0, 0.0, -0.7]).as_matrix()
    upper = rest[:, 2] > 0
    bent = np.where(upper[:, None], rest @ R.T, rest @ other.T)
    found = one_ring_rotations(weights, rest, bent)
    far = np.abs(rest[:, 2]) > 0.5
    assert np.abs(found[far & upper] - R).max() < 1e-9
    assert np.abs(found[far & ~upper] - other).max() < 1e-9
    lonely = one_ring_rotations(sp.csr_matrix((len(rest), len(rest))), rest, rest)
    assert np.abs(lonely - np.eye(3)).max() == 0
    # some rows only: those rows' rotations, to the bit
    rows = np.array([5, 0, 41, 41, 100])
    assert np.array_equal(one_ring_rotations(weights, rest, bent, rows), found[rows])
    assert one_ring_rotations(weights, rest, bent, rows[:0]).shape == (0, 3, 3)


def test_arap_right_hand_side_is_the_laplacian_of_the_rest_turned():
    """With every rotation R, ``b = R (L r)`` (L the weighted Laplacian): the global step then
    puts the rigidly turned shape back where it was."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    rest = np.asarray(sphere.vertices) * [1.0, 0.7, 0.5]
    weights = cotangent_weights(rest, np.asarray(sphere.faces), clamp_negative=True)
    turn = Rotation.from_rotvec([0.2, -0.4, 0.7]).as_matrix()
    rotations = np.repeat(turn[None], len(rest), axis=0)
    laplacian = weights_laplacian(weights)
    b = arap_right_hand_side(weights, rest, rotations)
    np.testing.assert_allclose(b, (laplacian @ rest) @ turn.T, atol=1e-12)
