"""Where an image has colour texture that optical flow can follow, as opposed to shading or noise.

Optical flow follows whatever changes in the image: on a printed pattern that is the material,
on smooth skin or a uniform colour it is mostly the shading, which stays with the lamps while
the surface turns under it, and the noise. White light scales the three channels alike, so the
image's chromaticity ``c_k = I_k / mean(I) - 1`` does not see it; what is left is the hue of
the material (and the noise). Per pixel, the smallest eigenvalue of the chromaticity's
structure tensor (Gaussian window) says how well the hue pins a patch down in both directions;
the noise alone has a structure tensor too, whose expectation follows from the noise level
(after Immerkær, "Fast noise variance estimation", CVIU 1996): the ratio of the two is the
texture's significance, about 1 where there is only noise.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> flat = np.clip(120 + rng.normal(0, 2, (64, 64, 3)), 0, 255).astype(np.uint8)
>>> bool(np.median(texture_significance(flat)) < 2)
True
>>> yy, xx = np.mgrid[0:64, 0:64]
>>> hue = np.stack([128 + 60 * np.sin(xx / 3.0) * np.cos(yy / 4.0), 128 + 0 * xx, 128 - 60 * np.sin(yy / 3.0)], -1)
>>> printed = np.clip(hue + rng.normal(0, 2, hue.shape), 0, 255).astype(np.uint8)
>>> bool(np.median(texture_significance(printed)) > 10)
True
"""

from __future__ import annotations

import numpy as np

from fourd.errors import InputError

__all__ = ["chromaticity", "noise_sigma", "texture_significance"]


def chromaticity(image) -> np.ndarray:
    """``I_k / mean_k(I) - 1`` of a uint8 RGB image ``[H, W, 3]``: float64 ``[H, W, 3]``
    (a grey image gives zeros). Dark pixels are damped (the mean has 2% of full scale added)."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] < 3:
        raise InputError(f"chromaticity needs an RGB image [H, W, 3], got {list(image.shape)}")
    rgb = image[:, :, :3].astype(np.float64) / 255.0
    mean = rgb.mean(axis=2, keepdims=True)
    return (rgb - mean) / (mean + 0.02)


def noise_sigma(plane: np.ndarray) -> float:
    """Standard deviation of additive white noise in a 2D array, from its response to
    Immerkær's 3 x 3 mask ``[[1, -2, 1], [-2, 4, -2], [1, -2, 1]]`` (which has standard
    deviation ``6 sigma`` on white noise and nearly none on smooth content), by the median
    absolute response (``1.4826 median / 6``) rather than Immerkær's mean, so that the edges
    of a printed pattern do not pass for noise."""
    p = np.asarray(plane, dtype=np.float64)
    if p.shape[0] < 3 or p.shape[1] < 3:
        return 0.0
    response = (
        p[:-2, :-2] - 2 * p[:-2, 1:-1] + p[:-2, 2:]
        - 2 * p[1:-1, :-2] + 4 * p[1:-1, 1:-1] - 2 * p[1:-1, 2:]
        + p[2:, :-2] - 2 * p[2:, 1:-1] + p[2:, 2:]
    )
    return float(1.4826 / 6.0 * np.median(np.abs(response)))


def texture_significance(image, *, sigma: float = 2.0) -> np.ndarray:
    """Per pixel ``[H, W]``: the smallest eigenvalue of the chromaticity's structure tensor
    (central differences, Gaussian window of ``sigma`` pixels, summed over the channels) over
    what the noise alone gives it in expectation (``sum_k noise_k^2 / 2``). About 1 (or less)
    where there is no hue texture; large on a printed pattern."""
    from fourd.appearance.flow import _cv2

    cv2 = _cv2()
    chroma = chromaticity(image)
    gx = np.zeros_like(chroma)
    gy = np.zeros_like(chroma)
    gx[:, 1:-1] = 0.5 * (chroma[:, 2:] - chroma[:, :-2])
    gy[1:-1, :] = 0.5 * (chroma[2:, :] - chroma[:-2, :])

    def window(a):
        return cv2.GaussianBlur(a, (0, 0), sigma)

    jxx = window((gx * gx).sum(axis=2))
    jyy = window((gy * gy).sum(axis=2))
    jxy = window((gx * gy).sum(axis=2))
    smallest = 0.5 * (jxx + jyy) - np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy**2)
    noise = sum(noise_sigma(chroma[:, :, k]) ** 2 for k in range(chroma.shape[2])) / 2.0
    return smallest / max(noise, 1e-12)
