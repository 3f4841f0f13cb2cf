"""Patch flattening: LSCM and ABF++ against analytic truth (developable patches unroll
isometrically; a curved cap flattens without flips, ABF++ keeping the angles at least as well)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from fourd.geometry.flattening import (
    AbfOptions,
    abf,
    angle_distortion,
    angles_to_uv,
    boundary_loop_vertices,
    corner_angles,
    flatten,
    lscm,
    map_singular_values,
    signed_uv_areas,
)
from fourd.geometry.marching import compact


def _sheet(n=13, m=9):
    """A jittered triangulated unit square: parameters ``s, t [N]`` and faces."""
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    index = i * m + j
    quads = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1).reshape(-1, 4)
    flip = (np.arange(len(quads)) % 3) == 0  # both diagonals occur
    faces = np.concatenate([
        np.where(flip[:, None], quads[:, [0, 1, 3]], quads[:, [0, 1, 2]]),
        np.where(flip[:, None], quads[:, [1, 2, 3]], quads[:, [0, 2, 3]]),
    ])
    return i.ravel() / (n - 1), j.ravel() / (m - 1), faces


def _cylinder_piece():
    s, t, faces = _sheet()
    return np.stack([np.cos(2.0 * s), np.sin(2.0 * s), 1.5 * t], axis=1), faces


def _folded_plane():
    s, t, faces = _sheet(n=13)
    fold = s > 0.5  # folded by 100 degrees along s = 0.5 (a grid line)
    angle = np.radians(100.0)
    x = np.where(fold, 0.5 + (s - 0.5) * np.cos(angle), s)
    z = np.where(fold, (s - 0.5) * np.sin(angle), 0.0)
    return np.stack([x, t, z], axis=1), faces


def _cap(height=0.0, subdivisions=3):
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    inside = np.asarray(sphere.vertices)[:, 2] > height
    return compact(np.asarray(sphere.vertices), np.asarray(sphere.faces)[inside[sphere.faces].all(axis=1)])


@pytest.mark.parametrize("method", ["lscm", "abf"])
@pytest.mark.parametrize("patch", [_cylinder_piece, _folded_plane])
def test_a_developable_patch_unrolls_isometrically(method, patch):
    vertices, faces = patch()
    flat = flatten(vertices, faces, method=method)
    stretch = map_singular_values(vertices, faces, flat.uv)
    assert np.abs(stretch - 1.0).max() < 1e-9
    assert signed_uv_areas(faces, flat.uv).min() > 0  # no flips, orientation kept
    assert flat.converged and np.allclose(flat.uv[flat.pinned[0]], 0.0)
    assert abs(flat.uv[flat.pinned[1], 1]) < 1e-12 and flat.uv[flat.pinned[1], 0] > 0


def test_a_curved_cap_flattens_without_flips_and_abf_keeps_angles_at_least_as_well():
    vertices, faces = _cap(height=0.0)  # a hemisphere: strongly curved
    conformal, angle_based = lscm(vertices, faces), abf(vertices, faces)
    for flat in (conformal, angle_based):
        assert signed_uv_areas(faces, flat.uv).min() > 0
        total = np.abs(signed_uv_areas(faces, flat.uv)).sum()
        assert abs(total / trimesh.Trimesh(vertices, faces).area - 1.0) < 1e-9  # scaled to the area
    assert angle_based.converged and 0 < angle_based.iterations <= 10
    # measured (hemisphere, 562 faces): lscm 0.02858, abf 0.02829; abf in 4 Newton steps
    assert angle_distortion(vertices, faces, angle_based.uv) <= angle_distortion(vertices, faces, conformal.uv)
    phi = corner_angles(vertices, faces)
    worst = [np.abs(corner_angles(f.uv, faces) - phi).max() for f in (conformal, angle_based)]
    assert worst[1] <= worst[0]


def test_abf_angles_are_consistent_so_the_layout_reproduces_them():
    """ABF++'s converged angles satisfy every constraint: laid out, they come back."""
    from fourd.geometry.flattening import _abf_angles

    vertices, faces = _cap(height=0.3)
    interior = ~boundary_loop_vertices(faces, len(vertices))
    angles, steps, residual = _abf_angles(corner_angles(vertices, faces), faces, interior, len(vertices), AbfOptions())
    assert residual < 1e-9 and steps >= 1
    uv = angles_to_uv(vertices, faces, angles)
    np.testing.assert_allclose(corner_angles(uv, faces), angles, atol=1e-7)


def test_pins_and_bad_patches():
    vertices, faces = _folded_plane()
    flat = lscm(vertices, faces, pinned=[0, 5])
    assert flat.pinned.tolist() == [0, 5] and np.allclose(flat.uv[0], 0.0)
    with pytest.raises(ValueError, match="two different"):
        lscm(vertices, faces, pinned=[3, 3])
    sphere = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(ValueError, match="not a disk"):
        abf(sphere.vertices, sphere.faces)
    with pytest.raises(ValueError, match="compact"):
        lscm(np.concatenate([vertices, [[9.0, 9.0, 9.0]]]), faces)
    with pytest.raises(ValueError, match="method"):
        flatten(vertices, faces, method="arap")



def test_the_disk_check_names_what_is_wrong():
    box = trimesh.creation.box()
    with pytest.raises(ValueError, match="Euler characteristic 2"):
        boundary_loop_vertices(box.faces, 8)
    with pytest.raises(ValueError, match="three or more faces"):
        boundary_loop_vertices(np.array([[0, 1, 2], [0, 2, 3], [0, 2, 4]]), 5)
    z = box.vertices[box.faces, 2]
    tube = box.faces[np.ptp(z, axis=1) > 0]  # the box without top and bottom: Euler characteristic 0
    with pytest.raises(ValueError, match="2 connected pieces"):
        boundary_loop_vertices(np.vstack([tube, [[8, 9, 10]]]), 11)  # and a triangle beside it: 1
    with pytest.raises(ValueError, match="touches itself"):
        boundary_loop_vertices(np.array([[0, 1, 2], [0, 3, 4]]), 5)  # two triangles meeting at a vertex
    assert boundary_loop_vertices(np.array([[0, 1, 2], [1, 3, 2]]), 4).all()
    s, t, faces = _sheet(n=13)
    inside = (s > s.min()) & (s < s.max()) & (t > t.min()) & (t < t.max())
    assert np.array_equal(~boundary_loop_vertices(faces, len(s)), inside)


def test_small_patches_solved_dense_flatten_as_the_sparse_solve_does(monkeypatch):
    import fourd.geometry.flattening as flattening

    vertices, faces = _cap(height=0.3)
    dense = lscm(vertices, faces).uv
    monkeypatch.setattr(flattening, "DENSE_UNKNOWNS", 0)
    assert np.allclose(lscm(vertices, faces).uv, dense, rtol=0, atol=1e-9)


@pytest.mark.parametrize("dense", [True, False])
def test_a_nearly_singular_layout_comes_back_nan_without_overflow_warnings(monkeypatch, dense):
    import fourd.geometry.flattening as flattening

    vertices, faces = _cap(height=0.3)
    if not dense:
        monkeypatch.setattr(flattening, "DENSE_UNKNOWNS", 0)
    # a solve that sends the free vertices millions of diagonals away, as a nearly singular
    # system does, instead of failing outright
    real_zposv, real_spsolve = flattening.zposv, flattening.spsolve

    def far_zposv(*args, **kwargs):
        factor, solution, info = real_zposv(*args, **kwargs)
        return factor, solution * 1e200, info

    monkeypatch.setattr(flattening, "zposv", far_zposv)
    monkeypatch.setattr(flattening, "spsolve", lambda *args, **kwargs: real_spsolve(*args, **kwargs) * 1e200)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no overflow on the way
        flat = lscm(vertices, faces)
    assert np.isnan(flat.uv).all()
    monkeypatch.undo()
    assert np.isfinite(lscm(vertices, faces).uv).all()
