import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.synth import scene as public_scene
from fourd.synth.data import shared_data_dir
from fourd.synth.scenes import CLOSED_SCENES, SCENES, SHARED_SCENES, scene, scene_options

PROCEDURAL = sorted(set(SCENES) - SHARED_SCENES)
needs_data = pytest.mark.skipif(
    shared_data_dir() is None, reason="shared data folder ../shared/data not found"
)


def _edge_lengths(vertices, faces):
    edges = trimesh.Trimesh(vertices, faces, process=False).edges_unique
    return np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)


@pytest.mark.parametrize("name", PROCEDURAL)
def test_every_procedural_scene_builds(name):
    frames = 5
    truth = scene(name, frames=frames)
    assert truth.frame_count == frames
    np.testing.assert_array_equal(truth.times, np.arange(frames))
    diagonal = truth.diagonal()
    assert 1.0 < diagonal < 4.0
    for t in range(frames):
        vertices, faces = truth.frame(t)
        assert np.isfinite(vertices).all() and len(faces) > 0
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        if name in CLOSED_SCENES:
            assert mesh.is_watertight, f"{name} frame {t} is not closed"
            assert mesh.volume > 0  # outward winding
        else:
            assert not mesh.is_watertight
    if isinstance(truth, AnimatedMesh):
        assert 2_000 <= truth.vertex_count <= 12_000
        # good-quality triangles: no slivers
        angles = trimesh.Trimesh(truth.vertices[0], truth.faces, process=False).face_angles
        assert np.degrees(angles.min()) > 15


def test_public_wrapper_delegates():
    a = public_scene("squash-ball", frames=3)
    b = scene("squash-ball", frames=3)
    np.testing.assert_array_equal(a.vertices, b.vertices)


def test_squash_ball_keeps_its_volume_and_really_deforms():
    truth = scene("squash-ball", frames=9)
    volumes = np.array(
        [trimesh.Trimesh(v, truth.faces, process=False).volume for v in truth.vertices]
    )
    assert np.ptp(volumes) <= 0.005 * volumes.mean()
    heights = np.ptp(truth.vertices[:, :, 1], axis=1)
    assert heights.max() / heights.min() > 1.8


def test_rigid_turn_is_rigid_and_turns_120_degrees():
    truth = scene("rigid-turn", frames=6)
    rng = np.random.default_rng(1)
    pick = rng.choice(truth.vertex_count, 300, replace=False)
    first = pdist(truth.vertices[0, pick])
    for t in range(1, 6):
        assert np.abs(pdist(truth.vertices[t, pick]) - first).max() < 1e-9
    a = truth.vertices[0] - truth.vertices[0].mean(axis=0)
    b = truth.vertices[-1] - truth.vertices[-1].mean(axis=0)
    u, _, vt = np.linalg.svd(b.T @ a)
    rotation = u @ vt
    angle = np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1)))
    assert abs(angle - 120.0) < 1e-6


def test_rigid_turn_is_deterministic_in_the_seed():
    a = scene("rigid-turn", frames=2, seed=3)
    b = scene("rigid-turn", frames=2, seed=3)
    c = scene("rigid-turn", frames=2, seed=4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    assert np.abs(a.vertices - c.vertices).max() > 0.01


def test_waving_sheet_is_isometric_with_a_boundary():
    truth = scene("waving-sheet", frames=5)
    rest = _edge_lengths(truth.rest, truth.faces)
    moved = False
    for vertices in truth.vertices:
        lengths = _edge_lengths(vertices, truth.faces)
        assert np.abs(lengths / rest - 1).max() < 0.01
        moved |= np.ptp(vertices[:, 2]) > 0.1
    assert moved
    mesh = trimesh.Trimesh(truth.vertices[0], truth.faces, process=False)
    assert len(mesh.outline().entities) == 1  # one boundary loop


def test_bending_arm_bends_and_stays_near_isometric():
    truth = scene("bending-arm", frames=5)
    rest = _edge_lengths(truth.vertices[0], truth.faces)
    last = _edge_lengths(truth.vertices[-1], truth.faces)
    assert np.median(np.abs(last / rest - 1)) < 0.02
    # the forearm (x > 0.5 at rest) has turned by about 90 degrees about Z
    tip = truth.vertices[0][:, 0] > 0.5
    direction = truth.vertices[-1][tip].mean(axis=0)
    assert np.degrees(np.arctan2(direction[1], direction[0])) > 70
    volumes = [trimesh.Trimesh(v, truth.faces, process=False).volume for v in truth.vertices]
    assert np.ptp(volumes) < 0.05 * np.mean(volumes)
    # no fold at the inner crease: points far apart at rest never come close together
    pairs = np.array(sorted(cKDTree(truth.vertices[-1]).query_pairs(0.03)))
    rest_distance = np.linalg.norm(truth.rest[pairs[:, 0]] - truth.rest[pairs[:, 1]], axis=1)
    assert rest_distance.max() < 0.2  # 0.54 with a folding joint (joint_width=0.25)


def test_touching_spheres_touch_in_the_middle_only():
    truth = scene("touching-spheres", frames=21)
    half = truth.vertex_count // 2
    centres = np.stack(
        [truth.vertices[:, :half].mean(axis=1), truth.vertices[:, half:].mean(axis=1)]
    )
    radius = np.linalg.norm(truth.vertices[0, :half] - centres[0, 0], axis=1).max()
    gap = np.linalg.norm(centres[1] - centres[0], axis=1) - 2 * radius
    assert gap[10] <= 0.0 < gap[0] and gap[-1] > 0.1


def test_splitting_blob_changes_topology():
    truth = scene("splitting-blob", frames=5)
    assert isinstance(truth, MeshSequence)
    parts = [
        len(trimesh.Trimesh(*truth.frame(t), process=False).split(only_watertight=False))
        for t in (0, 4)
    ]
    assert parts == [1, 2]


def test_unknown_scene_lists_the_names():
    with pytest.raises(InputError, match="rigid-turn"):
        scene("teapot")


def test_unknown_option_is_named():
    with pytest.raises(InputError, match="wobble"):
        scene("rigid-turn", wobble=3)
    assert "angle" in scene_options("rigid-turn")


def test_bad_frame_count():
    with pytest.raises(InputError):
        scene("squash-ball", frames=0)


@needs_data
def test_crane_default_is_the_benchmark_selection():
    from fourd.synth.data import load_shared

    truth = scene("crane")
    full = load_shared("crane")
    assert truth.frame_count == 20
    np.testing.assert_array_equal(truth.vertices[5], full.vertices[10])
    short = scene("crane", frames=4, step=1, start=3)
    np.testing.assert_array_equal(short.vertices[0], full.vertices[3])
    with pytest.raises(InputError, match="only"):
        scene("crane", frames=500)
    still = scene("crane", frames=3, step=0, start=7)
    assert still.frame_count == 3
    for k in range(3):
        np.testing.assert_array_equal(still.vertices[k], full.vertices[7])
    with pytest.raises(InputError, match="step"):
        scene("crane", step=-1)


@needs_data
@pytest.mark.parametrize("name", sorted(SHARED_SCENES))
def test_shared_scenes_build(name):
    truth = scene(name, frames=3)
    assert truth.frame_count == 3 and np.isfinite(truth.vertices).all()
    if name == "dfaust-hopping":
        assert len(truth.faces) == 0
    else:
        mesh = trimesh.Trimesh(truth.vertices[2], truth.faces, process=False)
        assert mesh.is_watertight == (name in CLOSED_SCENES)
