import numpy as np
import pytest

from fourd.errors import InputError
from fourd.synth import data
from fourd.synth.data import load_shared, shared_data_dir

needs_data = pytest.mark.skipif(
    shared_data_dir() is None, reason="shared data folder ../shared/data not found"
)


def test_environment_variable_wins(tmp_path, monkeypatch):
    monkeypatch.setenv("FOURD_DATA", str(tmp_path))
    assert shared_data_dir() == tmp_path.resolve()


def test_missing_file_raises_input_error_naming_it(tmp_path, monkeypatch):
    monkeypatch.setenv("FOURD_DATA", str(tmp_path))
    with pytest.raises(InputError, match="horse-gallop.npz"):
        load_shared("horse-gallop")


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(InputError, match="crane"):
        load_shared("giraffe")


def test_reads_a_mesh_file_from_the_environment_folder(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    vertices = rng.normal(size=(3, 4, 3)).astype(np.float32)
    np.savez(
        tmp_path / "crane.npz", vertices=vertices, faces=np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    )
    monkeypatch.setenv("FOURD_DATA", str(tmp_path))
    anim = load_shared("crane")
    assert anim.vertices.dtype == np.float64
    np.testing.assert_array_equal(anim.vertices, vertices.astype(np.float64))
    np.testing.assert_array_equal(anim.times, [0.0, 1.0, 2.0])


def test_point_sequence_is_unnormalised(tmp_path, monkeypatch):
    points = np.array([[[0.0, 0.5, -0.5], [1.0, 1.0, 1.0]]] * 2, dtype=np.float16)
    np.savez(
        tmp_path / "dfaust-hopping.npz",
        points=points,
        loc=np.array([1, 2, 3], np.float16),
        scale=np.float64(2.0),
        frames=np.array([5, 6]),
    )
    monkeypatch.setenv("FOURD_DATA", str(tmp_path))
    anim = load_shared("dfaust-hopping")
    assert anim.faces.shape == (0, 3)
    np.testing.assert_allclose(anim.vertices[0], [[1.0, 3.0, 2.0], [3.0, 4.0, 5.0]])


@needs_data
def test_real_files_load_with_their_documented_shapes():
    crane = load_shared("crane")
    assert crane.vertices.shape == (175, 10002, 3) and crane.faces.shape == (20000, 3)
    hopping = load_shared("dfaust-hopping")
    assert hopping.vertices.shape == (17, 100000, 3) and len(hopping.faces) == 0
    height = np.ptp(hopping.vertices[0][:, 1])
    assert 1.4 < height < 2.1  # metres: a person, not the normalised unit height


def test_repository_root_is_found():
    root = data._repository_root()
    assert root is not None and (root / "pyproject.toml").is_file()
