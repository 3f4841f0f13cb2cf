"""The constrained ARAP system of the sliding: precompute and reduced solver."""

import numpy as np
from kinematic_shapes import MovingBlob, _sphere_template

from fourd.methods import kinematic as K


def test_reduced_solver_gives_the_solution_of_the_saddle_system_5():
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from fourd.methods.kinematic.arap_solve import ConstrainedSolver

    blob = MovingBlob()
    V, F = _sphere_template(blob, resolution=0.3)
    pre = K.slide_precompute(V, F)
    n = len(V)
    rng = np.random.default_rng(9)
    normals = V / np.linalg.norm(V, axis=1, keepdims=True) + 0.1 * rng.normal(size=(n, 3))
    offsets = rng.normal(scale=0.1, size=n)
    constrained = rng.uniform(size=n) > 0.2
    rhs = rng.normal(size=(n, 3))
    reference = V + 0.01 * rng.normal(size=(n, 3))
    solver = ConstrainedSolver(pre, normals, offsets, constrained, 1e-4)
    P = solver.solve(rhs, reference)
    # the 4n x 4n system (5): [L3 + mu, C^T; C, 0] [p; lambda] = [b + mu p_ref; c], lambda_i = 0 rows
    L3 = solver.L3
    rows = np.repeat(np.arange(n), 3)
    C = sp.csr_matrix((normals.ravel(), (rows, np.arange(3 * n))), shape=(n, 3 * n))
    C = sp.diags(constrained.astype(float)) @ C
    Z = sp.diags((~constrained).astype(float))
    saddle = sp.bmat([[L3, C.T], [C, Z]], format="csc")
    right = np.r_[rhs.ravel() + solver.mu * reference.ravel(), np.where(constrained, offsets, 0.0)]
    solution = spla.spsolve(saddle, right)
    assert np.abs(solution[: 3 * n].reshape(n, 3) - P).max() < 1e-8
    assert np.abs(np.einsum("ij,ij->i", normals, P) - offsets)[constrained].max() < 1e-9


def test_elimination_order_is_a_permutation_that_reduces_fill():
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from fourd.methods.kinematic.arap_solve import elimination_order

    blob = MovingBlob()
    V, F = _sphere_template(blob, resolution=0.3)
    pre = K.slide_precompute(V, F)
    n = len(V)
    order = elimination_order(pre.laplacian)
    assert np.array_equal(np.sort(order), np.arange(n))
    # a scrambled vertex order, as marching cubes may leave it: the order must undo it
    scrambled = np.random.default_rng(3).permutation(n)
    L = (pre.laplacian + 1e-3 * sp.identity(n)).tocsr()[scrambled][:, scrambled]

    def fill(matrix):
        lu = spla.splu(
            matrix.tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
        return lu.L.nnz

    mine = elimination_order(L)
    assert fill(L[mine][:, mine]) < 0.5 * fill(L)
    assert np.array_equal(elimination_order(sp.identity(4, format="csr")), np.arange(4))
