"""Method ``kinematic`` (000_00387fefe94cc850.txt): the whole pipeline and its options.

(Named after the method, not ``test_pipeline.py``: the test folders have no ``__init__.py``,
so test file names must be unique across them.)
"""

import numpy as np
import pytest
from kinematic_shapes import _blob_sequence

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.methods import kinematic as K
from fourd.methods import reconstruct
from fourd.sequence import Frame, PointCloudSequence


@pytest.mark.slow
def test_reconstruct_tracks_a_rigid_scan_at_the_noise_level():
    blob, seq = _blob_sequence()
    anim = reconstruct(seq, "kinematic", template_vertices=7000)
    assert isinstance(anim, AnimatedMesh) and anim.rest is not None
    assert anim.vertices.shape[0] == len(seq)
    for t in range(len(seq)):
        R, c = blob.motion(t)
        R0, c0 = blob.motion(0)
        expected = (anim.rest - c0) @ R0 @ R.T + c
        assert np.linalg.norm(anim.vertices[t] - expected, axis=1).mean() < 0.02
        assert np.abs(blob.value(anim.vertices[t], t)).mean() < 0.01
    assert anim.observed.mean() > 0.9


def test_a_still_shape_of_revolution_is_not_spun_by_the_noise():
    """A spheroid held still, scanned with noise: its spin about its axis does not change
    the fit, so only a rigid prediction that ignores such directions keeps the template
    still (measured: 0.003 with it, 0.031 and growing without it at the last frame)."""
    rng = np.random.default_rng(0)
    frames = []
    for t in range(8):
        d = rng.normal(size=(2500, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        points = d * np.array([1.0, 1.3, 1.0]) + 0.003 * rng.normal(size=(2500, 3))
        frames.append(Frame(points=points, time=float(t)))
    anim = reconstruct(PointCloudSequence(frames), "kinematic", template_vertices=2000)
    drift = np.linalg.norm(anim.vertices - anim.vertices[0], axis=2).mean(axis=1)
    assert drift.max() < 0.01, np.round(drift, 4)


@pytest.mark.slow
def test_output_at_fractional_times_lies_between_the_neighbouring_frames():
    blob, seq = _blob_sequence(frames=3)
    anim = reconstruct(seq, "kinematic", template_vertices=2000, times=(0.0, 0.5, 1.0, 1.5, 2.0))
    assert np.allclose(anim.times, [0, 0.5, 1, 1.5, 2])
    x = anim.vertices[..., 0].mean(axis=1)  # the blob moves along +x
    assert x[0] < x[1] < x[2] < x[3] < x[4]
    assert abs(x[1] - 0.5 * (x[0] + x[2])) < 0.25 * (x[2] - x[0])


@pytest.mark.slow
def test_an_open_sheet_stays_open():
    rng = np.random.default_rng(7)
    frames = []
    for t in range(3):
        uv = rng.uniform(-1, 1, size=(3000, 2))
        z = 0.1 * np.sin(2 * uv[:, 0] + 0.3 * t)
        frames.append(
            Frame(points=np.c_[uv, z], time=float(t), sensors=np.array([[0.0, 0.0, 5.0]]))
        )
    anim = reconstruct(PointCloudSequence(frames), "kinematic", template_vertices=1500)
    F = anim.faces
    edges = np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.sum(counts == 1) > 20  # a boundary exists: the sheet was not closed up
    extent = anim.vertices[-1].max(axis=0) - anim.vertices[-1].min(axis=0)
    assert extent[2] < 0.5 and extent[0] > 1.5 and extent[1] > 1.5


def test_options_are_validated():
    with pytest.raises(ValueError):
        K.Options(iterations=0)
    with pytest.raises(ValueError):
        K.Options(time_scale=0.0)
    with pytest.raises(InputError):
        reconstruct(PointCloudSequence([Frame(points=np.zeros((5, 3)))]), "kinematic")
    assert K.MIN_FRAMES == 2


@pytest.mark.slow
def test_output_before_and_beyond_the_input_times():
    blob, seq = _blob_sequence(frames=3)
    anim = reconstruct(seq, "kinematic", template_vertices=2000, times=(-0.5, 0.0, 1.0, 2.5))
    x = anim.vertices[..., 0].mean(axis=1)
    speed = blob.speed[0]
    assert abs((x[1] - x[0]) - 0.5 * speed) < 0.3 * speed
    assert abs((x[3] - x[2]) - 1.5 * speed) < 0.3 * speed


def _kinematic_on_crane(*, frames: int, step: int, start: int = 0, **options) -> dict:
    """``kinematic`` (with ``options``) on a stretch of the crane capture scanned with the
    standard protocol, evaluated with 10,000 samples; skips without ../shared/data."""
    from fourd import synth
    from fourd.bench import PROTOCOL
    from fourd.metrics import evaluate
    from fourd.synth.data import shared_data_dir

    if shared_data_dir() is None or not (shared_data_dir() / "crane.npz").exists():
        pytest.skip("../shared/data/crane.npz is not available")
    truth = synth.scene("crane", frames=frames, seed=0, start=start, step=step)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    anim = reconstruct(scans, method="kinematic", **options)
    return evaluate(anim, truth, samples=10000, seed=0)


@pytest.mark.slow
def test_held_out_crane_motion_is_tracked():
    """Crane frames 90-100 (every second), a stretch no default was tuned on, scanned with the
    standard protocol: a limb moves up to 15 median edges per frame. Correspondence stays
    near 1% of the diagonal (0.0101 / 0.0123 measured; 0.0205 / 0.0281 before the
    registration started from the carried motion and searched 40 edges)."""
    metrics = _kinematic_on_crane(frames=6, start=90, step=2)
    assert metrics["correspondence_mean"] < 0.015
    assert metrics["correspondence_last"] < 0.02
    assert metrics["chamfer"] < 0.006


@pytest.mark.slow
def test_a_limb_that_starts_to_move_is_registered():
    """Crane frames 140-146 (every second, standard scans): at frame 142 the rigid
    prediction leaves 2.6% of the points unexplained, up from under 1%, below the 3% of
    ``RegisterOptions.threshold``; registering there on the rise keeps the correspondence at
    0.0035 / 0.0049 (0.0044 / 0.0061 measured without: ``follow_threshold=0.03``)."""
    metrics = _kinematic_on_crane(frames=4, start=140, step=2)
    assert metrics["correspondence_mean"] < 0.004
    assert metrics["correspondence_last"] < 0.0055
    # the urshape's cells near the data meet at 34 pinched vertices: each got a copy per fan
    assert metrics["pinched_vertices_max"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("still_normals", [0.2, 0.0])
def test_a_still_crane_does_not_creep(still_normals):
    """The first crane pose scanned 10 times with the standard protocol (independent noise):
    nothing moves, so the correspondence error must not grow over the frames. With
    constraint normals from each frame's noisy surface everywhere (``still_normals=0``) the
    standing foot creeps up the leg: measured 0.0013 at frame 1, 0.0044 at frame 8 and 0.0061
    at the last; by default 0.0013, 0.0017 and 0.0020."""
    metrics = _kinematic_on_crane(frames=10, step=0, still_normals=still_normals)
    drift = metrics["per_frame"]["correspondence"]
    # the last frame lies at the end of the 4D implicit, whose one-sided fit moves it a little
    growth = drift[-2] - drift[1]
    if still_normals == 0:
        assert growth > 0.001  # the defect this guards against is still there
    else:
        assert growth < 0.0005 and drift[-1] < 0.0025, np.round(drift, 4)


def test_a_pinched_vertex_gets_a_copy_per_fan_that_moves_with_it():
    from fourd.animation import AnimatedMesh
    from fourd.geometry.fans import pinched_vertices
    from fourd.methods.kinematic.pipeline import without_pinches

    bow_tie = np.array([[0, 1, 2], [0, 3, 4]])  # two triangles touching at vertex 0
    vertices = np.random.default_rng(0).normal(size=(3, 5, 3))
    observed = np.ones((3, 5), dtype=bool)
    observed[1, 0] = False
    split = without_pinches(AnimatedMesh(bow_tie, vertices, observed=observed, rest=vertices[0]))
    assert len(pinched_vertices(split.faces)) == 0 and split.vertex_count == 6
    copy = split.faces[1, 0]
    assert copy == 5 and np.array_equal(split.vertices[:, copy], vertices[:, 0])
    assert np.array_equal(split.observed[:, copy], observed[:, 0])
    assert np.array_equal(split.rest[copy], vertices[0, 0])
    assert np.array_equal(split.vertices[:, :5], vertices)
