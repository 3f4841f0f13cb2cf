"""The shading of fixed lamps, fitted from the coloured points of a whole capture and divided out.

A studio's lamps stay where they are while the performer moves, so the light a diffuse surface
receives depends on its normal alone: recorded colour = albedo x ``S(n)`` (Lambertian light from
distant lamps; no shadows or inter-reflection). ``S`` is smooth on the sphere of directions:
Ramamoorthi and Hanrahan ("An efficient representation for irradiance environment maps",
SIGGRAPH 2001) show that spherical harmonics up to order 2 hold about 99% of its energy; the
kink of one strong lamp's clamped cosine still leaves a few per cent at order 4 (the default
here; 3.5% spread on the example below, 1.6% at order 8). A polynomial of the
normal's coordinates of degree ``d`` spans exactly the spherical harmonics up to order ``d``, so
``S`` is fitted by least squares over the points of every frame (the albedo's own variation
averages out, because it does not depend on the direction the surface faces), with points whose
brightness is far from the fit (outliers, specks of other colours) dropped and the fit repeated.

A patch of skin that turns towards a lamp brightens: to optical flow or to a photometric term
that is motion. Dividing by ``S(n)`` leaves what moves with the skin: its albedo.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> n = rng.normal(size=(20000, 3)); n /= np.linalg.norm(n, axis=1, keepdims=True)
>>> light = 0.3 + 0.7 * np.clip(n @ [0.0, 0.8, 0.6], 0, None)
>>> albedo = 0.5 + 0.02 * rng.normal(size=(len(n), 1)) * [1, 1, 1]
>>> lighting = fit_lighting([np.zeros((len(n), 3))], [n], [albedo * light[:, None]])
>>> ratio = lighting.deshade(albedo * light[:, None], n)[:, 0] / albedo[:, 0]   # one common factor
>>> bool(np.std(ratio) / np.mean(ratio) < 0.05)
True
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fourd.errors import InputError

__all__ = ["Lighting", "fit_lighting", "direction_basis"]


def direction_basis(normals: np.ndarray, degree: int) -> np.ndarray:
    """Monomials ``x^a y^b z^c`` (``a + b + c <= degree``) of unit ``normals [P, 3]``: ``[P, M]``.
    On the unit sphere they span the spherical harmonics up to order ``degree`` (with
    redundancy, since ``x^2 + y^2 + z^2 = 1``)."""
    normals = np.asarray(normals, dtype=np.float64)
    x, y, z = normals[:, 0], normals[:, 1], normals[:, 2]
    columns = [
        x**a * y**b * z ** (total - a - b)
        for total in range(degree + 1)
        for a in range(total + 1)
        for b in range(total - a + 1)
    ]
    return np.stack(columns, axis=1)


@dataclass(frozen=True, eq=False)
class Lighting:
    """Shading of fixed lamps as a function of the surface normal.

    Attributes
    ----------
    coefficients : ndarray [M]
        Of :func:`direction_basis` at ``degree``; ``S(n) = basis(n) @ coefficients`` is the
        recorded intensity (mean of R, G, B) of a surface of the capture's typical albedo.
    degree : int
    residual : float
        Median absolute deviation of the kept points' intensity from the fit, relative to it
        (what the albedo's variation and the sensor noise leave).
    floor : float
        The smallest shading divided by (a tenth of the fit's median), so that surfaces facing
        away from every lamp do not blow up.
    """

    coefficients: np.ndarray
    degree: int
    residual: float
    floor: float

    def shading(self, normals: np.ndarray) -> np.ndarray:
        """``S(n)`` for unit ``normals [P, 3]``: float64 ``[P]`` (at least :attr:`floor`)."""
        return np.maximum(direction_basis(normals, self.degree) @ self.coefficients, self.floor)

    def deshade(self, colors: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """``colors [P, 3]`` divided by the shading of their ``normals [P, 3]``: the albedo up to
        one common factor, float64 ``[P, 3]``."""
        return np.asarray(colors, dtype=np.float64) / self.shading(normals)[:, None]


def fit_lighting(
    points: Sequence[np.ndarray],
    normals: Sequence[np.ndarray],
    colors: Sequence[np.ndarray],
    *,
    degree: int = 4,
    samples: int = 60000,
    rounds: int = 3,
    seed: int = 0,
) -> Lighting:
    """Fit the shading of fixed lamps to coloured points with oriented normals.

    Parameters
    ----------
    points, normals, colors : sequences (one entry per frame) of ``[P_t, 3]`` arrays
        Colours in [0, 1]; a frame whose colours are None is skipped. ``points`` only gives the
        counts (the shading does not depend on where a point is).
    degree : int
        Polynomial degree in the normal (spherical harmonics up to this order).
    samples : int
        At most this many points, drawn evenly from every frame, enter the fit.
    rounds : int
        Fits; after each, points whose intensity is off the fit by more than 4 median absolute
        deviations are dropped.
    seed : int

    Raises
    ------
    InputError
        No frame has colours, or too few points for the fit.
    """
    rng = np.random.default_rng(seed)
    frames = [(n, c) for n, c in zip(normals, colors, strict=True) if c is not None and n is not None and len(c)]
    if not frames:
        raise InputError("the shading fit needs coloured points")
    per_frame = max(1, samples // len(frames))
    chosen_n, chosen_i = [], []
    for n, c in frames:
        pick = rng.choice(len(c), min(per_frame, len(c)), replace=False)
        chosen_n.append(np.asarray(n, dtype=np.float64)[pick])
        chosen_i.append(np.asarray(c, dtype=np.float64)[pick].mean(axis=1))
    n = np.concatenate(chosen_n)
    intensity = np.concatenate(chosen_i)
    basis = direction_basis(n, degree)
    if len(n) < 4 * basis.shape[1]:
        raise InputError(f"the shading fit needs at least {4 * basis.shape[1]} coloured points, got {len(n)}")
    keep = np.ones(len(n), dtype=bool)
    for _ in range(rounds):
        coefficients = np.linalg.lstsq(basis[keep], intensity[keep], rcond=1e-10)[0]
        fitted = basis @ coefficients
        relative = (intensity - fitted) / np.maximum(np.abs(fitted), 1e-6)
        spread = 1.4826 * np.median(np.abs(relative[keep] - np.median(relative[keep])))
        keep = np.abs(relative) <= 4.0 * max(spread, 1e-6)
    fitted = basis @ coefficients
    residual = float(np.median(np.abs(intensity[keep] - fitted[keep]) / np.maximum(np.abs(fitted[keep]), 1e-6)))
    floor = 0.1 * float(np.median(fitted[keep]))
    return Lighting(coefficients, degree, residual, max(floor, 1e-6))
