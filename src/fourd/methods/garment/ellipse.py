"""Ellipses in space fitted to garment boundaries (Popa's thesis, Appendix B.1).

An ellipse is a plane (centre and unit normal) with two orthogonal unit axes in it and a
radius along each. :func:`fit_ellipses` fits one to each of many small point sets at once: the
points projected on their least-squares plane, then the direct least-squares ellipse of
Fitzgibbon, Pilu and Fisher (1999) in the numerically stable form of Halir and Flusser (1998)
(the thesis computes "the best fit ellipse" analytically with the WildMagic library; six
points instead of the five that determine a conic, against near-degenerate samples, B.1.1).
:func:`ransac_candidates` draws such samples among the boundary points near a reference
ellipse (within twice its largest radius, B.1.2), :func:`prune` keeps the candidates close to
the reference in location, orientation (30 degrees) and size, and :func:`support` counts the
boundary points on each.

Examples
--------
>>> angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
>>> ring = np.column_stack([3 * np.cos(angles), np.sin(angles), np.full(40, 2.0)])
>>> ellipse = fit_ellipse(ring)
>>> (np.round(ellipse.center, 6) + 0.0).tolist(), np.round(ellipse.radii, 6).tolist()
([0.0, 0.0, 2.0], [3.0, 1.0])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fourd.errors import InputError

__all__ = [
    "Ellipse",
    "EllipseBatch",
    "as_batch",
    "ellipse_perimeter",
    "fit_ellipse",
    "fit_ellipses",
    "point_distances",
    "prune",
    "ransac_candidates",
    "support",
]

#: Inverse of the constraint matrix ``4 a c - b^2 = 1`` restricted to ``(a, b, c)`` (Halir and
#: Flusser 1998, eq. 21).
_C1_INVERSE = np.array([[0.0, 0.0, 0.5], [0.0, -1.0, 0.0], [0.5, 0.0, 0.0]])


def ellipse_perimeter(a, b):
    """Perimeter of ellipses of radii ``a``, ``b`` (arrays or floats): Ramanujan's second
    approximation."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    h = ((a - b) / (a + b)) ** 2
    return np.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))


@dataclass(frozen=True)
class Ellipse:
    """One ellipse in space (input units).

    Attributes
    ----------
    center : float64 [3]
    normal : float64 [3]
        Unit normal of its plane.
    axes : float64 [2, 3]
        Unit directions of its major and minor axes (orthogonal, in the plane).
    radii : float64 [2]
        Major and minor radius (``radii[0] >= radii[1] > 0``).
    """

    center: np.ndarray
    normal: np.ndarray
    axes: np.ndarray
    radii: np.ndarray

    @property
    def perimeter(self) -> float:
        """Ramanujan's second approximation of the perimeter."""
        return float(ellipse_perimeter(self.radii[0], self.radii[1]))

    def points(self, count: int = 64) -> np.ndarray:
        """``count`` points along it, ``[count, 3]``."""
        t = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
        return (
            self.center
            + np.outer(self.radii[0] * np.cos(t), self.axes[0])
            + np.outer(self.radii[1] * np.sin(t), self.axes[1])
        )

    def flipped(self) -> Ellipse:
        """The same ellipse with its normal reversed (axes kept right-handed)."""
        return Ellipse(self.center, -self.normal, np.stack([self.axes[0], -self.axes[1]]), self.radii)


@dataclass(frozen=True)
class EllipseBatch:
    """Many ellipses, as :class:`Ellipse` fields with a leading axis ``[B, ...]``; ``valid``
    [B] is false where a sample gave no ellipse (a hyperbola or a degenerate conic)."""

    center: np.ndarray
    normal: np.ndarray
    axes: np.ndarray
    radii: np.ndarray
    valid: np.ndarray

    def __len__(self) -> int:
        return len(self.center)

    def __getitem__(self, i: int) -> Ellipse:
        return Ellipse(self.center[i], self.normal[i], self.axes[i], self.radii[i])

    def subset(self, keep: np.ndarray) -> EllipseBatch:
        return EllipseBatch(
            self.center[keep], self.normal[keep], self.axes[keep], self.radii[keep], self.valid[keep]
        )


def as_batch(ellipse: Ellipse) -> EllipseBatch:
    """One ellipse as a batch of one."""
    return EllipseBatch(
        ellipse.center[None], ellipse.normal[None], ellipse.axes[None], ellipse.radii[None],
        np.ones(1, dtype=bool),
    )


def fit_ellipses(samples: np.ndarray) -> EllipseBatch:
    """The least-squares ellipse of each point set ``samples [B, K, 3]`` (``K >= 5``)."""
    samples = np.asarray(samples, dtype=np.float64)
    if samples.ndim != 3 or samples.shape[2] != 3 or samples.shape[1] < 5:
        raise InputError(f"ellipse samples must be [B, K >= 5, 3], got {list(samples.shape)}")
    mean = samples.mean(axis=1)
    centred = samples - mean[:, None, :]
    _, vectors = np.linalg.eigh(centred.transpose(0, 2, 1) @ centred)
    normal = vectors[:, :, 0]
    u, v = vectors[:, :, 2], vectors[:, :, 1]
    x = np.einsum("bkj,bj->bk", centred, u)
    y = np.einsum("bkj,bj->bk", centred, v)
    scale = np.sqrt((x**2 + y**2).mean(axis=1))
    scale = np.where(scale > 0, scale, 1.0)
    x, y = x / scale[:, None], y / scale[:, None]
    conic = _direct_fit(x, y)  # [B, 6]: a x^2 + b xy + c y^2 + d x + e y + f = 0
    center2, radii, directions, valid = _conic_geometry(conic)
    center = mean + scale[:, None] * (center2[:, :1] * u + center2[:, 1:] * v)
    axes = directions[:, :, :1] * u[:, None, :] + directions[:, :, 1:] * v[:, None, :]  # [B, 2, 3]
    radii = radii * scale[:, None]
    # a right-handed frame: axes[0] x axes[1] = normal
    normal = np.cross(axes[:, 0], axes[:, 1])
    return EllipseBatch(center, normal, axes, radii, valid)


def fit_ellipse(points: np.ndarray) -> Ellipse:
    """The least-squares ellipse of ``points [P, 3]`` (at least 5); :class:`InputError` when
    they lie on no ellipse (on a line, or a hyperbola fits them better)."""
    points = np.asarray(points, dtype=np.float64)
    batch = fit_ellipses(points[None])
    if not batch.valid[0]:
        raise InputError(f"no ellipse fits these {len(points)} points")
    return batch[0]


def _direct_fit(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Halir and Flusser's ellipse-specific least-squares conic of each row of ``x, y [B, K]``:
    ``[B, 6]`` coefficients (NaN rows where no eigenvector satisfies ``4ac - b^2 > 0``)."""
    d1 = np.stack([x * x, x * y, y * y], axis=2)  # [B, K, 3]
    d2 = np.stack([x, y, np.ones_like(x)], axis=2)
    s1 = d1.transpose(0, 2, 1) @ d1
    s2 = d1.transpose(0, 2, 1) @ d2
    s3 = d2.transpose(0, 2, 1) @ d2
    s3 = s3 + 1e-12 * np.eye(3)[None]
    t = -np.linalg.solve(s3, s2.transpose(0, 2, 1))  # [B, 3, 3]
    m = _C1_INVERSE[None] @ (s1 + s2 @ t)
    values, vectors = np.linalg.eig(m)
    vectors = np.real(vectors)
    condition = 4 * vectors[:, 0, :] * vectors[:, 2, :] - vectors[:, 1, :] ** 2  # [B, 3]
    condition = np.where(np.abs(np.imag(values)) < 1e-9, condition, -np.inf)
    best = np.argmax(condition, axis=1)
    a1 = np.take_along_axis(vectors, best[:, None, None].repeat(3, axis=1), axis=2)[:, :, 0]
    ok = np.take_along_axis(condition, best[:, None], axis=1)[:, 0] > 0
    conic = np.concatenate([a1, (t @ a1[:, :, None])[:, :, 0]], axis=1)
    conic[~ok] = np.nan
    return conic


def _conic_geometry(conic: np.ndarray):
    """Centre ``[B, 2]``, radii ``[B, 2]`` (major first), unit axis directions ``[B, 2, 2]``
    and validity ``[B]`` of each conic row ``[B, 6]``."""
    a, b, c, d, e, f = conic.T
    quadratic = np.stack([np.stack([a, b / 2], -1), np.stack([b / 2, c], -1)], axis=1)  # [B, 2, 2]
    finite = np.isfinite(conic).all(axis=1)
    quadratic = np.where(finite[:, None, None], quadratic, np.eye(2)[None])
    linear = np.where(finite[:, None], np.stack([d, e], axis=1), 0.0)
    determinant = np.linalg.det(quadratic)
    safe = np.abs(determinant) > 1e-15
    quadratic_safe = np.where(safe[:, None, None], quadratic, np.eye(2)[None])
    center = np.linalg.solve(2 * quadratic_safe, -linear[:, :, None])[:, :, 0]
    at_center = 0.5 * np.einsum("bi,bi->b", linear, center) + np.where(finite, f, 0.0)
    values, directions = np.linalg.eigh(quadratic_safe)
    with np.errstate(divide="ignore", invalid="ignore"):
        squared = -at_center[:, None] / values
    valid = finite & safe & (squared > 0).all(axis=1)
    radii = np.sqrt(np.where(valid[:, None], squared, 1.0))
    axes = directions.transpose(0, 2, 1)
    # the conic's sign is arbitrary, and with it which eigenvalue belongs to the major axis
    swap = radii[:, 0] < radii[:, 1]
    radii = np.where(swap[:, None], radii[:, ::-1], radii)
    axes = np.where(swap[:, None, None], axes[:, ::-1], axes)
    return center, radii, axes, valid


def point_distances(ellipses: EllipseBatch, points: np.ndarray) -> np.ndarray:
    """Approximate distance ``[B, P]`` from every point ``[P, 3]`` to every ellipse: the
    out-of-plane offset and, in the plane, the Sampson distance (first-order distance to the
    conic ``x^2 / r1^2 + y^2 / r2^2 = 1``)."""
    offset = np.asarray(points, dtype=np.float64)[None, :, :] - ellipses.center[:, None, :]
    height = np.einsum("bpj,bj->bp", offset, ellipses.normal)
    x = np.einsum("bpj,bj->bp", offset, ellipses.axes[:, 0])
    y = np.einsum("bpj,bj->bp", offset, ellipses.axes[:, 1])
    r1, r2 = ellipses.radii[:, :1] ** 2, ellipses.radii[:, 1:] ** 2
    value = x**2 / r1 + y**2 / r2 - 1.0
    gradient = 2.0 * np.sqrt((x / r1) ** 2 + (y / r2) ** 2)
    in_plane = np.abs(value) / np.maximum(gradient, 1e-300)
    return np.sqrt(in_plane**2 + height**2)


def support(ellipses: EllipseBatch, points: np.ndarray, tolerance: float, chunk: int = 256):
    """How many of ``points [P, 3]`` lie within ``tolerance`` of each ellipse, int64 ``[B]``,
    and their mean distance ``[B]`` (inf where none)."""
    counts = np.zeros(len(ellipses), dtype=np.int64)
    mean = np.full(len(ellipses), np.inf)
    for start in range(0, len(ellipses), chunk):
        part = ellipses.subset(slice(start, start + chunk))
        distance = point_distances(part, points)
        near = distance <= tolerance
        counts[start : start + chunk] = near.sum(axis=1)
        with np.errstate(invalid="ignore"):
            mean[start : start + chunk] = np.where(
                near.any(axis=1), (distance * near).sum(axis=1) / near.sum(axis=1), np.inf
            )
    return counts, mean


def ransac_candidates(
    points: np.ndarray,
    reference: Ellipse,
    rng: np.random.Generator,
    *,
    samples: int = 2000,
    sample_size: int = 6,
    reach: float = 2.0,
) -> EllipseBatch:
    """Ellipses through random ``sample_size``-point subsets of the boundary ``points [P, 3]``
    within ``reach`` times the reference's largest radius of its centre (B.1.1, B.1.2); only
    valid ones, normals turned to the reference's side."""
    points = np.asarray(points, dtype=np.float64)
    near = points[np.linalg.norm(points - reference.center, axis=1) <= reach * reference.radii[0]]
    if len(near) < sample_size:
        return EllipseBatch(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2, 3)), np.zeros((0, 2)),
                            np.zeros(0, dtype=bool))
    if len(near) == sample_size:
        picks = np.broadcast_to(np.arange(sample_size), (1, sample_size))
    else:  # distinct points per sample
        picks = np.argpartition(rng.random((samples, len(near))), sample_size, axis=1)[:, :sample_size]
    batch = fit_ellipses(near[picks])
    batch = batch.subset(batch.valid)
    flip = np.einsum("bj,j->b", batch.normal, reference.normal) < 0
    normal = np.where(flip[:, None], -batch.normal, batch.normal)
    axes = batch.axes.copy()
    axes[flip, 1] *= -1
    return EllipseBatch(batch.center, normal, axes, batch.radii, batch.valid)


def prune(
    candidates: EllipseBatch,
    reference: Ellipse,
    *,
    max_shift: float,
    max_angle_degrees: float = 30.0,
    size_tolerance: float = 0.3,
) -> EllipseBatch:
    """The candidates close to ``reference`` (B.1.2): centre within ``max_shift`` (input units),
    plane normal within ``max_angle_degrees``, each radius and the perimeter within a factor
    ``1 +- size_tolerance`` of the reference's."""
    if not len(candidates):
        return candidates
    shift = np.linalg.norm(candidates.center - reference.center, axis=1)
    cosine = np.abs(candidates.normal @ reference.normal)
    low, high = 1.0 - size_tolerance, 1.0 + size_tolerance
    ratio = candidates.radii / reference.radii[None, :]
    perimeter_ratio = ellipse_perimeter(candidates.radii[:, 0], candidates.radii[:, 1]) / reference.perimeter
    keep = (
        (shift <= max_shift)
        & (cosine >= np.cos(np.radians(max_angle_degrees)))
        & ((ratio >= low) & (ratio <= high)).all(axis=1)
        & (perimeter_ratio >= low)
        & (perimeter_ratio <= high)
    )
    return candidates.subset(keep)
