"""The local relaxation of a cross-parameterisation (thesis 5.4.3): an exact map stays, a map
slid along the target by noise comes back towards the truth and loses its flips."""

from __future__ import annotations

import numpy as np
import pytest
from assembly_shapes import remeshed_frames, rigid_copy, slid_map, true_map

from fourd.methods.assembly import RelaxOptions, flipped_triangles, relax_map
from fourd.methods.assembly.options import Options


def _relax(pair, faces, bary, **kwargs):
    return relax_map(pair.source_vertices, pair.source_faces, pair.target_vertices, pair.target_faces,
                     faces, bary, **kwargs)


def _error(pair, points):
    return np.linalg.norm(points - pair.truth, axis=1) / pair.edge


@pytest.mark.parametrize("laplacian", ["uniform", "cotangent"])
def test_a_rigidly_moved_copy_keeps_the_identity_map(laplacian):
    pair = rigid_copy()
    faces, bary = true_map(pair)
    result = _relax(pair, faces, bary, options=RelaxOptions(laplacian=laplacian, sweeps=2))
    # the one-ring rotations take the motion out: the energy is zero at the start
    assert result.energy.max() < 1e-20 * pair.edge**2
    assert (result.flipped == 0).all()
    # measured: 9e-16 edges
    assert _error(pair, result.points).max() < 1e-9


def test_a_slid_map_comes_back_towards_the_truth_without_flips():
    pair = remeshed_frames()  # bending-arm frames 0 and 3, each remeshed on its own
    faces, bary = slid_map(pair, noise=0.4)
    before = _error(pair, _relax(pair, faces, bary, options=RelaxOptions(sweeps=0)).points)
    result = _relax(pair, faces, bary)
    after = _error(pair, result.points)
    # measured: median 0.47 -> 0.15, 95th percentile 0.99 -> 0.29 source edges; energy
    # 44 -> 0.19; 420 flipped triangles -> 0 (14 after the first sweep)
    assert np.median(after) < 0.4 * np.median(before)
    assert np.percentile(after, 95) < 0.4 * np.percentile(before, 95)
    assert result.energy[-1] < 0.01 * result.energy[0]
    assert np.all(np.diff(result.energy) < 0)
    assert result.flipped[0] > 100 and result.flipped[-1] == 0
    assert not flipped_triangles(pair.source_faces, pair.target_vertices, pair.target_faces,
                                 result.faces, result.barycentric).any()
    corners = pair.target_vertices[pair.target_faces[result.faces]]
    np.testing.assert_allclose(np.einsum("nk,nkd->nd", result.barycentric, corners), result.points)
    assert (result.barycentric >= 0).all()


def test_the_sweeps_stop_once_one_gains_less_than_the_tolerance():
    pair = remeshed_frames()
    faces, bary = slid_map(pair, noise=0.4)
    full = _relax(pair, faces, bary, options=RelaxOptions(sweeps=6))
    gains = -np.diff(full.energy) / full.energy[0]
    tolerance = 0.5 * (gains[1] + gains[2])  # between the second sweep's gain and the third's
    assert gains[1] > tolerance > gains[2]
    stopped = _relax(pair, faces, bary, options=RelaxOptions(sweeps=6, tolerance=tolerance))
    # the same sweeps as the full run up to the first that gained too little, then no more
    assert len(stopped.energy) == 4
    np.testing.assert_array_equal(stopped.energy, full.energy[:4])
    with pytest.raises(ValueError, match="tolerance"):
        RelaxOptions(tolerance=1.0)
    for value in (-0.01, 1.0, float("nan")):  # the assembly's own option names itself
        with pytest.raises(ValueError, match="relax_tolerance"):
            Options(relax_tolerance=value)


def test_fixed_and_unmapped_vertices_stay_where_they_are():
    pair = rigid_copy()
    faces, bary = slid_map(pair, noise=0.3)
    rng = np.random.default_rng(3)
    unmapped = rng.random(len(faces)) < 0.05
    fixed = ~unmapped & (rng.random(len(faces)) < 0.2)
    true_faces, true_bary = true_map(pair)
    faces = np.where(unmapped, -1, np.where(fixed, true_faces, faces))  # fixed: at the truth
    bary = np.where(fixed[:, None], true_bary, bary)
    result = _relax(pair, faces, bary, fixed=fixed)
    assert (result.faces[unmapped] == -1).all() and np.isnan(result.points[unmapped]).all()
    np.testing.assert_array_equal(result.faces[fixed], faces[fixed])
    np.testing.assert_array_equal(result.barycentric[fixed], bary[fixed])
    moved = ~unmapped & ~fixed
    before = _error(pair, _relax(pair, faces, bary, options=RelaxOptions(sweeps=0)).points)
    # measured: median 0.35 -> 0.08 source edges, the holes and the fixed vertices kept
    assert np.median(_error(pair, result.points)[moved]) < 0.5 * np.median(before[moved])


def test_a_collapsed_target_triangle_is_walked_round():
    """A target triangle with two corners at one point (marching cubes makes them; crane-50
    met one and the compiled step divided by its zero edge): the vertex mapped into it keeps
    its place for the step, the others relax as ever."""
    pair = rigid_copy()
    faces, bary = slid_map(pair, noise=0.3)
    collapsed = int(faces[0])
    target = pair.target_vertices.copy()
    target[pair.target_faces[collapsed, 1]] = target[pair.target_faces[collapsed, 0]]
    pair = pair._replace(target_vertices=target)
    bary = bary.copy()
    bary[0] = 1.0 / 3.0
    before = _error(pair, _relax(pair, faces, bary, options=RelaxOptions(sweeps=0)).points)
    result = _relax(pair, faces, bary)
    assert np.isfinite(result.points).all() and (result.faces >= 0).all()
    assert np.median(_error(pair, result.points)) < 0.5 * np.median(before)


def test_bad_input_is_an_error():
    pair = rigid_copy()
    faces, bary = true_map(pair)
    with pytest.raises(ValueError, match="one row per source vertex"):
        _relax(pair, faces[:-1], bary)
    with pytest.raises(ValueError, match="out of range"):
        _relax(pair, faces + len(pair.target_faces), bary)
    with pytest.raises(ValueError, match="laplacian"):
        RelaxOptions(laplacian="mean")
    with pytest.raises(ValueError, match="steps"):
        RelaxOptions(steps=0)
