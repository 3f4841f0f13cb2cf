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


def diffuse_studio() -> Lamps:
    """The lighting of a garment-capture studio (Popa's thesis, 4.3.1): a uniform diffuse sky
    and no lamps, so brightness says how deep a point lies, not which way it faces."""
    return Lamps(directions=np.array([[0.0, 1.0, 0.0]]), intensities=np.array([0.0]), ambient=0.1, diffuse=0.8)


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
    diffuse : float
        Share of full white from a uniform diffuse sky (the studio of Popa's garment capture,
        thesis 4.3.1): a surface gets ``diffuse`` times its :func:`accessibility`, which
        depends on the surface around it, not on its normal alone (0: none).
    """

    directions: np.ndarray = field(default_factory=_studio_directions)
    intensities: np.ndarray = field(default_factory=lambda: np.array([0.55, 0.3, 0.12]))
    ambient: float = 0.25
    diffuse: float = 0.0

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
        if not self.diffuse >= 0:
            raise InputError(f"diffuse must be >= 0, got {self.diffuse!r}")
        object.__setattr__(self, "directions", directions / norms)
        object.__setattr__(self, "intensities", intensities)


def shading(normals, lamps: Lamps | None = None, *, sky=None) -> np.ndarray:
    """Lambertian shading of surface points with unit ``normals [P, 3]``; float64 ``[P]``.
    ``sky`` [P]: the points' :func:`accessibility` (the diffuse light's share; 1 without)."""
    lamps = Lamps() if lamps is None else lamps
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    lit = lamps.ambient + np.clip(normals @ lamps.directions.T, 0.0, None) @ lamps.intensities
    if lamps.diffuse:
        lit = lit + lamps.diffuse * (np.ones(len(normals)) if sky is None else np.asarray(sky, dtype=np.float64))
    return lit


def shaded_colors(albedo, normals, *, noise: float = 0.0, rng=None, lamps: Lamps | None = None, sky=None):
    """Colour a sensor records: ``albedo [P, 3] x shading(normals, sky=sky)`` plus Gaussian
    noise of standard deviation ``noise`` (fraction of full scale, drawn from ``rng``), clipped
    to [0, 1]; float64 ``[P, 3]``."""
    color = np.asarray(albedo, dtype=np.float64) * shading(normals, lamps, sky=sky)[:, None]
    if noise > 0:
        if rng is None:
            raise InputError("noise needs an rng")
        color = color + rng.normal(scale=noise, size=color.shape)
    return np.clip(color, 0.0, 1.0)


#: How far the diffuse light's horizon search reaches, fraction of the truth's diagonal.
DIFFUSE_REACH = 0.03
#: Azimuth sectors of the horizon search.
DIFFUSE_SECTORS = 8


def accessibility(vertices, faces, normals, *, reach: float, sectors: int = DIFFUSE_SECTORS) -> np.ndarray:
    """How much of a uniform diffuse sky each vertex's side along ``normals [N, 3]`` receives,
    in [0, 1] (1: an open plane), ``[N]``: horizon-based ambient occlusion. Around each vertex,
    in ``sectors`` azimuth sectors of its tangent plane, the highest elevation ``e`` of the
    surface's vertices within ``reach`` (input units) above the plane blocks the sky below it;
    a sector then receives ``cos^2 e`` of its cosine-weighted light. A valley of a fold sees a
    narrower sky than a ridge: under diffuse light valleys are dark and ridges bright (Popa's
    "dark equals deep", thesis 4.3.1)."""
    from scipy.spatial import cKDTree

    vertices = np.asarray(vertices, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    pairs = cKDTree(vertices).query_pairs(reach, output_type="ndarray")
    i = np.r_[pairs[:, 0], pairs[:, 1]]
    j = np.r_[pairs[:, 1], pairs[:, 0]]
    offset = vertices[j] - vertices[i]
    distance = np.maximum(np.linalg.norm(offset, axis=1), 1e-300)
    normal = normals[i]
    sine = np.clip(np.einsum("ij,ij->i", offset, normal) / distance, 0.0, 1.0)
    # a tangent basis per vertex for the azimuth
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(normals, helper)
    first /= np.maximum(np.linalg.norm(first, axis=1, keepdims=True), 1e-300)
    second = np.cross(normals, first)
    azimuth = np.arctan2(np.einsum("ij,ij->i", offset, second[i]), np.einsum("ij,ij->i", offset, first[i]))
    sector = np.minimum(((azimuth + np.pi) / (2 * np.pi) * sectors).astype(np.int64), sectors - 1)
    highest = np.zeros((len(vertices), sectors))
    np.maximum.at(highest, (i, sector), sine)
    return (1.0 - highest**2).mean(axis=1)
