"""Rigid point-to-plane ICP: the rotation and translation that move a point set onto a
surface sampled by oriented points, with a trimmed and normal-checked association.

Each iteration associates every source point with its nearest target point, keeps the pairs
within the ``trim`` percentile of the distances whose normals agree within ``max_angle``,
and solves the linearised point-to-plane problem ``sum ((R p + t - q) . n_q)^2`` for a small
rotation vector and a translation (a 6x6 system), composing the exact rotation.

References
----------
Chen, Medioni: Object modelling by registration of multiple range images, IVC 10(3), 1992
(point-to-plane); Besl, McKay: A method for registration of 3-D shapes, PAMI 14(2), 1992.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

#: Sources of at least this many points query the target's k-d tree in parallel.
PARALLEL_QUERIES = 5000


class RigidFit(NamedTuple):
    """The outcome of :func:`rigid_icp`.

    rotation : float64 [3, 3]
    translation : float64 [3]
        ``x -> rotation @ x + translation``.
    rms : float
        Root mean square point-to-plane distance of the kept pairs at the end (input units).
    iterations : int
    """

    rotation: np.ndarray
    translation: np.ndarray
    rms: float
    iterations: int


def _rotation(vector: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(vector))
    if angle < 1e-300:
        return np.eye(3)
    x, y, z = vector / angle
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def rigid_icp(
    source: np.ndarray,
    target: np.ndarray,
    target_normals: np.ndarray,
    *,
    source_normals: np.ndarray | None = None,
    iterations: int = 30,
    trim: float = 85.0,
    max_angle: float = 45.0,
    tolerance: float = 1e-7,
    rotate: bool = True,
    rotation_evidence: float = 0.0,
    max_turn: float = 180.0,
    tree: cKDTree | None = None,
) -> RigidFit:
    """Rigid motion moving ``source`` [P, 3] onto the surface of ``target`` [Q, 3] with unit
    ``target_normals`` [Q, 3] by point-to-plane ICP.

    Parameters
    ----------
    source_normals : ndarray [P, 3], optional
        With them, pairs whose (moved) normals differ by more than ``max_angle`` degrees are
        not used.
    iterations : int
    trim : float
        Percentile of the pair distances beyond which pairs are not used (100: all).
    tolerance : float
        Stop when the update moves no point by more than this fraction of the source's
        extent.
    rotate : bool
        False: a translation only (the rotation stays the identity).
    rotation_evidence : float
        With a value above 0, a translation alone is fitted too and returned unless the
        rigid motion's rms is lower than the translation's by more than this fraction: a
        rotation that explains so little is not determined by the surface (the spin of a
        surface of revolution about its axis, any turn of a sphere) and was chosen by the
        noise and the deformation.
    max_turn : float
        Below 180, the translation alone is returned too when the rigid motion turns by more
        than this many degrees (between two adjacent frames of a capture such a turn is an
        ICP minimum a deformation chose: a ball squashing matches itself turned on its side).
    tree : cKDTree, optional
        The target's k-d tree, when the caller fits many sources to one target.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(3000, 3))
    >>> p = p / np.linalg.norm(p / [1.0, 0.7, 0.5], axis=1, keepdims=True)  # an ellipsoid
    >>> n = p / [1.0, 0.49, 0.25]; n /= np.linalg.norm(n, axis=1, keepdims=True)
    >>> turn = _rotation(np.array([0.0, 0.0, 0.1]))
    >>> fit = rigid_icp(p @ turn.T + [0.05, 0, 0], p, n, trim=100)
    >>> bool(np.allclose(fit.rotation @ turn, np.eye(3), atol=1e-3))
    True
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    target_normals = np.asarray(target_normals, dtype=np.float64)
    if source.ndim != 2 or source.shape[1] != 3 or len(source) < 3:
        raise ValueError(f"source must have shape [P >= 3, 3], got {list(source.shape)}")
    if target.ndim != 2 or target.shape[1] != 3 or len(target) < 3:
        raise ValueError(f"target must have shape [Q >= 3, 3], got {list(target.shape)}")
    if target_normals.shape != target.shape:
        raise ValueError("target_normals must have the target's shape")
    if not 0 < trim <= 100:
        raise ValueError(f"trim must lie in (0, 100], got {trim}")
    if not 0 <= rotation_evidence < 1:
        raise ValueError(f"rotation_evidence must lie in [0, 1), got {rotation_evidence}")
    if not 0 <= max_turn <= 180:
        raise ValueError(f"max_turn must lie in [0, 180] degrees, got {max_turn}")
    tree = cKDTree(target) if tree is None else tree
    pairs = (source, source_normals, tree, target, target_normals)
    settings = (iterations, trim, max_angle, tolerance)
    fit = _fit(*pairs, *settings, rotate=rotate)
    if not rotate:
        return fit
    if np.trace(fit.rotation) < 1 + 2 * np.cos(np.radians(max_turn)):
        return _fit(*pairs, *settings, rotate=False)
    if rotation_evidence > 0:
        shift = _fit(*pairs, *settings, rotate=False)
        if fit.rms > (1.0 - rotation_evidence) * shift.rms:
            return shift
    return fit


def _fit(source, source_normals, tree, target, target_normals, iterations, trim, max_angle,
         tolerance, *, rotate):  # fmt: skip
    """The ICP iterations of :func:`rigid_icp` (``tree``: the target's k-d tree)."""
    extent = float(np.linalg.norm(np.ptp(source, axis=0))) or 1.0
    centre = source.mean(axis=0)
    rotation, translation = np.eye(3), np.zeros(3)
    rms, done = 0.0, 0
    cosine = np.cos(np.radians(max_angle))
    # threads cost more than they save on a small source (a part of a few dozen points)
    workers = -1 if len(source) >= PARALLEL_QUERIES else 1
    for step in range(1, iterations + 1):
        done = step
        moved = source @ rotation.T + translation
        distance, nearest = tree.query(moved, workers=workers)
        keep = distance <= np.percentile(distance, trim)
        if source_normals is not None:
            turned = source_normals @ rotation.T
            keep &= np.einsum("ij,ij->i", turned, target_normals[nearest]) >= cosine
        if keep.sum() < 6:
            break
        p = moved[keep] - centre
        q = target[nearest[keep]] - centre
        n = target_normals[nearest[keep]]
        rows = np.concatenate([np.cross(p, n), n], axis=1) if rotate else n
        residual = np.einsum("ij,ij->i", q - p, n)
        rms = float(np.sqrt(np.mean(residual**2)))
        update, *_ = np.linalg.lstsq(rows, residual, rcond=None)
        if not rotate:
            update = np.concatenate([np.zeros(3), update])
        turn = _rotation(update[:3])
        # x -> turn (x - centre) + centre + shift, composed with the current motion
        rotation = turn @ rotation
        translation = turn @ (translation - centre) + centre + update[3:]
        if np.linalg.norm(update[:3]) * extent + np.linalg.norm(update[3:]) <= tolerance * extent:
            break
    return RigidFit(rotation, translation, rms, done)
