"""Hue texture against shading and noise: where optical flow follows the material."""

import numpy as np
import pytest

from fourd.appearance.texture import chromaticity, noise_sigma, texture_significance
from fourd.errors import InputError


def _image(rng, hue_amplitude, shading_amplitude, noise=2.0, size=96):
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    shading = 1.0 + shading_amplitude * np.sin(xx / 9.0 + yy / 13.0)  # white light: all channels
    pattern = hue_amplitude * np.sin(xx / 3.0) * np.cos(yy / 4.0)
    base = np.stack([140 + pattern, 120 + 0 * xx, 110 - pattern], axis=-1)
    image = base * shading[:, :, None] + rng.normal(0, noise, base.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


def test_shading_and_noise_are_not_texture_but_a_printed_hue_is():
    rng = np.random.default_rng(0)
    shaded = texture_significance(_image(rng, 0.0, 0.4))
    printed = texture_significance(_image(rng, 40.0, 0.4))
    assert np.percentile(shaded, 90) < 3.0
    assert np.median(printed) > 5.0


def test_the_noise_estimate_ignores_the_edges_of_a_pattern():
    rng = np.random.default_rng(1)
    cells = (np.add.outer(np.arange(128) // 16, np.arange(128) // 16) % 2) * 100.0
    noisy = cells + rng.normal(0, 3.0, cells.shape)
    assert noise_sigma(noisy) == pytest.approx(3.0, rel=0.1)


def test_grey_has_no_chromaticity_and_bad_images_are_input_errors():
    grey = np.full((8, 8, 3), 90, np.uint8)
    assert np.allclose(chromaticity(grey), 0.0)
    with pytest.raises(InputError, match="RGB"):
        chromaticity(np.zeros((8, 8), np.uint8))


def test_the_texture_gate_keeps_anchors_on_print_and_drops_them_on_a_uniform_colour():
    from fourd import synth
    from fourd.appearance import anchors

    truth = synth.scene("bending-arm", frames=2)
    counts = {}
    for appearance in ("cloth", "uniform"):
        scans = synth.scan(truth, resolution=96, seed=0, appearance=appearance, video=True, video_resolution=96)
        counts[appearance] = (anchors(scans).total, anchors(scans, texture=3.0).total)
    # measured: cloth 846 -> 846, uniform 953 -> 0
    assert counts["cloth"][1] > 0.5 * counts["cloth"][0]
    assert counts["uniform"][1] <= 0.02 * counts["uniform"][0]
