"""Coloured ICP: rigid registration of two coloured point sets by geometry and colour together.

The photometric alternative to video anchors when the frames carry colour but there is no
calibrated video: Park, Zhou, Koltun, "Colored Point Cloud Registration Revisited", ICCV 2017.
For each target point ``p`` (normal ``n_p``) a colour gradient ``d_p`` in its tangent plane is
fitted to its neighbours' intensities (section 3, "the virtual image on the tangent plane"), so
that ``C_p(u) = C(p) + d_p . (u - p)`` continues the colour around ``p``. A source point ``q``
moved by the current transform ``T`` to ``s = T q`` and matched with its nearest target point
``p`` contributes

- a geometric residual ``r_G = (s - p) . n_p`` (point-to-plane), and
- a photometric residual ``r_C = C_p(s) - C(q)`` (its colour against the target's colour
  continued to where it landed; ``d_p`` lies in the tangent plane, so projecting ``s`` onto it
  changes nothing),

minimised together, ``(1 - w) sum r_C^2 + w sum r_G^2`` with ``w = 0.968`` (the paper's
sigma), by Gauss-Newton steps on a rotation and translation (section 4). Colour pins down the
motions geometry cannot: a textured plane sliding within itself.

Intensities are the mean of the RGB channels in [0, 1]; lengths in input units.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> xy = rng.uniform(-1, 1, (4000, 2))
>>> plane = np.column_stack([xy, np.zeros(len(xy))])
>>> paint = lambda p: np.repeat((0.5 + 0.4 * np.sin(4 * p[:, :1]) * np.cos(3 * p[:, 1:2])), 3, axis=1)
>>> moved = plane + [0.05, -0.03, 0.0]           # a slide within the plane
>>> result = colored_icp(plane, paint(plane), moved, paint(plane))
>>> (np.round(result.transform[:3, 3], 3) + 0.0).tolist(), bool(result.converged)
([0.05, -0.03, 0.0], True)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.errors import InputError

#: The weight of the geometric term (Park et al. 2017, section 5: sigma = 0.968).
GEOMETRY_WEIGHT = 0.968


class ColoredICPResult(NamedTuple):
    """Outcome of :func:`colored_icp`.

    Attributes
    ----------
    transform : ndarray [4, 4]
        Rigid transform taking the source onto the target (``x -> R x + t``).
    fitness : float
        Share of source points with a target within ``max_distance`` at the end.
    rmse : float
        Root mean square distance of those matches (input units).
    photometric_rmse : float
        Root mean square of their colour residuals (intensity, 0-1).
    iterations : int
    converged : bool
        The last step moved points less than ``tolerance`` times the source's extent.
    history : tuple of float
        The objective after each iteration.
    """

    transform: np.ndarray
    fitness: float
    rmse: float
    photometric_rmse: float
    iterations: int
    converged: bool
    history: tuple


def _intensity(colors, count: int, name: str) -> np.ndarray:
    colors = np.asarray(colors, dtype=np.float64)
    if colors.ndim == 2 and colors.shape == (count, 3):
        return colors.mean(axis=1)
    if colors.shape == (count,):
        return colors
    raise InputError(f"{name} must have shape [{count}, 3] or [{count}], got {list(colors.shape)}")


def color_gradients(points, normals, intensity, *, k: int = 16) -> np.ndarray:
    """Intensity gradients ``[P, 3]`` in the tangent planes of ``points [P, 3]`` (unit
    ``normals [P, 3]``, ``intensity [P]``): per point the least-squares ``d`` with ``d . n = 0``
    over its ``k`` nearest neighbours projected onto the tangent plane,
    ``I(p') - I(p) ~ d . (f(p') - p)`` (Park et al. 2017, equation 6)."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    intensity = np.asarray(intensity, dtype=np.float64)
    k = min(k, len(points) - 1)
    if k < 3:
        raise InputError("colour gradients need at least four points")
    _, neighbours = cKDTree(points).query(points, k=k + 1)
    neighbours = neighbours[:, 1:]
    offset = points[neighbours] - points[:, None, :]  # [P, k, 3]
    offset -= np.einsum("pkj,pj->pk", offset, normals)[:, :, None] * normals[:, None, :]
    change = intensity[neighbours] - intensity[:, None]
    # least squares in 3D with the constraint as an extra, heavily weighted row: d . n = 0
    system = np.einsum("pki,pkj->pij", offset, offset) + np.einsum("pi,pj->pij", normals, normals)
    right = np.einsum("pki,pk->pi", offset, change)
    try:
        return np.linalg.solve(system, right[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(system.reshape(-1, 3), right.reshape(-1), rcond=None)[0]  # pragma: no cover


def _rotation(omega: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(omega))
    if angle < 1e-15:
        return np.eye(3)
    axis = omega / angle
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def colored_icp(
    source,
    source_colors,
    target,
    target_colors,
    *,
    target_normals=None,
    init=None,
    max_distance: float | None = None,
    geometry_weight: float = GEOMETRY_WEIGHT,
    iterations: int = 40,
    tolerance: float = 1e-7,
    k: int = 16,
) -> ColoredICPResult:
    """Rigidly register a coloured source point set onto a coloured target.

    Parameters
    ----------
    source, target : array [P, 3], [Q, 3]
    source_colors, target_colors : array [P, 3] / [Q, 3] (RGB in [0, 1]) or intensities [P] / [Q]
    target_normals : array [Q, 3], optional
        Unit normals of the target (default: PCA normals of 16 neighbours; their sign does not
        matter).
    init : array [4, 4], optional
        Starting transform (default identity).
    max_distance : float, optional
        Matches farther apart are ignored (default: 5 times the target's median point spacing).
    geometry_weight : float
        ``w`` in ``(1 - w) E_C + w E_G``, in (0, 1]; 1 is point-to-plane ICP.
    iterations : int
    tolerance : float
        Stop when a step moves no point more than ``tolerance`` times the source's extent.
    k : int
        Neighbours of the colour gradients.

    Returns
    -------
    ColoredICPResult

    References
    ----------
    J. Park, Q.-Y. Zhou, V. Koltun, "Colored Point Cloud Registration Revisited", ICCV 2017,
    sections 3-4.
    """
    source = np.asarray(source, dtype=np.float64).reshape(-1, 3)
    target = np.asarray(target, dtype=np.float64).reshape(-1, 3)
    if len(source) < 3 or len(target) < 4:
        raise InputError("coloured ICP needs at least 3 source and 4 target points")
    if not 0.0 < geometry_weight <= 1.0:
        raise InputError(f"geometry_weight must be in (0, 1], got {geometry_weight!r}")
    source_intensity = _intensity(source_colors, len(source), "source_colors")
    target_intensity = _intensity(target_colors, len(target), "target_colors")
    if target_normals is None:
        from fourd.geometry.normals import pca_normals

        target_normals = pca_normals(target, min(16, len(target) - 1)).normals
    target_normals = np.asarray(target_normals, dtype=np.float64).reshape(-1, 3)
    if len(target_normals) != len(target):
        raise InputError(f"target_normals has {len(target_normals)} rows for {len(target)} points")
    tree = cKDTree(target)
    if max_distance is None:
        spacing = float(np.median(tree.query(target, k=2)[0][:, 1]))
        max_distance = 5.0 * spacing
    gradients = color_gradients(target, target_normals, target_intensity, k=k)
    transform = np.eye(4) if init is None else np.array(init, dtype=np.float64)
    if transform.shape != (4, 4):
        raise InputError(f"init must be a 4 x 4 transform, got shape {list(transform.shape)}")
    extent = float(np.linalg.norm(source.max(axis=0) - source.min(axis=0))) or 1.0
    sqrt_g, sqrt_c = np.sqrt(geometry_weight), np.sqrt(1.0 - geometry_weight)
    history, converged = [], False
    for _ in range(iterations):
        moved = source @ transform[:3, :3].T + transform[:3, 3]
        distance, match = tree.query(moved, distance_upper_bound=max_distance)
        ok = np.isfinite(distance)
        if ok.sum() < 6:
            raise InputError("coloured ICP: fewer than 6 matches within max_distance")
        s, p = moved[ok], target[match[ok]]
        n, d = target_normals[match[ok]], gradients[match[ok]]
        r_g = np.einsum("ij,ij->i", s - p, n)
        r_c = target_intensity[match[ok]] + np.einsum("ij,ij->i", d, s - p) - source_intensity[ok]
        jacobian = np.concatenate(
            [sqrt_g * np.hstack([np.cross(s, n), n]), sqrt_c * np.hstack([np.cross(s, d), d])]
        )
        residual = np.concatenate([sqrt_g * r_g, sqrt_c * r_c])
        history.append(float(residual @ residual) / len(s))
        step = np.linalg.lstsq(jacobian, -residual, rcond=None)[0]
        update = np.eye(4)
        update[:3, :3] = _rotation(step[:3])
        update[:3, 3] = step[3:]
        transform = update @ transform
        if np.linalg.norm(step[:3]) * extent + np.linalg.norm(step[3:]) < tolerance * extent:
            converged = True
            break
    moved = source @ transform[:3, :3].T + transform[:3, 3]
    distance, match = tree.query(moved, distance_upper_bound=max_distance)
    ok = np.isfinite(distance)
    photometric = target_intensity[match[ok]] + np.einsum(
        "ij,ij->i", gradients[match[ok]], moved[ok] - target[match[ok]]
    ) - source_intensity[ok]
    return ColoredICPResult(
        transform,
        float(ok.mean()),
        float(np.sqrt(np.mean(distance[ok] ** 2))) if ok.any() else float("nan"),
        float(np.sqrt(np.mean(photometric**2))) if ok.any() else float("nan"),
        len(history),
        converged,
        tuple(history),
    )
