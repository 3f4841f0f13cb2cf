"""The urshape of the ``kinematic`` method (000_00387fefe94cc850.txt section 4)."""

import numpy as np
from kinematic_shapes import MovingBlob, _sphere_template

from fourd.methods import kinematic as K
from fourd.methods.kinematic import urshape


def test_extract_template_lies_on_the_surface_and_is_closed():
    blob = MovingBlob()
    V, F = _sphere_template(blob)
    assert len(F) > 500
    assert np.abs(blob.value(V, 0.0)).max() < 1e-3
    edges = np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed 2-manifold edges
    # outward orientation: positive enclosed volume
    volume = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
    assert volume > 3.0


def test_extract_template_corrects_its_cell_size_towards_the_target_vertex_count():
    blob = MovingBlob()
    bounds = np.array([np.full(3, -1.4), np.full(3, 1.4)])
    first = len(K.extract_template(blob, 0.0, bounds=bounds, cell_size=0.12)[0])
    for target in (int(first * 0.6), int(first * 1.15), int(first * 1.05)):
        count = len(K.extract_template(
            blob, 0.0, bounds=bounds, cell_size=0.12, target_vertices=target
        )[0])
        if abs(first / target - 1.0) <= urshape.VERTEX_TOLERANCE:
            assert count == first  # close enough: no second marching cubes
        else:
            assert abs(count / target - 1.0) < 0.05


def test_the_template_is_no_denser_than_sparse_frames():
    from fourd.methods.kinematic.urshape import template_size

    dense = [np.zeros((20000, 3))] * 3
    sparse = [np.zeros((2500, 3)), np.zeros((3000, 3)), np.zeros((2800, 3))]
    assert template_size(10000, dense) == 10000
    assert template_size(10000, sparse) == 2800
