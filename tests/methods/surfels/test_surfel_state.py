import numpy as np
import pytest

from fourd.methods.surfels import (
    build_topology,
    fit_rotations,
    layout,
    move,
    retract,
    sample_surfels,
    surfel_state,
    tangent_basis,
)
from fourd.methods.surfels.state import SurfelState, skew


def _state(seed=0, frames=3, count=20):
    rng = np.random.default_rng(seed)
    return surfel_state(rng.normal(size=(frames, count, 3)), rng.normal(size=(frames, count, 3)))


def test_tangent_basis_is_orthonormal_and_normal_to_n():
    rng = np.random.default_rng(0)
    normals = np.concatenate([rng.normal(size=(500, 3)), np.eye(3), -np.eye(3)])
    basis = tangent_basis(normals)
    unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    gram = np.einsum("pai,paj->pij", basis, basis)
    assert np.allclose(gram, np.eye(2), atol=1e-12)
    assert np.abs(np.einsum("pa,pai->pi", unit, basis)).max() < 1e-12
    # right-handed (t_u, t_v, n)
    assert np.allclose(np.cross(basis[..., 0], basis[..., 1]), unit, atol=1e-12)


def test_move_is_the_first_order_model_and_retract_makes_it_valid():
    state = _state()
    lay = layout(state)
    assert lay.size == 3 * 20 * 3 + 3 * 20 * 2 + 2 * 20 * 3
    assert move(state, np.zeros(lay.size)).positions.tobytes() == state.positions.tobytes()
    rng = np.random.default_rng(1)
    step = 0.3 * rng.normal(size=lay.size)
    positions, offsets, vectors = lay.split(step)
    moved = move(state, step)
    basis = tangent_basis(state.normals)
    assert np.allclose(moved.normals, state.normals + np.einsum("tsab,tsb->tsa", basis, offsets))
    assert np.all(np.linalg.norm(moved.normals, axis=-1) >= 1.0)  # eq. 11: normals only grow
    assert np.allclose(moved.rotations, (np.eye(3) + skew(vectors)) @ state.rotations)
    done = retract(state, step)
    assert np.allclose(done.positions, state.positions + positions)
    assert np.allclose(np.linalg.norm(done.normals, axis=-1), 1.0)
    assert np.allclose(done.rotations @ np.swapaxes(done.rotations, -1, -2), np.eye(3), atol=1e-10)
    assert np.allclose(np.linalg.det(done.rotations), 1.0)
    # small rotation vectors: the retraction agrees with the exponential map to second order
    small = retract(
        state, 1e-4 * np.r_[np.zeros(lay.rotations_start), np.ones(lay.size - lay.rotations_start)]
    )
    assert np.abs(small.rotations - (np.eye(3) + skew(np.full(3, 1e-4)))).max() < 1e-7


def test_the_layout_addresses_each_unknown_once():
    lay = layout(_state(frames=4, count=7))
    t, s = np.meshgrid(np.arange(4), np.arange(7), indexing="ij")
    starts = np.concatenate(
        [
            (lay.position(t, s)[..., None] + np.arange(3)).ravel(),
            (lay.normal(t, s)[..., None] + np.arange(2)).ravel(),
            (lay.rotation(t[:-1], s[:-1])[..., None] + np.arange(3)).ravel(),
        ]
    )
    assert np.array_equal(np.sort(starts), np.arange(lay.size))


def test_state_validates_shapes():
    with pytest.raises(ValueError, match="rotations"):
        SurfelState(np.zeros((2, 5, 3)), np.zeros((2, 5, 3)), np.zeros((2, 5, 3, 3)))
    with pytest.raises(ValueError, match="normals"):
        SurfelState(np.zeros((2, 5, 3)), np.zeros((2, 4, 3)), np.zeros((1, 5, 3, 3)))
    with pytest.raises(ValueError, match="step"):
        layout(_state()).split(np.zeros(3))


def test_topology_links_within_eps_top_and_drops_stretched_edges():
    rng = np.random.default_rng(2)
    first = rng.uniform(0, 1, (300, 3))
    later = first.copy()
    later[:150] += [3.0, 0.0, 0.0]  # half moves away: their edges to the other half stretch
    graph = build_topology(np.stack([first, later]), 0.2)
    lengths = np.linalg.norm(first[graph.edges[:, 0]] - first[graph.edges[:, 1]], axis=1)
    assert len(graph.edges) > 300 and np.all(lengths <= 0.2)
    assert not np.any((graph.edges[:, 0] < 150) & (graph.edges[:, 1] >= 150))
    kept = build_topology(np.stack([first, later]), 0.2, max_stretch=None)
    assert np.any((kept.edges[:, 0] < 150) & (kept.edges[:, 1] >= 150))
    assert np.array_equal(graph.degrees, np.bincount(graph.directed[:, 0], minlength=300))


def test_topology_with_normals_flags_the_edges_along_the_surface():
    """A tube of radius 0.2, eps_top 0.5: in space both sides of it are within eps_top, along
    the surface (half the circumference, 0.63) they are not."""
    angle = np.linspace(0, 2 * np.pi, 19, endpoint=False)
    ring = np.c_[np.cos(angle), np.sin(angle)]
    heights = np.arange(0.0, 1.0, 0.1)
    normals = np.concatenate([np.c_[ring, np.zeros(len(ring))]] * len(heights))
    positions = np.concatenate([np.c_[0.2 * ring, np.full(len(ring), h)] for h in heights])
    spatial = build_topology(positions, 0.5, max_stretch=None)
    flagged = build_topology(positions, 0.5, max_stretch=None, normals=normals)
    assert np.array_equal(flagged.edges, spatial.edges)  # the deformation priors keep them all
    along = flagged.along_surface
    assert len(along.edges) == flagged.surface.sum() < len(spatial.edges)
    i, j = along.edges.T
    cosines = np.einsum("ij,ij->i", normals[i], normals[j])
    assert np.any(np.einsum("ij,ij->i", normals[spatial.edges[:, 0]], normals[spatial.edges[:, 1]]) < -0.9)
    # the arc between two surfels of one ring, theta apart, is 0.2 theta: at most 0.5
    assert cosines.min() > np.cos(0.5 / 0.2) - 1e-9
    # every pair whose arc is within eps_top stays: on a plane, normals change nothing
    arcs = np.hypot(0.2 * np.arccos(np.clip(cosines, -1, 1)), positions[i, 2] - positions[j, 2])
    assert arcs.max() <= 0.5 + 1e-9
    kept = set(map(tuple, along.edges))
    assert kept <= set(map(tuple, spatial.edges))
    flat = np.c_[np.random.default_rng(0).uniform(0, 1, (200, 2)), np.zeros(200)]
    up = np.tile([0.0, 0.0, 1.0], (200, 1))
    assert build_topology(flat, 0.2, normals=up).surface.all()
    # an edge along the tube's length is never dropped
    straight = (np.abs(cosines - 1) < 1e-12)
    assert np.sum(straight) == sum(
        1 for a, b in spatial.edges if np.allclose(normals[a], normals[b])
    )


def test_sample_surfels_keeps_one_point_per_cell():
    rng = np.random.default_rng(3)
    points = rng.uniform(0, 1, (5000, 3))
    chosen = sample_surfels(points, 0.25)
    cells = np.floor((points - points.min(axis=0)) / 0.25).astype(int)
    assert len(np.unique(cells[chosen], axis=0)) == len(chosen) == len(np.unique(cells, axis=0))


def test_fit_rotations_recovers_a_rigid_turn():
    rng = np.random.default_rng(4)
    first = rng.normal(size=(100, 3))
    angle = 0.4
    turn = np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    first[0] = 100.0  # no neighbours: identity
    positions = np.stack([first, first @ turn.T + 5.0])
    graph = build_topology(positions, 1.5)
    rotations = fit_rotations(positions, graph)
    assert rotations.shape == (1, 100, 3, 3)
    # three neighbours or more determine the rotation
    determined = graph.degrees >= 3
    assert determined.mean() > 0.8
    assert np.allclose(rotations[0, determined], turn, atol=1e-10)
    assert np.array_equal(rotations[0, 0], np.eye(3))
