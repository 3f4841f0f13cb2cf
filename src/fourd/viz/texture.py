"""Textures carried by correspondences, per-vertex error and ``observed`` colours.

The papers show drift by painting a texture on the first frame and carrying it to every later
frame through the correspondences: a surface that slides shows a swimming pattern, a correct
one shows checks glued to the body. Here the texture is a solid (3D) checkerboard or grid
evaluated at each vertex's *first-frame* position, so no UV unwrapping is needed: the texture
coordinate of vertex ``i`` is ``vertices[0, i]`` (scaled), the same in every frame.

A :class:`~fourd.animation.MeshSequence` has no correspondence between frames; its texture
coordinates are each frame's own positions, so its checks never swim (a "world-space"
texture), which captions must say.

References
----------
.. [1] Süßmuth, Winter, Greiner, "Reconstructing Animated Meshes from Time-Varying Point
   Clouds", SGP 2008, Fig. 1 and Sec. 6 (texture on the first frame to show correspondence).
.. [2] Sharf et al., "Space-time surface reconstruction using incompressible flow",
   SIGGRAPH Asia 2008, Sec. 7 (checkerboard textures carried by the flow).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError

log = logging.getLogger("fourd.viz.texture")

#: Texture modes understood by the renderers and the viewer.
TEXTURES = ("checker", "grid", "none")

# Fixed, irrational-ish offset of the lattice so that check boundaries do not line up with
# symmetry planes of generated test shapes (which would hide half a check row).
_LATTICE_OFFSET = np.array([0.371, 0.113, 0.257])


class TextureSpace(NamedTuple):
    """How world positions map to texture coordinates: ``(p - origin) / cell``.

    Attributes
    ----------
    origin : ndarray [3]
        World position of a lattice corner (minus a fixed fractional offset).
    cell : float
        Edge length of one check, input units.
    """

    origin: np.ndarray
    cell: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Texture coordinates ``[M, 3]`` of world ``points [M, 3]`` (one check per unit)."""
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.cell


def texture_space(bounds: np.ndarray, *, cells: float = 10.0) -> TextureSpace:
    """A lattice with ``cells`` checks along the diagonal of ``bounds [2, 3]``."""
    if not cells > 0:
        raise InputError(f"cells must be positive, got {cells}")
    bounds = np.asarray(bounds, dtype=np.float64)
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    cell = diagonal / cells if diagonal > 0 else 1.0
    return TextureSpace(bounds[0] - _LATTICE_OFFSET * cell, cell)


def carries_correspondence(result) -> bool:
    """True for an :class:`AnimatedMesh` (texture fixed on frame 0), False for a MeshSequence."""
    return isinstance(result, AnimatedMesh)


def texture_coordinates(result, index: int, *, cells: float = 10.0) -> np.ndarray:
    """Per-vertex texture coordinates ``[N_t, 3]`` of frame ``index``.

    For an :class:`AnimatedMesh` these are the *first-frame* positions of the vertices (the
    same array for every ``index``): the texture travels with the correspondences. For a
    :class:`MeshSequence` they are the frame's own positions (no correspondence exists).
    The lattice is sized on frame 0 so that ``cells`` checks span its diagonal.
    """
    first = result.frame(0)[0]
    box = np.stack([first.min(axis=0), first.max(axis=0)]) if len(first) else result.bounds()
    space = texture_space(box, cells=cells)
    if isinstance(result, AnimatedMesh):
        return space.apply(first)
    return space.apply(result.frame(index)[0])


def texture_pattern(
    coords: np.ndarray, texture: str = "checker", *, line: float = 0.08
) -> np.ndarray:
    """Pattern value in [0, 1] of texture coordinates ``coords [M, 3]``.

    ``"checker"``: 1 on even cells of the 3D lattice, 0 on odd ones. ``"grid"``: 0 on the
    lattice planes (lines ``line`` cells wide where they cut the surface), 1 elsewhere.
    ``"none"``: all ones.
    """
    coords = np.asarray(coords, dtype=np.float64)
    if texture == "checker":
        parity = np.floor(coords).astype(np.int64).sum(axis=-1) & 1
        return (1 - parity).astype(np.float64)
    if texture == "grid":
        frac = coords - np.floor(coords)
        near = np.minimum(frac, 1.0 - frac).min(axis=-1)
        return (near > line * 0.5).astype(np.float64)
    if texture == "none":
        return np.ones(coords.shape[:-1])
    raise InputError(f"unknown texture {texture!r}; choose one of {', '.join(TEXTURES)}")


def _truth_frame(truth, result_time: float, index: int, result_count: int):
    """The truth frame matching result frame ``index`` (same index when the counts agree,
    otherwise the nearest time)."""
    if truth.frame_count == result_count:
        return truth.frame(index)
    nearest = int(np.argmin(np.abs(np.asarray(truth.times) - result_time)))
    return truth.frame(nearest)


def _surface_samples(vertices: np.ndarray, faces: np.ndarray, count: int, seed: int) -> np.ndarray:
    """Vertices plus ``count`` area-uniform samples of the triangles (seeded)."""
    if len(faces) == 0 or count <= 0:
        return vertices
    rng = np.random.default_rng(seed)
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = area.sum()
    if not total > 0:
        return vertices
    pick = rng.choice(len(faces), size=count, p=area / total)
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[pick]
    samples = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    return np.concatenate([vertices, samples])


def vertex_errors(
    result, truth, *, samples_per_vertex: float = 4.0, seed: int = 0
) -> list[np.ndarray]:
    """Per frame, the distance ``[N_t]`` from each result vertex to the truth surface.

    The truth surface of the matching frame (same index when frame counts agree, else nearest
    time) is represented by its vertices plus ``samples_per_vertex`` area-uniform samples per
    result vertex, so distances are slightly over-estimated (by under a sample spacing).
    A point-sequence truth (no faces) uses its points.
    """
    if not isinstance(truth, (AnimatedMesh, MeshSequence)):
        raise InputError(
            f"truth must be an AnimatedMesh or MeshSequence, got {type(truth).__name__}"
        )
    errors = []
    for i in range(result.frame_count):
        vertices, _ = result.frame(i)
        tv, tf = _truth_frame(truth, float(result.times[i]), i, result.frame_count)
        cloud = _surface_samples(tv, tf, int(samples_per_vertex * len(vertices)), seed + i)
        errors.append(cKDTree(cloud).query(vertices)[0])
    return errors


def error_scale(errors: list[np.ndarray], *, percentile: float = 98.0) -> float:
    """One colour-map maximum for all frames: the ``percentile`` of all vertex errors."""
    flat = np.concatenate([np.ravel(e) for e in errors]) if errors else np.zeros(1)
    scale = float(np.percentile(flat, percentile)) if flat.size else 0.0
    return scale if scale > 0 else 1.0


def colormap(values: np.ndarray, vmax: float, *, name: str = "magma_r") -> np.ndarray:
    """RGB in [0, 1] ``[M, 3]`` of ``values`` mapped from ``[0, vmax]`` through a matplotlib map.

    The default ``magma_r`` runs from pale yellow (no error) through red to near black.
    """
    from matplotlib import colormaps

    t = np.clip(np.asarray(values, dtype=np.float64) / vmax, 0.0, 1.0)
    # keep the darkest end out of reach so shading stays readable
    return colormaps[name](0.02 + 0.83 * t)[..., :3]


#: Base colours (linear-ish RGB in [0, 1]).
CLAY = np.array([0.80, 0.78, 0.74])
CHECK_LIGHT = np.array([0.96, 0.93, 0.86])
CHECK_DARK = np.array([0.90, 0.45, 0.16])
FILLED_TINT = np.array([0.25, 0.55, 0.95])


def tint_unobserved(colors: np.ndarray, observed: np.ndarray, *, amount: float = 0.6) -> np.ndarray:
    """Blend the colours ``[N, 3]`` of vertices with ``observed == False`` towards blue."""
    colors = np.array(colors, dtype=np.float64, copy=True)
    filled = ~np.asarray(observed, dtype=bool)
    colors[filled] = (1 - amount) * colors[filled] + amount * FILLED_TINT
    return colors
