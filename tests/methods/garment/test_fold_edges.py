"""Fold edges in video frames (thesis 4.4): a painted fold is found as a pair of edges, flat
regions and texture give none."""

import numpy as np
import pytest

from fourd.errors import InputError
from fourd.methods.garment import fold_edges, trace_edges

H, W = 200, 240


def _band(sign=1.0, angle=0.3, half_width=12.0):
    """A grey image with one fold across a flat patch: a ridge (sign 1) or a valley (-1)."""
    y, x = np.mgrid[0:H, 0:W].astype(float)
    d = (x - 120) * np.cos(angle) - (y - 100) * np.sin(angle)
    fold = sign * np.where(np.abs(d) < half_width, 0.125 * (1 + np.cos(np.pi * d / half_width)), 0.0)
    patch = (x > 40) & (x < 200) & (y > 30) & (y < 170)
    return 0.5 + fold * patch, d


def _noisy(image, seed=0):
    return np.clip(image + np.random.default_rng(seed).normal(0, 0.01, image.shape), 0, 1)


@pytest.mark.parametrize("sign, ridge", [(1.0, True), (-1.0, False)])
def test_a_painted_fold_is_one_pair_of_edges_along_it(sign, ridge):
    image, d = _band(sign)
    pairs = fold_edges(_noisy(image))
    assert len(pairs) == 1
    pair = pairs[0]
    assert pair.ridge == ridge
    assert abs(pair.distance - 12.0) < 2.5  # the brightness slopes are steepest half a fold out
    for edge in (pair.first, pair.second):
        assert edge.length > 100
        x, y = edge.points[:, 0].round().astype(int), edge.points[:, 1].round().astype(int)
        assert np.all(np.abs(np.abs(d[y, x]) - 6.0) < 2.5)


def test_flat_regions_and_texture_give_no_folds():
    image, _ = _band()
    assert fold_edges(_noisy(np.full((H, W), 0.5))) == []
    # the same pattern printed in hue at constant brightness: texture, not shape
    fold = image - 0.5
    hue_print = np.stack([0.5 + fold, 0.5 - fold, np.full_like(fold, 0.5)], axis=-1)
    assert fold_edges(_noisy(hue_print)) == []


def test_edges_are_traced_as_ordered_chains():
    mask = np.zeros((20, 30), dtype=bool)
    mask[5, 3:25] = True
    chains = trace_edges(mask)
    assert len(chains) == 1
    assert np.all(np.abs(np.diff(chains[0][:, 0])) == 1)


def test_a_rendered_garment_shows_folds_only_when_it_has_them():
    from scipy.ndimage import binary_erosion

    from fourd import synth

    truth = synth.scene("tshirt", frames=5)  # no folds in frame 0, the deepest in frame 1
    # plain fabric under diffuse light: the studio the thesis films folds in (4.3.1)
    scans = synth.scan(truth, appearance="uniform", video=True, video_resolution=256, resolution=48, lighting="diffuse")
    counts = []
    for t in (0, 1):
        image = scans.video.image(0, t)
        garment = binary_erosion(np.asarray(image)[..., :3].mean(axis=2) > 0.15 * 255, iterations=3)
        counts.append(len(fold_edges(image, mask=garment)))
    assert counts[0] <= 1 and counts[1] >= 3


def test_a_bad_frame_is_an_input_error():
    with pytest.raises(InputError):
        fold_edges(np.zeros((4, 4)))
