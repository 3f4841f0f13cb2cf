"""The Gauss-Newton Hessian with its structure kept between assemblies
(:mod:`fourd.methods.surfels.hessian`) against the product of the whole stacked Jacobian."""

import numpy as np
import pytest
import scipy.sparse as sp

from fourd.methods.surfels import (
    MatchOptions,
    associate,
    laplace_term,
    layout,
    match_term,
    move,
    rigid_term,
)
from fourd.methods.surfels.hessian import data_blocks, planned_derivatives
from fourd.methods.surfels.state import Layout
from fourd.methods.surfels.term import keep_columns


def test_the_data_blocks_are_each_surfels_position_and_normal_offset_in_each_frame():
    lay = Layout(frames=2, count=3)
    blocks = data_blocks(lay)
    assert blocks.shape == (lay.size, lay.size)
    assert blocks.nnz == 2 * 3 * 15 and not np.any(blocks.data)
    structure = np.zeros((lay.size, lay.size), dtype=bool)
    for frame in range(2):
        for surfel in range(3):
            unknowns = np.r_[
                lay.position(frame, surfel) + np.arange(3), lay.normal(frame, surfel) + np.arange(2)
            ]
            structure[np.ix_(unknowns, unknowns)] = True
    coo = blocks.tocoo()
    stored = np.zeros_like(structure)
    stored[coo.row, coo.col] = True
    assert np.array_equal(stored, np.triu(structure))
    # restricted to some unknowns: the same entries among those, renumbered
    columns = np.array([0, 1, 4, 5, 19, 20, 22])
    kept = data_blocks(lay, columns)
    full = sp.csr_matrix((np.ones(blocks.nnz), blocks.indices, blocks.indptr), shape=blocks.shape)
    expected = full[columns][:, columns]
    assert kept.shape == (7, 7)
    assert np.array_equal(
        sp.csr_matrix((np.ones(kept.nnz), kept.indices, kept.indptr)).toarray(),
        expected.toarray(),
    )


@pytest.mark.parametrize("restricted", [False, True])
def test_a_kept_structure_gives_the_stacked_jacobians_gradient_and_hessian(
    restricted, random_surfel_problem
):
    state, graph, data = random_surfel_problem(seed=1, count=30)
    lay = layout(state)
    rng = np.random.default_rng(2)
    columns = np.flatnonzero(rng.random(lay.size) < 0.6) if restricted else None
    options = MatchOptions(tangential=0.2)

    def restrict(jacobian):
        return jacobian if columns is None else keep_columns(jacobian, columns)

    plan, patterns = None, None
    for step in range(3):
        at = move(state, rng.normal(scale=0.03, size=lay.size))
        data_part = match_term(at, data, associate(at, data, 0.2, options), 1.0, options)
        priors = [
            laplace_term(at, graph, 0.3, pattern=None if patterns is None else patterns[0]),
            rigid_term(at, graph, 0.8, 0.2, pattern=None if patterns is None else patterns[1]),
        ]
        patterns = patterns or tuple(p.pattern for p in priors)
        jacobians = [restrict(p.jacobian) for p in priors]
        residuals = np.concatenate([p.residuals for p in priors])
        whole = sp.vstack([restrict(data_part.jacobian), *jacobians], format="csr")
        expected_gradient = 2.0 * whole.T @ np.concatenate([data_part.residuals, residuals])
        expected_hessian = sp.triu(2.0 * (whole.T @ whole))
        gradient, hessian, next_plan = planned_derivatives(
            restrict(data_part.jacobian), data_part.residuals, jacobians, residuals,
            patterns, plan, lay, columns,
        )
        assert jacobians == []  # let go once read
        assert next_plan is plan or step == 0
        plan = next_plan
        assert np.allclose(gradient, expected_gradient, rtol=1e-12, atol=1e-12)
        assert hessian.shape == expected_hessian.shape
        assert abs(hessian - expected_hessian).max() <= 1e-12 * abs(expected_hessian).max()
    # the priors' patterns of another assembly: a plan of their own
    fresh = (laplace_term(state, graph, 0.3), rigid_term(state, graph, 0.8, 0.2))
    other = tuple(p.pattern for p in fresh)
    assert not plan.fits(other)


def test_a_data_row_outside_its_surfels_block_is_refused(random_surfel_problem):
    state, graph, data = random_surfel_problem(seed=1, count=30)
    lay = layout(state)
    prior = laplace_term(state, graph, 0.3)
    # a row that ties two surfels' positions
    data_jacobian = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, 3])), shape=(1, lay.size))
    with pytest.raises(ValueError, match="leaves its surfel"):
        planned_derivatives(
            data_jacobian, np.ones(1), [prior.jacobian], prior.residuals, (prior.pattern,),
            None, lay,
        )
