"""The model's pieces: a small piece of the surfel graph that loses its data has only the
acceleration prior there and is left out of the mesh; a piece with data in every frame, or
one large enough to be carried by its own priors, stays."""

from __future__ import annotations

import numpy as np

from fourd.methods.surfels.model import Model, unsupported_pieces, without_surfels
from fourd.methods.surfels.state import surfel_state
from fourd.methods.surfels.topology import Topology
from fourd.methods.surfels.urshape import Urshape


def _model(observed_alone: np.ndarray) -> Model:
    """Frames ``T = 4``: a chain of 10 surfels with data in every frame, then surfel 10
    alone in the graph (data where ``observed_alone``), then a pair (11, 12) with data in
    frame 0 only, flying off at constant velocity after it."""
    frames, chain = 4, 10
    x = np.arange(chain, dtype=float)
    base = np.concatenate([np.stack([x, 0 * x, 0 * x], 1), [[20.0, 0, 0], [30, 0, 0], [31, 0, 0]]])
    positions = np.repeat(base[None], frames, axis=0)
    positions[:, 11:] += np.arange(frames)[:, None, None] * np.array([0.0, 0.0, 5.0])
    normals = np.broadcast_to([0.0, 0.0, 1.0], positions.shape).copy()
    edges = np.array([[i, i + 1] for i in range(chain - 1)] + [[11, 12]])
    observed = np.zeros((frames, len(base)), dtype=bool)
    observed[:, :chain] = True
    observed[:, 10] = observed_alone
    observed[0, 11:] = True
    urshape = Urshape(
        base.copy(), normals[0].copy(), np.broadcast_to(np.eye(3), (frames, len(base), 3, 3)).copy()
    )
    return Model(
        surfel_state(positions, normals), Topology(edges, len(base), 1.5), 0, observed, urshape
    )


def test_small_pieces_without_data_in_some_frame_are_found_and_dropped_with_their_urshape():
    model = _model(np.array([True, True, False, True]))
    lost = unsupported_pieces(model, 8)
    np.testing.assert_array_equal(np.flatnonzero(lost), [10, 11, 12])
    kept = without_surfels(model, lost)
    assert kept.state.count == 10 and kept.urshape.positions.shape == (10, 3)
    assert kept.urshape.rotations.shape == (4, 10, 3, 3) and len(kept.topology.edges) == 9
    # what is left lies where the data was in every frame (the pair flew 15 units away)
    assert np.abs(kept.state.positions[:, :, 2]).max() == 0.0
    # a piece large enough for its own priors stays, and so does everything with min_piece 0
    assert not unsupported_pieces(model, 2)[11:].any() and unsupported_pieces(model, 2)[10]
    assert not unsupported_pieces(model, 0).any()
    # the chain is never dropped: it has data in every frame
    assert not unsupported_pieces(model, 100)[:10].any()


def test_a_lone_surfel_with_data_in_every_frame_stays():
    model = _model(np.ones(4, dtype=bool))
    np.testing.assert_array_equal(np.flatnonzero(unsupported_pieces(model, 8)), [11, 12])
    assert without_surfels(model, np.zeros(13, dtype=bool)) is model


def _plane_and_lost_pair() -> Model:
    """Frames ``T = 3``: a flat 12 x 12 grid of surfels one unit apart with data in every
    frame, and a pair of surfels far off with data in frame 0 only."""
    frames = 3
    x, y = np.meshgrid(np.arange(12.0), np.arange(12.0))
    grid = np.stack([x.ravel(), y.ravel(), 0 * x.ravel()], 1)
    base = np.concatenate([grid, [[30.0, 5, 0], [31, 5, 0]]])
    positions = np.repeat(base[None], frames, axis=0)
    normals = np.broadcast_to([0.0, 0.0, 1.0], positions.shape).copy()
    index = np.arange(144).reshape(12, 12)
    edges = np.concatenate(
        [
            np.stack([index[:, :-1].ravel(), index[:, 1:].ravel()], 1),
            np.stack([index[:-1].ravel(), index[1:].ravel()], 1),
            [[144, 145]],
        ]
    )
    observed = np.zeros((frames, len(base)), dtype=bool)
    observed[:, :144] = True
    observed[0, 144:] = True
    return Model(surfel_state(positions, normals), Topology(edges, len(base), 2.0), 0, observed)


def test_the_streamed_mesh_leaves_out_the_small_pieces_without_data_too():
    from fourd.methods.surfels.options import Options
    from fourd.methods.surfels.stream import _first_mesh

    model = _plane_and_lost_pair()
    for min_piece, pair_meshed in ((8, False), (0, True)):
        carried = _first_mesh(model, 1.0, Options(min_piece=min_piece))
        assert (carried.binding.surfel >= 144).any() == pair_meshed
        assert (carried.rest[:, 0] > 20).any() == pair_meshed
        assert (carried.rest[:, 0] < 12).any()  # the plane is meshed either way
