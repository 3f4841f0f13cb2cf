"""The fold detector (fourd.metrics.folds): one definition for truth and result."""

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.metrics.folds import find_folds, fold_heights, fold_recall
from fourd.synth.garments import tshirt


def _sheet(amplitude, n=61, wavelength=0.2):
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    z = amplitude * np.sin(2 * np.pi * x / wavelength) * (x > 0.2) * (x < 0.8)
    vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return vertices, faces


def test_a_folded_sheet_has_its_ridges_and_valleys_and_a_flat_one_none():
    vertices, faces = _sheet(0.02)
    folds = find_folds(vertices, faces, wavelength=0.3, depth=0.01)
    ridges = [f for f in folds if f.height > 0]
    valleys = [f for f in folds if f.height < 0]
    assert len(ridges) == 3 and len(valleys) == 3
    for fold in ridges:  # crests on the sine's maxima, x = 0.25, 0.45, 0.65
        assert np.min(np.abs(fold.crest[0] - np.array([0.25, 0.45, 0.65]))) < 0.03
    flat, _ = _sheet(0.0)
    assert find_folds(flat, faces, wavelength=0.3, depth=0.01) == []
    assert np.abs(fold_heights(flat, faces, 0.3)).max() < 1e-9


def test_a_garment_finds_all_its_own_folds_and_few_in_a_garment_without_them():
    folded = tshirt(6, 0)
    plain = tshirt(6, 0, fold_depth=0.0)
    assert fold_recall(folded, folded)["fold_recall"] == 1.0
    report = fold_recall(plain, folded)
    assert report["folds_truth"] > 20
    assert report["fold_recall"] < 0.4  # only the creases the pose makes (armpits) are in both


def test_without_truth_folds_recall_is_not_defined():
    vertices, faces = _sheet(0.0)
    flat = AnimatedMesh(faces, vertices[None])
    report = fold_recall(flat, flat)
    assert report["fold_recall"] is None and report["folds_truth"] == 0
