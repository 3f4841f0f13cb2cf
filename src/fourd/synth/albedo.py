"""Surface colour of the synthetic scenes: procedural albedo on the rest surface.

The albedo is a solid texture: a function of a point of the scene's rest surface (the position
the material point has in the truth's rest pose, or in its first frame when it has none), so it
moves with the skin as a printed or natural texture does. Shading is separate
(:mod:`fourd.synth.shading`).

Kinds (:data:`APPEARANCES`):

``skin``
    Low contrast and smooth: one skin tone (chosen by the seed) whose brightness varies by a few
    percent and whose redness varies a little, both sums of 12 seeded plane waves with
    wavelengths of 8 to 30 % of the rest surface's bounding-box diagonal ``D``.
``cloth``
    A high-contrast printed pattern: a patchwork of cells of ``0.07 D`` (a randomly turned
    lattice) in random colours from a seeded palette, each cell with a ball-shaped dot (a disc
    where the surface cuts it) of a contrasting palette colour.

``uniform``
    One colour everywhere (a seeded mid-tone): the shading is all there is to see, the case
    in which colour must not change what geometry alone gives.

All are deterministic functions of the point, the rest bounds and the seed, so any subset of
points can be coloured independently (per hit, per pixel) with the same result.

Examples
--------
>>> points = np.random.default_rng(0).random((5, 3))
>>> bounds = np.array([[0.0, 0, 0], [1, 1, 1]])
>>> a = albedo(points, "cloth", bounds=bounds, seed=3)
>>> a.shape, bool(((a >= 0) & (a <= 1)).all())
((5, 3), True)
>>> np.array_equal(a[2:], albedo(points[2:], "cloth", bounds=bounds, seed=3))
True
"""

from __future__ import annotations

import colorsys

import numpy as np

from fourd.errors import InputError

#: The albedo kinds.
APPEARANCES: tuple[str, ...] = ("skin", "cloth", "uniform")

#: Skin tones (linear RGB albedo in [0, 1]) the skin kind picks from.
SKIN_TONES = np.array(
    [[0.87, 0.68, 0.57], [0.78, 0.57, 0.45], [0.60, 0.42, 0.31], [0.93, 0.77, 0.67]]
)

#: Cloth: cell side as a fraction of the rest diagonal, dot radius as a fraction of the cell.
CLOTH_CELL, CLOTH_DOT = 0.07, 0.32


def check_appearance(kind) -> str | None:
    """``kind`` validated: None (no colour) or one of :data:`APPEARANCES`."""
    if kind is None or kind == "none":
        return None
    if kind not in APPEARANCES:
        raise InputError(f"unknown appearance {kind!r}; choose one of {', '.join(APPEARANCES)}")
    return kind


def albedo(points, kind: str, *, bounds, seed: int = 0) -> np.ndarray:
    """Albedo of rest-surface points.

    Parameters
    ----------
    points : array [P, 3]
        Positions on the rest surface (input units).
    kind : {"skin", "cloth", "uniform"}
    bounds : array [2, 3]
        Bounding box of the whole rest surface: sets the pattern's scale (its diagonal ``D``)
        and origin, so that all points of a scene share one pattern.
    seed : int
        Chooses the tone, the waves, the palette and the lattice.

    Returns
    -------
    ndarray float64 [P, 3]
        Linear RGB albedo in [0, 1].
    """
    kind = check_appearance(kind)
    if kind is None:
        raise InputError(f"albedo needs a kind: {', '.join(APPEARANCES)}")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or not np.isfinite(bounds).all():
        raise InputError(f"bounds must be a finite [2, 3] array, got shape {list(bounds.shape)}")
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    if diagonal <= 0:
        raise InputError("the rest surface's bounding box is a single point")
    local = (points - bounds.mean(axis=0)) / diagonal
    if kind == "skin":
        return _skin(local, seed)
    if kind == "uniform":
        tone = np.random.default_rng([seed, 13]).uniform(0.35, 0.75, size=3)
        return np.tile(tone, (len(points), 1))
    return _cloth(local, seed)


def _waves(local: np.ndarray, rng: np.random.Generator, count: int = 12) -> np.ndarray:
    """A smooth field in about [-1, 1]: ``count`` plane waves, wavelengths 0.08-0.3 D."""
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    wavelength = rng.uniform(0.08, 0.3, size=count)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=count)
    weight = rng.uniform(0.5, 1.0, size=count)
    field = np.cos(2.0 * np.pi * (local @ directions.T) / wavelength + phase) @ weight
    return field / np.sqrt(0.5 * (weight**2).sum())  # unit standard deviation


def _skin(local: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng([seed, 11])
    tone = SKIN_TONES[rng.integers(len(SKIN_TONES))]
    brightness = 1.0 + 0.05 * _waves(local, rng)
    redness = 0.03 * _waves(local, rng)
    color = tone[None] * brightness[:, None] + redness[:, None] * np.array([1.0, -0.4, -0.5])
    return np.clip(color, 0.0, 1.0)


def _mix(values: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser on uint64 (wrapping arithmetic)."""
    values = values ^ (values >> np.uint64(30))
    values = values * np.uint64(0xBF58476D1CE4E5B9)
    values = values ^ (values >> np.uint64(27))
    values = values * np.uint64(0x94D049BB133111EB)
    return values ^ (values >> np.uint64(31))


def _palette(rng: np.random.Generator, count: int = 7) -> np.ndarray:
    """``count`` colours: saturated random hues, spread over the hue circle, plus near-white
    and near-black so that neighbouring cells differ in brightness as well as hue."""
    hues = (rng.uniform() + np.arange(count - 2) / (count - 2)) % 1.0
    colors = [
        colorsys.hsv_to_rgb(h, rng.uniform(0.6, 0.95), rng.uniform(0.45, 0.95)) for h in hues
    ]
    colors += [(0.92, 0.9, 0.86), (0.08, 0.08, 0.1)]
    return np.array(colors)[rng.permutation(count)]


def _cloth(local: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng([seed, 12])
    palette = _palette(rng)
    turn, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    lattice = (local @ turn.T) / CLOTH_CELL + rng.uniform(0.0, 1.0, size=3)
    cell = np.floor(lattice)
    inside = lattice - cell
    index = cell.astype(np.int64).astype(np.uint64)  # two's complement: distinct for negatives
    key = (
        index[:, 0] * np.uint64(0x9E3779B97F4A7C15)
        ^ index[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)
        ^ index[:, 2] * np.uint64(0x165667B19E3779F9)
        ^ np.uint64(seed & 0xFFFFFFFF)
    )
    hashed = _mix(key)
    count = np.uint64(len(palette))
    base = (hashed % count).astype(np.int64)
    shift = 1 + ((hashed >> np.uint64(16)) % (count - np.uint64(1))).astype(np.int64)
    dot_color = (base + shift) % len(palette)
    centre = np.stack(
        [((hashed >> np.uint64(24 + 8 * i)) & np.uint64(255)).astype(np.float64) / 255.0 for i in range(3)],
        axis=1,
    )
    centre = 0.3 + 0.4 * centre
    in_dot = ((inside - centre) ** 2).sum(axis=1) < CLOTH_DOT**2
    return palette[np.where(in_dot, dot_color, base)]
