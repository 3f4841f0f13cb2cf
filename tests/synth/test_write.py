import json

import numpy as np
import pytest

import fourd
from fourd.errors import InputError
from fourd.synth.scanner import scan
from fourd.synth.scenes import scene
from fourd.synth.write import synthesize, write_synth


def test_folder_reads_back_as_the_scans(tmp_path):
    truth = scene("squash-ball", frames=3)
    scans = scan(truth, resolution=48, drop_frames=(1,))
    out = write_synth(truth, scans, tmp_path / "capture", info={"scene": "squash-ball"})
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        "frame_0000.ply",
        "frame_0001.ply",
        "sensors.json",
        "times.txt",
        "truth.json",
        "truth.npz",
    ]
    back = fourd.load_sequence(out)
    np.testing.assert_array_equal(back.times, [0.0, 2.0])
    for a, b in zip(back, scans, strict=True):
        np.testing.assert_allclose(a.points, b.points, atol=1e-5)  # float32 PLY
        np.testing.assert_allclose(a.sensors, b.sensors, atol=1e-5)
    with np.load(out / "truth.npz") as data:
        np.testing.assert_allclose(data["vertices"], truth.vertices, atol=1e-6)
        np.testing.assert_array_equal(data["faces"], truth.faces)
        np.testing.assert_array_equal(data["times"], truth.times)
    assert json.loads((out / "truth.json").read_text())["scene"] == "squash-ball"
    back_truth = fourd.load_result(out / "truth.npz")
    np.testing.assert_allclose(back_truth.vertices, truth.vertices, atol=1e-6)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no leftovers


def test_mesh_sequence_truth_layout(tmp_path):
    truth, scans = synthesize("splitting-blob", tmp_path / "blob", frames=2, resolution=48)
    with np.load(tmp_path / "blob" / "truth.npz") as data:
        assert str(data["kind"]) == "meshes"
        for t in range(2):
            np.testing.assert_allclose(data[f"vertices_{t}"], truth.frame(t)[0], atol=1e-6)
            np.testing.assert_array_equal(data[f"faces_{t}"], truth.frame(t)[1])
    info = json.loads((tmp_path / "blob" / "truth.json").read_text())
    assert info["kind"] == "meshes" and info["scan"]["resolution"] == 48
    assert len(fourd.load_sequence(tmp_path / "blob")) == 2


def test_wrong_inputs_write_nothing(tmp_path):
    truth = scene("squash-ball", frames=2)
    with pytest.raises(InputError):
        write_synth(truth, [1, 2], tmp_path / "x")
    with pytest.raises(InputError):
        write_synth("truth", scan(truth, resolution=32), tmp_path / "y")
    assert list(tmp_path.iterdir()) == []


def test_point_truth_is_written_without_faces(tmp_path):
    from fourd.animation import AnimatedMesh

    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    truth = AnimatedMesh(np.zeros((0, 3)), np.stack([points, 1.1 * points]))
    out = write_synth(truth, scan(truth, outliers=0.0), tmp_path / "points")
    with np.load(out / "truth.npz") as data:
        assert data["faces"].shape == (0, 3)
        np.testing.assert_allclose(data["vertices"], truth.vertices, atol=1e-6)
    assert len(fourd.load_sequence(out)) == 2
