"""The topology graph ``T_S`` of the surfel trajectories and the scales it is built at: the
sampling distance ``eps_sampl`` (from the point spacing) and ``eps_top = 2 eps_sampl``.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.1 "Discretization" and 3.2 "Topological stitching" (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from fourd.geometry.grid import one_per_cube
from fourd.geometry.neighbors import point_spacing

#: ``eps_sampl`` in point spacings by default: a surfel stands for about four data points
#: (on a uniform random sample the mean distance between points is about two spacings).
SAMPLING_SPACINGS = 4.0
#: ``eps_top = TOPOLOGY_FACTOR * eps_sampl`` (the paper's c = 2).
TOPOLOGY_FACTOR = 2.0


def sampling_distance(points: np.ndarray, *, spacings: float = SAMPLING_SPACINGS) -> float:
    """``eps_sampl``: ``spacings`` times the median nearest-neighbour distance of ``points``
    [P, 3] (input units)."""
    if spacings <= 0:
        raise ValueError(f"spacings must be positive, got {spacings}")
    return float(spacings) * point_spacing(points)


def sample_surfels(points: np.ndarray, sampling: float) -> np.ndarray:
    """Indices [S] of ``points`` [P, 3] keeping one per cube of side ``sampling`` (the one
    nearest its centre): an initial surfel set about ``sampling`` apart."""
    points = np.asarray(points, dtype=np.float64)
    if sampling <= 0:
        raise ValueError(f"sampling must be positive, got {sampling}")
    scaled = (points - points.min(axis=0)) / sampling
    off_centre = np.sum((scaled - np.floor(scaled) - 0.5) ** 2, axis=1)
    return one_per_cube(scaled, 1.0, -off_centre)


@dataclass(frozen=True)
class Topology:
    """The graph ``T_S``, global over time.

    edges : int64 [E, 2]
        Undirected, ``i < j``, sorted.
    count : int
        Number of surfels ``S``.
    radius : float
        ``eps_top`` the edges were built with (input units); also the data term's truncation.
    surface : bool [E] or None
        The edges whose surfels lie within ``eps_top`` of each other along the surface
        (:func:`build_topology` with normals); the shape priors (eq. 6-8) use those only,
        the deformation priors (eq. 9, 10) every edge. None: all of them.
    """

    edges: np.ndarray
    count: int
    radius: float
    surface: np.ndarray | None = None

    def __post_init__(self):
        e = self.edges
        if e.ndim != 2 or e.shape[1] != 2:
            raise ValueError(f"edges must have shape [E, 2], got {list(e.shape)}")
        if len(e) and (e.min() < 0 or e.max() >= self.count or np.any(e[:, 0] >= e[:, 1])):
            raise ValueError(f"edges must be pairs i < j of surfels 0..{self.count - 1}")
        if self.surface is not None and self.surface.shape != (len(e),):
            raise ValueError(f"surface must be a flag per edge [{len(e)}]")

    @cached_property
    def along_surface(self) -> Topology:
        """The graph of the edges along the surface only (``surface``); built once, every
        energy evaluation asks for it."""
        if self.surface is None or self.surface.all():
            return self
        return Topology(self.edges[self.surface], self.count, self.radius)

    @property
    def directed(self) -> np.ndarray:
        """Both directions of every edge [2E, 2]: the ``(i, j in N(i))`` of the sums."""
        return np.concatenate([self.edges, self.edges[:, ::-1]])

    @property
    def degrees(self) -> np.ndarray:
        """``#N(i)`` [S]."""
        return np.bincount(self.edges.ravel(), minlength=self.count)


def build_topology(
    positions: np.ndarray,
    radius: float,
    *,
    reference: int = 0,
    max_stretch: float | None = 1.5,
    normals: np.ndarray | None = None,
) -> Topology:
    """Edges between surfels within ``radius`` (``eps_top``) of each other in frame
    ``reference``, less those whose length changes over the trajectories by more than
    ``max_stretch`` (largest over smallest length; the stitching filter of sec. 3.2).

    Parameters
    ----------
    positions : ndarray [T, S, 3] or [S, 3]
    radius : float
    reference : int
    max_stretch : float or None
        None keeps every edge of the reference frame.
    normals : ndarray [T, S, 3] or [S, 3], optional
        With normals, each edge is flagged ``surface`` when its surfels lie within ``radius``
        along the surface too, the paper's *geodesic* ``eps_top`` (sec. 3.1): when the arc
        through both that meets their normals, ``c theta / (2 sin(theta / 2))`` for chord
        ``c`` and angle ``theta`` between the normals, is at most ``radius`` long. The two
        sides of a limb thinner than ``radius`` (opposite normals: ``c pi / 2``) are joined,
        but not along the surface.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim == 2:
        positions = positions[None]
    if radius <= 0:
        raise ValueError(f"radius must be positive, got {radius}")
    count = positions.shape[1]
    pairs = cKDTree(positions[reference]).query_pairs(radius, output_type="ndarray")
    pairs = np.sort(pairs.astype(np.int64).reshape(-1, 2), axis=1)
    if max_stretch is not None and len(pairs) and len(positions) > 1:
        lengths = np.linalg.norm(positions[:, pairs[:, 0]] - positions[:, pairs[:, 1]], axis=-1)
        stretch = lengths.max(axis=0) / np.maximum(lengths.min(axis=0), 1e-300)
        pairs = pairs[stretch <= max_stretch]
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    surface = None
    if normals is not None:
        arcs = _arc_lengths(positions[reference], _frame(normals, reference), pairs)
        surface = arcs <= radius
    return Topology(pairs, count, float(radius), surface)


def _frame(normals: np.ndarray, reference: int) -> np.ndarray:
    normals = np.asarray(normals, dtype=np.float64)
    return normals[reference] if normals.ndim == 3 else normals


def _arc_lengths(positions: np.ndarray, normals: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Length [E] of the circular arc through each pair's surfels that meets their normals:
    ``c theta / (2 sin(theta / 2))``, chord ``c``, ``theta`` the angle between the normals."""
    a, b = normals[pairs[:, 0]], normals[pairs[:, 1]]
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    theta = 2.0 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
    half = 0.5 * theta
    stretch = np.ones_like(half)
    bent = half > 1e-6
    stretch[bent] = half[bent] / np.sin(half[bent])
    chords = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
    return chords * stretch
