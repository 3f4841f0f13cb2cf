"""Method ``flow`` (paper 002): the whole pipeline -- watertight output, volume, topology,
missing frames -- and its options.

(Named after the method, not ``test_pipeline.py``: the test folders have no ``__init__.py``,
so test file names must be unique across them.)
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from flow_scenes import (
    FAST,
    SENSORS,
    _check_closed_manifold,
    _ellipsoid_scan,
    _squash_sequence,
    _turning_ball_frames,
)

from fourd import InputError, MeshSequence, PointCloudSequence, synth
from fourd.geometry.field import Field4D
from fourd.methods import method_options
from fourd.methods.flow import (
    Options,
    mass_conservation_error,
    reconstruct,
    run,
)
from fourd.methods.flow.post import (
    drop_cavities,
)


@pytest.fixture(scope="module")
def squash_result():  # about 20 s on a loaded 2-core machine
    seq, volumes = _squash_sequence(4)
    return run(seq, Options(**FAST)), volumes


@pytest.mark.slow
def test_every_frame_closed_manifold_and_volume_kept(squash_result):
    result, volumes = squash_result
    assert len(result.meshes) == 4
    measured = np.array([_check_closed_manifold(v, f).volume for v, f in result.meshes.meshes])
    assert np.all(np.abs(measured / volumes - 1) < 0.15)
    spread = measured.std() / measured.mean()
    assert spread < 0.05


@pytest.mark.slow
def test_mass_error_reported_and_field_protocol(squash_result):
    result, _ = squash_result
    assert 0 <= result.mass_error < 0.1
    assert result.mass_error == pytest.approx(mass_conservation_error(result.mass))
    field = result.field
    assert isinstance(field, Field4D)
    centre = np.zeros((1, 3))
    far = np.array([[5.0, 5.0, 5.0]])
    assert field.value(centre, 0.0)[0] < 0 < field.value(far, 0.0)[0]
    # the gradient points outwards on the +x side of the ball
    g = field.gradient(np.array([[0.45, 0.0, 0.0]]), 0.5)
    assert g.shape == (1, 4) and g[0, 0] > 0


def test_mass_conservation_error_definition():
    assert mass_conservation_error([2.0, 2.0, 2.0]) == 0.0
    assert mass_conservation_error(np.ones((3, 4, 4))) == 0.0
    assert mass_conservation_error([1.0, 3.0]) == pytest.approx(0.5)


def test_options_validated_through_registry():
    options = method_options(
        "flow", {"resolution": "20", "neighbourhood": "27", "coherent": "false"}
    )
    assert options.resolution == 20 and options.neighbourhood == 27
    with pytest.raises(InputError):
        method_options("flow", {"neighbourhood": "9"})
    with pytest.raises(InputError):
        method_options("flow", {"inner": "lu"})
    with pytest.raises(InputError, match="interpolation_entries"):
        method_options("flow", {"interpolation_entries": "-1"})


@pytest.mark.slow
def test_automatic_substeps_follow_fast_motion():
    """A ball whose top moves ~1.2 cells per frame: time_substeps=0 inserts a slice between
    the frames and every frame stays closed, without cavities, near its ellipsoid."""
    frames, radius = 3, 0.5
    points, all_radii = [], []
    for t in range(frames):
        a = np.exp(0.4 * t / (frames - 1))
        all_radii.append(radius * np.array([1 / np.sqrt(a), a, 1 / np.sqrt(a)]))
        points.append(_ellipsoid_scan(all_radii[-1], seed=t, hole=False))
    sensors = np.vstack([SENSORS, [[0.0, 3.0, 0.0]]])
    seq = PointCloudSequence.from_arrays(points, sensors=sensors)
    result = run(seq, Options(resolution=16, max_iterations=3, time_substeps=0, max_substeps=3))
    assert result.grid.slices == 2 * (frames - 1) + 1
    for (vertices, faces), radii in zip(result.meshes.meshes, all_radii, strict=True):
        _check_closed_manifold(vertices, faces)
        assert drop_cavities(vertices, faces)[2] == 0
        off = np.abs(np.linalg.norm(vertices / radii, axis=1) - 1.0)
        assert off.mean() < 0.05, off.mean()


@pytest.mark.slow
def test_missing_frame_reconstructed():
    seq, volumes = _squash_sequence(4)
    result = run(seq, Options(**FAST, missing_frames=(2,)))
    vertices, faces = result.meshes.meshes[2]
    mesh = _check_closed_manifold(vertices, faces)
    assert abs(mesh.volume / volumes[2] - 1) < 0.2
    # surface close to the truth ellipsoid of frame 2 (within a flow cell)
    a = np.exp(0.3 * np.sin(2 * np.pi * 2 / 4))
    radii = 0.5 * np.array([1 / np.sqrt(a), a, 1 / np.sqrt(a)])
    level = np.linalg.norm(vertices / radii, axis=1)
    assert np.median(np.abs(level - 1)) * radii.min() < result.grid.h
    with pytest.raises(InputError):
        run(seq, Options(**FAST, missing_frames=(9,)))


@pytest.mark.slow
def test_splitting_blob_components():
    from fourd.synth import scan, scene

    truth = scene("splitting-blob", frames=6)
    scans = scan(truth, cameras=3, noise=0.002, outliers=0.02)  # the standard scan
    # the default iso-level (mass_levels adds pockets at this resolution, see its option)
    result = reconstruct(scans, Options(resolution=24, max_iterations=8))
    counts = []
    for v, f in result.meshes:
        mesh = _check_closed_manifold(v, f)
        counts.append(len(mesh.split(only_watertight=False)))
    truth_counts = [
        len(trimesh.Trimesh(v, f).split(only_watertight=False)) for v, f in truth.meshes
    ]
    assert truth_counts[0] == 1 and truth_counts[-1] == 2
    # one body before the pinch, two once the gap is wider than a flow cell (the frame right
    # after the pinch, with a sub-cell gap, may still be joined)
    assert counts[: truth_counts.index(2)] == [1] * truth_counts.index(2)
    assert counts[-2:] == [2, 2]
    assert all(a <= b for a, b in zip(counts, counts[1:], strict=False))


@pytest.fixture(scope="module")
def squash_scene_volumes():
    from fourd.synth import scan, scene

    truth = scene("squash-ball", frames=4)
    scans = scan(truth, cameras=3, resolution=96, noise=0.002, outliers=0.02)
    # the default mass_levels="auto" finds the ball incompressible and sets its volumes
    result = reconstruct(scans, Options(resolution=24, max_iterations=8))
    return np.array([_check_closed_manifold(v, f).volume for v, f in result.meshes])


@pytest.mark.slow
def test_a_ball_seen_from_above_keeps_its_unseen_half_with_the_previous_prior():
    """The standard cameras look down on the ball, so its lower half is one large hole. With
    ``regularize_towards="previous"`` the flow fills it (0.985 of the truth's volume); with the
    paper's pull towards zero its cells sink below 0.5 (0.61)."""
    from fourd.synth import scan, scene

    truth = scene("squash-ball", frames=3, strength=0.0)
    scans = scan(truth, cameras=3, resolution=96, noise=0.002, outliers=0.02)
    result = reconstruct(scans, Options(resolution=24, regularize_towards="previous"))
    volumes = np.array([_check_closed_manifold(v, f).volume for v, f in result.meshes])
    assert np.all(np.abs(volumes / (4 / 3 * np.pi * 0.6**3) - 1) < 0.05)


@pytest.mark.slow
def test_a_turning_thick_ball_keeps_its_interior():
    """A bumpy ball turning under three cameras that look down on it, at resolution 24 (the
    ball about 24 cells across). The fit's local minima label a handful of cells inside, and
    with only those the capped IRLS leaves a pit from the unseen underside into the ball (0.90
    of the truth's volume, the 99th percentile of the distance to the truth 0.15 of its
    diagonal); with the fit's deep interior labelled too, 0.945 and 0.09."""
    for volume, distance in _turning_ball_frames(scan_resolution=96, resolution=24):
        assert volume > 0.93
        assert np.percentile(distance, 99) < 0.12


def test_regularize_towards_is_validated():
    with pytest.raises(ValueError, match="regularize_towards"):
        Options(regularize_towards="one")


@pytest.mark.parametrize("field", ["observed_distance", "level_limit", "unobserved_smoothing"])
def test_mass_level_settings_are_validated(field):
    with pytest.raises(ValueError, match=field):
        Options(**{field: -1})


@pytest.mark.slow
def test_squash_ball_scene_closed_and_volume_bounded(squash_scene_volumes):
    volumes = squash_scene_volumes
    truth = 4 / 3 * np.pi * 0.6**3
    assert np.all(np.abs(volumes / truth - 1) < 0.2)
    assert (volumes.max() - volumes.min()) / volumes.mean() < 0.15


@pytest.mark.slow
def test_squash_ball_scene_volume_target(squash_scene_volumes):
    """The issue's 2%. It failed while mass_levels followed the flow's per-frame mass, whose
    own range (the capped solves' error) was about 3% here."""
    volumes = squash_scene_volumes
    assert (volumes.max() - volumes.min()) / volumes.mean() < 0.02


def test_reconstruct_with_diagnostics_reports_the_mass_error(monkeypatch):
    import fourd.methods.flow as flow
    import fourd.methods.flow.method as method
    from fourd.methods import reconstruct_with_diagnostics

    scans = synth.scan(synth.scene("squash-ball", frames=2), resolution=32)
    meshes = MeshSequence(meshes=((np.eye(3), np.array([[0, 1, 2]])),) * 2)
    fake = SimpleNamespace(meshes=meshes, mass_error=0.017)
    monkeypatch.setattr(method, "run", lambda seq, options=None: fake)  # where it is looked up
    result, diagnostics = reconstruct_with_diagnostics(scans, method="flow")
    assert result is meshes and diagnostics == flow.FlowDiagnostics(0.017)


@pytest.mark.slow
def test_a_thick_ball_at_resolution_48_is_solid():
    """rigid-turn at flow resolution 48 (the ball about 48 cells across): with the fit's
    offset points and deep interior labelled 2 cells under the data (the defaults from 48
    on), each frame keeps 0.985 of the truth's volume; without them (``fit_offset=0``,
    ``deep_inside=4``, the defaults at 32) the ball came out hollow, 0.26 of its volume."""
    for volume, distance in _turning_ball_frames(scan_resolution=128, resolution=48):
        assert volume > 0.95
        assert np.mean(distance) < 0.004
        assert np.percentile(distance, 99) < 0.05
