import numpy as np
import pytest

from fourd import AnimatedMesh, Frame, InputError, MeshSequence, PointCloudSequence


def _points(count=10, seed=0):
    return np.random.default_rng(seed).normal(size=(count, 3))


def test_frame_converts_and_validates():
    frame = Frame(points=_points().astype(np.float32), time=2)
    assert frame.points.dtype == np.float64 and frame.time == 2.0 and len(frame) == 10


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"points": np.zeros((0, 3))}, "empty"),
        ({"points": np.zeros((5, 2))}, "shape"),
        ({"points": np.array([[0, 0, np.nan]] * 3)}, "NaN"),
        ({"points": np.array([[0, 0, np.inf]] * 3)}, "NaN or infinite"),
        ({"points": _points(), "normals": np.ones((10, 3))}, "unit length"),
        ({"points": _points(), "normals": np.tile([0, 0, 1.0], (9, 1))}, "rows"),
        ({"points": _points(), "time": float("nan")}, "finite"),
        ({"points": [["a", "b", "c"]]}, "numeric"),
    ],
)
def test_frame_rejects_bad_arrays(kwargs, message):
    with pytest.raises(InputError, match=message):
        Frame(**kwargs)


def test_sequence_times_must_increase():
    frames = (Frame(_points(), time=0), Frame(_points(), time=0))
    with pytest.raises(InputError, match="increase strictly"):
        PointCloudSequence(frames, names=("a.ply", "b.ply"))


def test_sequence_from_arrays_with_fixed_sensors():
    sensors = np.array([[5.0, 0, 0], [0, 5, 0]])
    seq = PointCloudSequence.from_arrays([_points(), _points(12)], sensors=sensors)
    assert len(seq) == 2 and seq.has_sensors and np.array_equal(seq.times, [0, 1])
    assert np.array_equal(seq[1].sensors, sensors)
    assert len(seq.select(1, None)) == 1
    lo, hi = seq.bounds()
    assert np.all(lo <= hi) and seq.diagonal() > 0


def test_sequence_needs_frames():
    with pytest.raises(InputError, match="no frames"):
        PointCloudSequence(())


def test_animated_mesh_validation():
    vertices = np.zeros((2, 4, 3))
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    anim = AnimatedMesh(faces, vertices)
    assert anim.observed.shape == (2, 4) and anim.observed.all()
    assert np.array_equal(anim.times, [0, 1])
    with pytest.raises(InputError, match="index vertices"):
        AnimatedMesh(np.array([[0, 1, 4]]), vertices)
    with pytest.raises(InputError, match=r"\[T, N, 3\]"):
        AnimatedMesh(faces, np.zeros((4, 3)))
    with pytest.raises(InputError, match="observed"):
        AnimatedMesh(faces, vertices, observed=np.ones((3, 4)))
    with pytest.raises(InputError, match="increase"):
        AnimatedMesh(faces, vertices, times=[1.0, 1.0])
    point_truth = AnimatedMesh(np.zeros((0, 3)), vertices)
    assert point_truth.faces.shape == (0, 3)


def test_mesh_sequence_validation():
    v = np.eye(3)
    f = np.array([[0, 1, 2]])
    seq = MeshSequence(((v, f), (v * 2, f)))
    assert seq.frame_count == 2 and seq.diagonal() > 0
    with pytest.raises(InputError, match="mesh 1 faces"):
        MeshSequence(((v, f), (v, np.array([[0, 1, 3]]))))


def test_fourd_evaluate_stays_a_function_after_the_metrics_and_bench_packages_are_imported():
    import importlib

    import fourd

    importlib.import_module("fourd.metrics")
    importlib.import_module("fourd.bench")
    assert callable(fourd.evaluate) and fourd.evaluate.__module__ == "fourd"
