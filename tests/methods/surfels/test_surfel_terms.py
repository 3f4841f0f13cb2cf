"""Every energy term's analytic Jacobian (hence gradient ``2 J^T r`` and Gauss-Newton Hessian
``2 J^T J``) against central differences along the model's parameterisation (eq. 11, 12)."""

import numpy as np
import pytest
import scipy.sparse as sp

from fourd.methods.surfels import (
    AnchorData,
    GuideData,
    MatchOptions,
    Weights,
    accel_term,
    anchor_term,
    associate,
    build_topology,
    frame_data,
    guide_term,
    laplace_term,
    layout,
    match_term,
    move,
    rigid_term,
    smooth_normal_term,
    smooth_position_term,
    surfel_state,
    total_energy,
)
from fourd.methods.surfels.energy import HESSIAN_PLAN, prior_reach
from fourd.methods.surfels.optimizer import free_unknowns
from fourd.methods.surfels.state import skew
from fourd.methods.surfels.term import Blocks, keep_columns


def _problem(seed=0, frames=3, count=40):
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-1, 1, (count, 2))
    base = np.c_[uv, 0.3 * np.sin(2 * uv[:, 0]) * uv[:, 1]]
    positions = base + rng.normal(scale=0.05, size=(frames, count, 3))
    normals = np.array([0.0, 0.0, 1.0]) + rng.normal(scale=0.3, size=(frames, count, 3))
    angles = rng.normal(scale=0.3, size=(frames - 1, count, 3))
    rotations = np.stack([_rodrigues(a) for a in angles.reshape(-1, 3)]).reshape(
        frames - 1, count, 3, 3
    )
    state = surfel_state(positions, normals, rotations)
    graph = build_topology(positions, 0.6, max_stretch=None)
    points = [
        base[rng.integers(count, size=120)] + rng.normal(scale=0.1, size=(120, 3))
        for _ in range(frames)
    ]
    data = frame_data(
        points, weight=2.0, normals=[rng.normal(size=(120, 3)) for _ in range(frames)]
    )
    return state, graph, data


def _rodrigues(vector):
    angle = np.linalg.norm(vector)
    k = skew(vector / angle)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _terms(state, graph, data):
    # a tangential share > 0 so that the point-to-surfel part is checked too
    near = MatchOptions(tangential=0.2)
    global_matches = associate(state, data, 0.15, near)
    aligned = MatchOptions(regime="alignment", tangential=0.2)
    alignment_matches = associate(state, data, 0.4, aligned)
    rng = np.random.default_rng(5)
    pairs = rng.integers(state.frames - 1, size=30)
    sources = state.positions[pairs, rng.integers(state.count, size=30)] + rng.normal(
        scale=0.02, size=(30, 3)
    )
    anchors = AnchorData(
        pairs, sources, sources + rng.normal(scale=0.1, size=(30, 3)), rng.uniform(0.2, 1, 30)
    )
    guided = rng.integers(state.count, size=25)
    frames = rng.integers(state.frames, size=25)
    guides = GuideData(
        frames,
        guided,
        state.positions[frames, guided] + rng.normal(scale=0.1, size=(25, 3)),
        rng.uniform(0.2, 1, 25),
    )
    return {
        "match": lambda s, d: match_term(s, data, global_matches, 1.5, near, derivatives=d),
        "match_alignment": lambda s, d: match_term(
            s, data, alignment_matches, 1.5, aligned, derivatives=d
        ),
        # the tangent plane only: no point-offset entries in the Jacobian
        "match_plane": lambda s, d: match_term(
            s, data, global_matches, 1.5, MatchOptions(), derivatives=d
        ),
        "smooth_position": lambda s, d: smooth_position_term(s, graph, 0.7, derivatives=d),
        "smooth_normal": lambda s, d: smooth_normal_term(s, graph, 0.3, derivatives=d),
        "laplace": lambda s, d: laplace_term(s, graph, 0.2, derivatives=d),
        "rigid": lambda s, d: rigid_term(s, graph, 0.9, 0.4, derivatives=d),
        "accel": lambda s, d: accel_term(s, 0.6, 0.25, derivatives=d),
        "rigid_urshape": lambda s, d: rigid_term(s, graph, 0.9, 0.4, derivatives=d, urshape=True),
        "accel_after_urshape": lambda s, d: accel_term(s, 0.6, 0.25, derivatives=d, first=1),
        "anchor": lambda s, d: anchor_term(s, anchors, 0.8, 0.5, derivatives=d),
        "guide": lambda s, d: guide_term(s, guides, 0.7, derivatives=d),
    }


@pytest.mark.parametrize(
    "name",
    [
        "match",
        "match_alignment",
        "match_plane",
        "smooth_position",
        "smooth_normal",
        "laplace",
        "rigid",
        "accel",
        "rigid_urshape",
        "accel_after_urshape",
        "anchor",
        "guide",
    ],
)
def test_jacobian_and_gradient_match_central_differences(name):
    state, graph, data = _problem(frames=4)
    evaluate = _terms(state, graph, data)[name]
    at = evaluate(state, True)
    size = layout(state).size
    assert at.jacobian.shape == (len(at.residuals), size)
    assert at.value > 0 and np.count_nonzero(at.gradient) > 0
    rng = np.random.default_rng(1)
    h = 1e-6
    worst_jacobian = worst_gradient = 0.0
    for _ in range(6):
        direction = rng.normal(size=size)
        plus, minus = (
            evaluate(move(state, h * direction), False),
            evaluate(move(state, -h * direction), False),
        )
        numeric = (plus.residuals - minus.residuals) / (2 * h)
        analytic = at.jacobian @ direction
        worst_jacobian = max(
            worst_jacobian, np.linalg.norm(numeric - analytic) / np.linalg.norm(analytic)
        )
        slope = (plus.value - minus.value) / (2 * h)
        worst_gradient = max(
            worst_gradient, abs(slope - at.gradient @ direction) / abs(at.gradient @ direction)
        )
    # measured: Jacobians within 4e-11, gradients within 2e-9 (residuals at most quadratic)
    assert worst_jacobian < 1e-6
    assert worst_gradient < 1e-6
    hessian = at.hessian
    assert abs(hessian - hessian.T).max() < 1e-12 * abs(hessian).max()


def test_value_only_agrees_and_truncated_points_add_a_constant():
    state, graph, data = _problem(seed=2)
    matches = associate(state, data, 0.15)
    assert 0 < matches.active.sum() < len(data.points)
    full = match_term(state, data, matches, 1.5)
    value_only = match_term(state, data, matches, 1.5, derivatives=False)
    assert value_only.jacobian is None and value_only.value == pytest.approx(full.value, rel=1e-12)
    outside = 1.5 * 2.0 * 0.15**2 * np.sum(~matches.active)
    assert full.value == pytest.approx(full.residuals @ full.residuals + outside, rel=1e-12)


def test_energy_sums_its_terms():
    state, graph, data = _problem(seed=3)
    weights = Weights(
        match=1.5,
        smooth_position=0.7,
        smooth_normal=0.3,
        laplace=0.2,
        rigid=0.9,
        rigid_normal=0.4,
        accel=0.6,
        accel_normal=0.25,
    )
    matches = associate(state, data, 0.15, MatchOptions(tangential=0.2))
    total = total_energy(state, graph, data, matches, weights, MatchOptions(tangential=0.2))
    terms = _terms(state, graph, data)
    parts = [
        terms[n](state, True)
        for n in ("match", "smooth_position", "smooth_normal", "laplace", "rigid", "accel")
    ]
    assert total.value == pytest.approx(sum(p.value for p in parts), rel=1e-12)
    assert np.allclose(total.gradient, sum(p.gradient for p in parts), rtol=1e-10, atol=1e-12)
    # the energy keeps the Hessian's upper triangle, the diagonal included
    full = sum(p.hessian for p in parts)
    assert abs(total.hessian - sp.triu(full)).max() < 1e-10
    assert sp.tril(total.hessian, k=-1).nnz == 0
    assert set(total.terms) == {
        "match",
        "smooth_position",
        "smooth_normal",
        "laplace",
        "rigid",
        "accel",
    }


def _prior_terms(graph):
    """The priors, whose Jacobian patterns the optimiser keeps between steps."""
    return {
        "smooth_position": lambda s, p: smooth_position_term(s, graph, 0.7, pattern=p),
        "smooth_normal": lambda s, p: smooth_normal_term(s, graph, 0.3, pattern=p),
        "laplace": lambda s, p: laplace_term(s, graph, 0.2, pattern=p),
        "rigid": lambda s, p: rigid_term(s, graph, 0.9, 0.4, pattern=p),
        "accel": lambda s, p: accel_term(s, 0.6, 0.25, pattern=p),
        "rigid_urshape": lambda s, p: rigid_term(s, graph, 0.9, 0.4, urshape=True, pattern=p),
        "accel_after_urshape": lambda s, p: accel_term(s, 0.6, 0.25, first=1, pattern=p),
    }


@pytest.mark.parametrize("name", list(_prior_terms(None)))
def test_a_kept_pattern_assembles_the_jacobian_of_another_state(name):
    state, graph, _ = _problem(frames=4)
    evaluate = _prior_terms(graph)[name]
    pattern = evaluate(state, None).pattern
    moved = move(state, np.random.default_rng(4).normal(scale=0.1, size=layout(state).size))
    fresh = evaluate(moved, None).jacobian
    reused = evaluate(moved, pattern).jacobian
    assert reused.shape == fresh.shape and (reused != fresh).nnz == 0
    # the identity blocks' and cross products' zeros are left out: the only zeros stored are
    # the tangent bases' (eq. 11), whose places move with the normals
    lay = layout(state)
    columns = np.r_[0 : lay.normals_start, lay.rotations_start : lay.size]
    positions_and_rotations = fresh[:, columns]
    assert positions_and_rotations.nnz > 0 or name == "smooth_normal"
    assert np.count_nonzero(positions_and_rotations.data) == positions_and_rotations.nnz
    # a pattern of some columns assembles exactly those columns
    columns = np.flatnonzero(np.random.default_rng(5).random(layout(state).size) < 0.6)
    narrow = evaluate(moved, pattern.keep_columns(columns)).jacobian
    assert narrow.shape == (fresh.shape[0], len(columns))
    assert abs(narrow - fresh[:, columns]).max() == 0.0


def test_a_pattern_from_another_term_is_refused():
    state, graph, _ = _problem(frames=4)
    terms = _prior_terms(graph)
    rigid = terms["rigid"](state, None).pattern
    with pytest.raises(ValueError, match="rows"):
        terms["accel"](state, rigid)
    # the same number of rows (3 a surfel and frame against 2 x 3 a surfel and inner frame)
    accel = terms["accel"](state, None).pattern
    assert accel.shape[0] == terms["laplace"](state, None).pattern.shape[0]
    with pytest.raises(ValueError, match="pattern fits only"):
        terms["laplace"](state, accel)
    # the rigidity's pattern without the normals' blocks, and another term's
    without_normals = rigid_term(state, graph, 0.9, 0.0).pattern
    with pytest.raises(ValueError, match="pattern fits only"):
        terms["rigid"](state, without_normals)
    with pytest.raises(ValueError, match="pattern fits only"):
        terms["rigid"](state, accel)


def test_energy_with_kept_patterns_equals_a_fresh_assembly():
    state, graph, data = _problem(seed=3, frames=4)
    weights = Weights(1.5, 0.7, 0.3, 0.2, 0.9, 0.4, 0.6, 0.25)
    match = MatchOptions(tangential=0.2)
    columns = np.flatnonzero(np.random.default_rng(6).random(layout(state).size) < 0.7)
    patterns = {}
    for step in range(3):
        at = move(state, np.random.default_rng(step).normal(scale=0.05, size=layout(state).size))
        matches = associate(at, data, 0.15, match)
        kept = total_energy(
            at, graph, data, matches, weights, match, columns=columns, patterns=patterns
        )
        fresh = total_energy(at, graph, data, matches, weights, match, columns=columns)
        assert set(patterns) == {
            "smooth_position", "smooth_normal", "laplace", "rigid", "accel", HESSIAN_PLAN
        }
        assert kept.value == fresh.value
        assert np.allclose(kept.gradient, fresh.gradient, rtol=1e-13, atol=1e-13)
        # the kept Hessian structure sums every entry as the stacked Jacobian's product does
        # (the data's rows first), only the entries' places in their rows differ
        assert abs(kept.hessian - fresh.hessian).max() == 0.0


def test_patterns_shared_between_other_columns_equal_a_fresh_assembly():
    # the hole filling optimises other surfels in each frame of one topology and layout
    state, graph, data = _problem(seed=4, frames=3)
    weights = Weights(1.5, 0.7, 0.3, 0.2, 0.9, 0.4, 0.6, 0.25)
    match = MatchOptions(tangential=0.2)
    shared = {}
    for step in range(3):
        rng = np.random.default_rng(10 + step)
        at = move(state, rng.normal(scale=0.05, size=layout(state).size))
        columns = np.flatnonzero(rng.random(layout(state).size) < 0.3)
        matches = associate(at, data, 0.15, match)
        reused = total_energy(
            at, graph, data, matches, weights, match, columns=columns, patterns={}, shared=shared
        )
        fresh = total_energy(at, graph, data, matches, weights, match, columns=columns)
        assert {name for name, _ in shared} == {
            "smooth_position", "smooth_normal", "laplace", "rigid", "accel"
        }
        assert all(pattern.shape[1] == layout(state).size for pattern in shared.values())
        assert reused.value == fresh.value
        assert np.allclose(reused.gradient, fresh.gradient, rtol=1e-13, atol=1e-13)
        assert reused.hessian.shape == (len(columns), len(columns))
        assert abs(reused.hessian - fresh.hessian).max() <= 1e-13 * abs(fresh.hessian).max()


@pytest.mark.parametrize("urshape", [False, True])
def test_a_local_energy_leaves_out_only_the_priors_rows_that_touch_nothing_free(urshape):
    # the hole filling moves some surfels of one frame, the urshape's fit frame 0 and every
    # rotation: the rows that touch neither are constants, left out
    state, graph, data = _problem(seed=6, frames=6)
    empty = frame_data([np.zeros((0, 3))])
    matches = associate(state, empty, 0.15)
    weights = Weights(0.0, 0.7, 0.3, 0.2, 0.9, 0.4, 0.6, 0.25)
    lay = layout(state)
    moving = np.zeros((state.frames, state.count), dtype=bool)
    if urshape:
        moving[0] = True
        rotations = np.ones((state.frames - 1, state.count), dtype=bool)
    else:
        # no rotation free: the rigidity's steps reach the frame through its positions
        moving[2, ::3] = True
        rotations = np.zeros((state.frames - 1, state.count), dtype=bool)
    free = free_unknowns(lay, moving, rotations)
    columns = np.flatnonzero(free)
    reach = prior_reach(lay, columns, urshape=urshape)
    if urshape:
        assert reach.frames.tolist() == [0] and reach.steps is None
        assert reach.centres.tolist() == []
    else:
        assert reach.frames.tolist() == [2] and reach.steps.tolist() == [1, 2]
        assert reach.centres.tolist() == [1, 2, 3]

    def energies(at):
        whole = total_energy(at, graph, empty, matches, weights, urshape=urshape)
        local = total_energy(at, graph, empty, matches, weights, columns=columns, urshape=urshape)
        return whole, local

    whole, local = energies(state)
    assert local.value < 0.9 * whole.value
    assert ("accel" in local.terms) != urshape
    full = whole.hessian + sp.triu(whole.hessian, k=1).T
    restricted = sp.triu(full[columns][:, columns])
    assert abs(local.hessian - restricted).max() <= 1e-12 * abs(restricted).max()
    assert np.allclose(local.gradient, whole.gradient[columns], rtol=0.0, atol=1e-12)
    # a step of the free unknowns changes both by the same amount
    step = np.where(free, np.random.default_rng(7).normal(scale=0.05, size=lay.size), 0.0)
    moved_whole, moved_local = energies(move(state, step))
    assert moved_whole.value - moved_local.value == pytest.approx(
        whole.value - local.value, rel=1e-12
    )


def test_overlapping_blocks_are_refused():
    blocks = Blocks(4, 6)
    blocks.add(np.array([0]), np.array([0]), np.ones((2, 3)))
    blocks.add(np.array([1]), np.array([2]), np.ones((2, 2)))
    with pytest.raises(ValueError, match="overlap"):
        blocks.matrix()
    # left-out entries do not overlap
    blocks = Blocks(4, 6)
    blocks.add(np.array([0]), np.array([0]), np.eye(3)[:2], np.eye(3, dtype=bool)[:2])
    blocks.add(np.array([0]), np.array([1]), np.ones((1, 1)))
    jacobian = blocks.matrix()
    assert jacobian.nnz == 3 and jacobian[0, 1] == 1.0 and jacobian[1, 1] == 1.0


def test_kept_columns_of_a_jacobian_are_its_columns_renumbered():
    state, graph, data = _problem(seed=4)
    matches = associate(state, data, 0.15, MatchOptions(tangential=0.2))
    jacobian = match_term(state, data, matches, 1.5, MatchOptions(tangential=0.2)).jacobian
    columns = np.flatnonzero(np.random.default_rng(2).random(jacobian.shape[1]) < 0.4)
    kept = keep_columns(jacobian, columns)
    assert kept.shape == (jacobian.shape[0], len(columns))
    assert kept.has_sorted_indices and np.all(np.diff(kept.indptr) >= 0)
    np.testing.assert_array_equal(kept.toarray(), jacobian.toarray()[:, columns])
    # every entry of the columns kept, none of the others
    assert kept.nnz == jacobian[:, columns].nnz < jacobian.nnz


def test_the_doublet_test_rejects_a_point_whose_surfels_nearest_point_is_far():
    # one surfel at the origin per frame; the frames' points interleaved in the data, so each
    # frame's points and their kept k-d tree are gathered, not sliced
    state = surfel_state(np.zeros((2, 1, 3)), np.tile([0.0, 0.0, 1.0], (2, 1, 1)))
    points = np.array([[0, 0, 0.01], [0, 0, 0.02], [0, 0, 1.0], [0, 0, 0.5]])
    data = frame_data([points[:2], points[2:]])
    data = type(data)(points[[0, 2, 1, 3]], data.frames[[0, 2, 1, 3]], data.weights)
    np.testing.assert_array_equal(data.in_frame(0), [0, 2])
    np.testing.assert_array_equal(data.in_frame(1), [1, 3])
    assert data.in_frame(2).size == 0
    assert data.tree(1) is data.tree(1)
    np.testing.assert_array_equal(data.tree(1).data, points[[2, 3]])
    # frame 1: the surfel's nearest point is 0.5 away from the point at 1.0, beyond eps_top
    alignment = MatchOptions(regime="alignment", percentile=100.0)  # no point beyond the cutoff
    matches = associate(state, data, 0.4, alignment)
    np.testing.assert_array_equal(matches.surfels, 0)
    np.testing.assert_array_equal(matches.active, [True, False, True, True])
    # the same points again, association unchanged by the kept trees
    again = associate(state, data, 0.4, alignment)
    np.testing.assert_array_equal(again.active, matches.active)


def test_an_association_from_the_one_before_is_the_nearest_surfel():
    """The warm start of a step's association (``previous``): every point gets the surfel a
    k-d tree gives, whether its previous surfel is still near, has moved off, or is far (the
    grid's bound too wide: the k-d tree answers those)."""
    from scipy.spatial import cKDTree

    from fourd.methods.surfels.match import nearest_from

    state, graph, data = _problem(seed=3, frames=3, count=60)
    before = associate(state, data, 0.15)
    rng = np.random.default_rng(4)
    moved = type(state)(
        state.positions + rng.normal(scale=0.05, size=state.positions.shape),
        state.normals,
        state.rotations,
    )
    for options in (MatchOptions(), MatchOptions(regime="alignment")):
        fresh = associate(moved, data, 0.15, options)
        warm = associate(moved, data, 0.15, options, previous=before)
        np.testing.assert_array_equal(warm.surfels, fresh.surfels)
        np.testing.assert_array_equal(warm.active, fresh.active)
    positions = rng.uniform(-1, 1, (300, 3))
    points = rng.uniform(-1.5, 1.5, (2000, 3))
    # guesses near, random and one far corner for all: the bounds span from a cell to the box
    for guess in (cKDTree(positions + 0.01).query(points)[1], rng.integers(300, size=2000),
                  np.full(2000, np.argmax(positions.sum(axis=1)))):
        found = nearest_from(positions, points, guess, 0.1)
        np.testing.assert_array_equal(found, cKDTree(positions).query(points)[1])
