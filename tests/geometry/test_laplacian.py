import numpy as np
import pytest

from fourd.geometry.laplacian import (
    cotangent_laplacian,
    cotangent_weights,
    laplacian_smooth,
    mass_matrix,
    uniform_laplacian,
)


def grid(n=6, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    V = np.c_[u.ravel(), v.ravel(), np.zeros(n * n)]
    interior = (u.ravel() > 0) & (u.ravel() < 1) & (v.ravel() > 0) & (v.ravel() < 1)
    V[interior, :2] += jitter * rng.uniform(-1, 1, size=(interior.sum(), 2)) / n
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
        idx[:-1, 1:].ravel(),
    )
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    return V, F, interior


def test_cotangent_laplacian_annihilates_linear_functions_inside_a_flat_mesh():
    V, F, interior = grid(7, jitter=0.3)
    L = cotangent_laplacian(V, F)
    linear = 2.0 * V[:, 0] - 3.0 * V[:, 1] + 0.5
    assert np.abs(L @ linear)[interior].max() < 1e-10
    assert np.abs(L @ np.ones(len(V))).max() < 1e-12


def test_cotangent_laplacian_is_symmetric_positive_semidefinite():
    V, F, _ = grid(6, jitter=0.2)
    V[:, 2] = np.sin(3 * V[:, 0])
    L = cotangent_laplacian(V, F, clamp_negative=True)
    assert abs(L - L.T).max() < 1e-12
    assert np.linalg.eigvalsh(L.toarray()).min() > -1e-10


def test_energy_is_sum_of_weighted_squared_edges():
    V, F, _ = grid(5, jitter=0.2)
    W = cotangent_weights(V, F).tocoo()
    x = np.random.default_rng(1).normal(size=len(V))
    expected = 0.5 * np.sum(W.data * (x[W.row] - x[W.col]) ** 2)
    assert abs(x @ cotangent_laplacian(V, F) @ x - expected) < 1e-10


def test_mass_matrix_sums_to_area_and_uniform_laplacian_rows_vanish():
    V, F, _ = grid(5)
    assert abs(mass_matrix(V, F).diagonal().sum() - 1.0) < 1e-12
    assert np.abs(uniform_laplacian(len(V), F) @ np.ones(len(V))).max() < 1e-12


def test_smoothing_reduces_noise_on_a_plane():
    V, F, interior = grid(12)
    noisy = V.copy()
    noisy[:, 2] = 0.01 * np.random.default_rng(2).normal(size=len(V))
    smooth = laplacian_smooth(noisy, F, iterations=10)
    assert np.abs(smooth[interior, 2]).std() < 0.5 * np.abs(noisy[interior, 2]).std()



def test_smoothing_weights_hold_vertices_and_scale_steps():
    V, F, interior = grid(12)
    noisy = V.copy()
    noisy[:, 2] = 0.01 * np.random.default_rng(2).normal(size=len(V))
    held = noisy[:, 0] < 0.5
    weights = np.where(held, 0.0, 1.0)
    smooth = laplacian_smooth(noisy, F, iterations=10, weights=weights)
    assert np.array_equal(smooth[held], noisy[held])
    moving = interior & ~held
    assert np.abs(smooth[moving, 2]).std() < 0.5 * np.abs(noisy[moving, 2]).std()
    ones = laplacian_smooth(noisy, F, iterations=10, weights=np.ones(len(V)))
    assert np.allclose(ones, laplacian_smooth(noisy, F, iterations=10))


def test_bad_shapes_are_rejected():
    with pytest.raises(ValueError):
        cotangent_laplacian(np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError):
        cotangent_laplacian(np.zeros((3, 3)), np.array([[0, 1, 5]]))
