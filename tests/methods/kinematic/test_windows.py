"""A sequence longer than one window (issue 56): ``kinematic`` fitted window by window gives the
same surfaces and correspondences, within tolerance, as one fit over the whole sequence, and
its trajectories do not jump at the windows' seams."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

import fourd
from fourd.methods import kinematic as K
from fourd.metrics import evaluate
from fourd.metrics.sampling import sample_surface


@pytest.fixture(scope="module")
def runs():
    truth = fourd.synth.scene("bending-arm", frames=9)
    scans = fourd.synth.scan(truth, resolution=96, seed=0)
    whole = K.reconstruct(scans, K.Options(template_vertices=800))
    windowed = K.reconstruct(scans, K.Options(template_vertices=800, window=3))
    return truth, whole, windowed


def test_windows_give_the_surfaces_and_correspondences_of_one_fit(runs):
    truth, whole, windowed = runs
    diagonal = truth.diagonal()
    one, many = evaluate(whole, truth, samples=10000), evaluate(windowed, truth, samples=10000)
    rng = np.random.default_rng(0)
    for t in range(truth.frame_count):
        a = sample_surface(whole.vertices[t], whole.faces, 20000, rng).points
        b = sample_surface(windowed.vertices[t], windowed.faces, 20000, rng).points
        gap = (cKDTree(a).query(b)[0].mean() + cKDTree(b).query(a)[0].mean()) / 2 / diagonal
        assert gap < one["chamfer"], (t, gap)  # apart by less than either is from the truth
    assert abs(many["chamfer"] - one["chamfer"]) < 0.1 * one["chamfer"]
    assert many["correspondence_mean"] < 1.25 * one["correspondence_mean"]
    assert many["correspondence_last"] < 1.25 * one["correspondence_last"]


def test_trajectories_do_not_jump_at_the_seams(runs):
    truth, _, windowed = runs
    v = windowed.vertices
    second = np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=2).mean(axis=1)  # frames 1 .. T-2
    seams = np.array([3, 6])  # windows of 3 frames: 0-2, 3-5, 6-8
    at_seams = np.concatenate([second[seams - 1], second[seams - 2]])  # the seam's frame and the one before
    inside = np.delete(second, np.concatenate([seams - 1, seams - 2]))
    assert at_seams.max() < 1.5 * np.median(inside)
