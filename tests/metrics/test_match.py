"""Whether a truth belongs to a result (fourd.metrics.match): right but noisy or partial
results pass, other scenes, units or frame counts do not."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh, InputError, MeshSequence
from fourd.metrics import check_truth, evaluate_files, truth_mismatch
from fourd.metrics.match import truth_at_times


def _truth(frames=4):
    sphere = trimesh.creation.icosphere(2)
    vertices = np.stack([sphere.vertices * (1 + 0.1 * t) + [0.2 * t, 0, 0] for t in range(frames)])
    return AnimatedMesh(sphere.faces, vertices)


def test_noisy_partial_and_per_frame_results_of_the_truth_pass():
    truth = _truth()
    rng = np.random.default_rng(0)
    noisy = AnimatedMesh(
        truth.faces, truth.vertices + rng.normal(scale=0.03, size=truth.vertices.shape)
    )
    assert truth_mismatch(noisy, truth) is None
    # one-sided scans: only the half facing the cameras, one frame with nothing at all
    halves = []
    for t in range(truth.frame_count):
        v, f = truth.frame(t)
        keep = f[(v[f][:, :, 2] > 0).all(axis=1)]
        halves.append((v, keep) if t != 2 else (np.zeros((0, 3)), np.zeros((0, 3), int)))
    assert truth_mismatch(MeshSequence(tuple(halves)), truth) is None
    # a stray component half a diagonal away still passes
    v = truth.vertices.copy()
    v[:, :5] += 0.5 * truth.diagonal()
    assert truth_mismatch(AnimatedMesh(truth.faces, v), truth) is None


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        (lambda v: v * 1000, "diagonal"),  # millimetres against metres
        (lambda v: v / 3, "diagonal"),
        (lambda v: v + [3.0, 0, 0], "centre"),  # another place
    ],
)
def test_other_units_or_places_fail(change, needle):
    truth = _truth()
    problem = truth_mismatch(AnimatedMesh(truth.faces, change(truth.vertices)), truth)
    assert problem.startswith("the result's bounding box (centre ") and needle in problem


def test_other_frame_counts_fail_and_force_matches_them_by_time(caplog):
    truth = _truth(frames=4)
    shorter = AnimatedMesh(truth.faces, truth.vertices[[1, 3]], times=[1.0, 3.0])
    assert truth_mismatch(shorter, truth) == "the result has 2 frames but the truth has 4"
    with pytest.raises(InputError) as info:
        check_truth(shorter, truth, "r.npz", "t.npz")
    assert str(info.value) == (
        "t.npz does not look like the truth of r.npz: the result has 2 frames but the truth has 4 "
        "(--force goes on anyway)"
    )
    with caplog.at_level(logging.WARNING, logger="fourd.metrics.match"):
        matched = check_truth(shorter, truth, "r.npz", "t.npz", force=True)
    assert len(caplog.records) == 2 and "--force" in caplog.records[0].getMessage()
    assert np.array_equal(matched.vertices, truth.vertices[[1, 3]])
    assert check_truth(truth, truth, "r", "t") is truth


def test_truth_at_times_keeps_the_kind():
    truth = _truth(frames=3)
    meshes = MeshSequence(tuple(truth.frame(t) for t in range(3)))
    picked = truth_at_times(meshes, [0.1, 1.9])
    assert isinstance(picked, MeshSequence) and picked.times.tolist() == [0.1, 1.9]
    assert np.array_equal(picked.meshes[1][0], truth.vertices[2])


def test_evaluate_files_refuses_unless_forced(tmp_path):
    truth = _truth(frames=3)
    np.savez(tmp_path / "truth.npz", vertices=truth.vertices, faces=truth.faces)
    np.savez(tmp_path / "mm.npz", vertices=truth.vertices * 1000, faces=truth.faces)
    with pytest.raises(InputError, match=r"truth\.npz does not look like the truth of .*mm\.npz"):
        evaluate_files(tmp_path / "mm.npz", tmp_path / "truth.npz", samples=500, floor=False)
    report = evaluate_files(
        tmp_path / "mm.npz", tmp_path / "truth.npz", samples=500, floor=False, force=True
    )
    assert report["frames"] == 3
