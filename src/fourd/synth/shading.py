"""Light of the synthetic studio: fixed lamps and Lambertian shading.

Colour seen = albedo x shading, with ``shading(n) = ambient + sum_l intensity_l max(0, n . l)``
for unit surface normal ``n`` and the unit directions ``l`` towards the lamps (directional
lamps fixed in the world, Y up). A patch that turns changes brightness; one that only moves
does not. Lambertian light does not depend on the viewer, so every camera sees a point with the
same colour.

Examples
--------
>>> up, side = np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
>>> bool(shading(up)[0] != shading(side)[0])
True
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fourd.errors import InputError


def _studio_directions() -> np.ndarray:
    directions = np.array([[0.45, 0.8, 0.4], [-0.75, 0.25, -0.35], [0.1, -0.4, -0.9]])
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


@dataclass(frozen=True, eq=False)
class Lamps:
    """Directional lamps fixed in the world.

    Attributes
    ----------
    directions : ndarray [L, 3]
        Unit directions towards the lamps (default: a key light from the upper front right, a
        fill from the left, a weak light from below behind).
    intensities : ndarray [L]
        Share of full white each lamp gives a surface facing it.
    ambient : float
        Light every surface gets.
    """

    directions: np.ndarray = field(default_factory=_studio_directions)
    intensities: np.ndarray = field(default_factory=lambda: np.array([0.55, 0.3, 0.12]))
    ambient: float = 0.25

    def __post_init__(self):
        directions = np.asarray(self.directions, dtype=np.float64).reshape(-1, 3)
        norms = np.linalg.norm(directions, axis=1, keepdims=True)
        if not np.isfinite(directions).all() or np.any(norms == 0):
            raise InputError("lamp directions must be finite nonzero vectors")
        intensities = np.asarray(self.intensities, dtype=np.float64).reshape(-1)
        if intensities.shape != (len(directions),) or np.any(intensities < 0):
            raise InputError("one intensity >= 0 per lamp")
        if not self.ambient >= 0:
            raise InputError(f"ambient must be >= 0, got {self.ambient!r}")
        object.__setattr__(self, "directions", directions / norms)
        object.__setattr__(self, "intensities", intensities)


def shading(normals, lamps: Lamps | None = None) -> np.ndarray:
    """Lambertian shading of surface points with unit ``normals [P, 3]``; float64 ``[P]``."""
    lamps = Lamps() if lamps is None else lamps
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    return lamps.ambient + np.clip(normals @ lamps.directions.T, 0.0, None) @ lamps.intensities


def shaded_colors(albedo, normals, *, noise: float = 0.0, rng=None, lamps: Lamps | None = None):
    """Colour a sensor records: ``albedo [P, 3] x shading(normals)`` plus Gaussian noise of
    standard deviation ``noise`` (fraction of full scale, drawn from ``rng``), clipped to
    [0, 1]; float64 ``[P, 3]``."""
    color = np.asarray(albedo, dtype=np.float64) * shading(normals, lamps)[:, None]
    if noise > 0:
        if rng is None:
            raise InputError("noise needs an rng")
        color = color + rng.normal(scale=noise, size=color.shape)
    return np.clip(color, 0.0, 1.0)
