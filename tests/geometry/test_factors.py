import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import trimesh

from fourd.geometry.factors import solve_ordered, unpermuted_factors
from fourd.geometry.laplacian import cotangent_laplacian


def test_back_substitution_in_an_elimination_order_solves_the_original_system():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    laplacian = cotangent_laplacian(sphere.vertices, sphere.faces)
    matrix = (laplacian + 0.01 * sp.identity(laplacian.shape[0])).tocsr()
    order = np.random.default_rng(0).permutation(matrix.shape[0])
    ordered = matrix[order][:, order].tocsc()
    lu = spla.splu(
        ordered, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    factors = unpermuted_factors(lu)
    assert factors is not None
    rhs = np.random.default_rng(1).normal(size=(matrix.shape[0], 4))
    solution = solve_ordered(factors, rhs, order)
    assert solution.shape == rhs.shape
    np.testing.assert_allclose(matrix @ solution, rhs, atol=1e-9 * np.abs(rhs).max())


def test_a_pivoted_or_column_permuted_factorisation_has_no_unpermuted_factors():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    laplacian = cotangent_laplacian(sphere.vertices, sphere.faces)
    matrix = (laplacian + 0.01 * sp.identity(laplacian.shape[0])).tocsc()
    assert unpermuted_factors(spla.splu(matrix, permc_spec="COLAMD")) is None
