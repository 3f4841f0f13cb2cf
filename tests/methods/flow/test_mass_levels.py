"""The flow's mass levels: meshes moved to the conserved mass."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from flow_scenes import (
    _check_closed_manifold,
)

from fourd.methods.flow import (
    Options,
)


def test_mass_meshes_move_only_the_unobserved_parts():
    """Two frames of a sphere, radius 0.5 and 0.55, both seen only on their upper half (z >
    0), with the same flow mass: the volumes become equal, the seen halves stay where they
    were, and the unseen halves move apart by what makes up the difference."""
    from fourd.methods.flow.mass_levels import _mesh_volume, mass_meshes

    sphere = trimesh.creation.icosphere(subdivisions=4)
    meshes = [(r * sphere.vertices, sphere.faces) for r in (0.5, 0.55)]
    points = [v[v[:, 2] > 0] for v, _ in meshes]
    h = 0.05
    moved = mass_meshes(
        meshes, points, np.array([1.0, 1.0]), h=h, reach=0.5, limit=4.0, smoothing=0
    )
    volumes = np.array([_mesh_volume(v, f) for v, f in moved])
    before = np.array([_mesh_volume(v, f) for v, f in meshes])
    assert abs(volumes[0] / volumes[1] - 1) < 0.002
    assert abs(volumes.mean() / before.mean() - 1) < 0.01
    for (v, _), (w, f) in zip(meshes, moved, strict=True):
        _check_closed_manifold(w, f)
        seen = v[:, 2] > 0
        assert np.abs(w[seen] - v[seen]).max() < 1e-12
        far_below = v[:, 2] < -2 * h
        radial = np.linalg.norm(w[far_below], axis=1) - np.linalg.norm(v[far_below], axis=1)
        assert abs(radial[0]) > 0.01 and np.ptp(radial) < 1e-3 * abs(radial[0])  # one offset
    # the smaller sphere's lower half grew, the larger one's shrank
    assert np.linalg.norm(moved[0][0], axis=1).min() > 0.5 - 1e-9
    assert np.linalg.norm(moved[1][0], axis=1).max() < 0.55 + 1e-9
    # a frame without points moves as a whole, by at most the limit
    whole = mass_meshes(
        meshes, [points[0], None], np.array([1.0, 1.0]), h=h, limit=0.1, smoothing=0
    )
    assert np.allclose(np.linalg.norm(whole[1][0], axis=1), 0.55 - 0.1 * h)


def test_mass_levels_auto_leaves_volumes_that_the_unseen_parts_cannot_explain():
    """all_or_nothing (mass_levels="auto"): two half-seen spheres of radius 0.5 and 0.55 need
    their unseen halves moved by about 0.05 to reach equal volumes, well under their radius:
    applied. A sphere of radius 0.5 next to one of 1.5 would need its unseen half moved by
    several times its radius: every frame left as it was (as if the volume truly changed).
    mass_levels is validated."""
    from fourd.methods.flow.mass_levels import _mesh_volume, mass_meshes

    sphere = trimesh.creation.icosphere(subdivisions=4)
    mass = np.array([1.0, 1.0])
    meshes = [(r * sphere.vertices, sphere.faces) for r in (0.5, 0.55)]
    points = [v[v[:, 2] > 0] for v, _ in meshes]
    kept = mass_meshes(meshes, points, mass, h=0.05, smoothing=0, all_or_nothing=True)
    volumes = np.array([_mesh_volume(v, f) for v, f in kept])
    assert abs(volumes[0] / volumes[1] - 1) < 0.002
    meshes = [(r * sphere.vertices, sphere.faces) for r in (0.5, 1.5)]
    points = [v[v[:, 2] > 0] for v, _ in meshes]
    left = mass_meshes(meshes, points, mass, h=0.05, limit=40.0, smoothing=0, all_or_nothing=True)
    assert all(w is v for (w, _), (v, _) in zip(left, meshes, strict=True))
    moved = mass_meshes(meshes, points, mass, h=0.05, limit=40.0, smoothing=0)
    assert not np.allclose(moved[0][0], meshes[0][0])  # without it: moved
    assert Options().mass_levels == "auto"
    with pytest.raises(ValueError):
        Options(mass_levels="sometimes")



def test_mass_meshes_measure_what_is_observed_in_observed_cells():
    """Data 0.02 off the seen upper halves (scan noise, gaps between scan lines): with flow
    cells of 0.025 as the unit the seen halves count as partly unobserved and move; in cells
    of 0.05 (``observed_cell``, what ``run`` passes above resolution 32) they stay."""
    from fourd.methods.flow.mass_levels import mass_meshes

    sphere = trimesh.creation.icosphere(subdivisions=4)
    meshes = [(r * sphere.vertices, sphere.faces) for r in (0.5, 0.55)]
    points = [1.04 * v[v[:, 2] > 0] for v, _ in meshes]
    common = {"h": 0.025, "reach": 0.5, "limit": 40.0, "smoothing": 0}
    fine = mass_meshes(meshes, points, np.ones(2), **common)
    coarse = mass_meshes(meshes, points, np.ones(2), **common, observed_cell=0.05)
    for (v, _), (w, _), (u, _) in zip(meshes, fine, coarse, strict=True):
        seen = v[:, 2] > 0.05
        assert np.abs(u[seen] - v[seen]).max() < 1e-12
        assert np.abs(w[seen] - v[seen]).max() > 1e-3


def test_mass_meshes_smooth_a_dent_out_of_a_frame_whose_volume_is_off():
    """A sphere (radius 0.5) whose unseen bottom cap is pushed 0.2 inwards, a pit, next to a
    frame of radius 0.56 with the same mass: the pitted frame's unseen half must move out by
    more than a flow cell, so it is smoothed first (the pit's depth below the rest of the
    unseen half drops by more than a third), the seen half stays, and both volumes meet. Alone
    (its volume already the target) the pitted frame keeps its unseen shape: what the flow got
    right, such as bumps carried round from frames that saw them, is not flattened."""
    from fourd.methods.flow.mass_levels import _mesh_volume, mass_meshes

    sphere = trimesh.creation.icosphere(subdivisions=4)
    vertices = 0.5 * sphere.vertices
    pit = vertices[:, 2] < -0.45
    vertices[pit] *= 0.6
    pitted, other = (vertices, sphere.faces), (0.56 * sphere.vertices, sphere.faces)
    points = [v[v[:, 2] > 0] for v, _ in (pitted, other)]
    (moved, faces), (grown, _) = mass_meshes([pitted, other], points, np.ones(2), h=0.05)
    _check_closed_manifold(moved, faces)
    assert abs(_mesh_volume(moved, faces) / _mesh_volume(grown, faces) - 1) < 2e-3
    seen = vertices[:, 2] > 0
    assert np.abs(moved[seen] - vertices[seen]).max() < 1e-12

    def depth(v):
        rest = (vertices[:, 2] < -0.1) & ~pit
        return np.linalg.norm(v[rest], axis=1).mean() - np.linalg.norm(v[pit], axis=1).mean()

    assert depth(moved) < 2 / 3 * depth(vertices), (depth(moved), depth(vertices))
    ((alone, _),) = mass_meshes([pitted], points[:1], np.ones(1), h=0.05)
    assert np.array_equal(alone, vertices)
