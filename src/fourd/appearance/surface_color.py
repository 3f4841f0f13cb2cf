"""The colour of one frame's points as a field on its surface, sampled anywhere near it.

Each point carries its colour (optionally with the lamps' shading divided out,
:mod:`~fourd.appearance.lighting`), in log space so that a change of brightness is an offset,
smoothed over its nearest neighbours against the sensor noise, and a gradient in its tangent
plane (:func:`~fourd.appearance.colored_icp.color_gradients`, Park, Zhou and Koltun 2017, eq. 6).
A position ``q`` near the surface then reads ``C(p) + d_p . (q - p)`` from its nearest point
``p``: the "virtual image on the tangent plane" of coloured ICP, per channel.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> xy = rng.uniform(-1, 1, (5000, 2))
>>> plane = np.column_stack([xy, np.zeros(len(xy))])
>>> colors = np.repeat(0.5 + 0.3 * np.sin(3 * xy[:, :1]), 3, axis=1)
>>> field = ColorField(plane, np.tile([0.0, 0, 1], (len(plane), 1)), colors, smoothing=0)
>>> value = field.sample(np.array([[0.2, 0.1, 0.0]]))[0, 0]
>>> bool(abs(value - np.log(0.5 + 0.3 * np.sin(0.6) + LOG_OFFSET)) < 0.01)
True
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from fourd.errors import InputError

__all__ = ["ColorField", "FIELD_POINTS_PER_READ", "LOG_OFFSET", "field_for_reads"]

#: Added to colours before the logarithm, so that black does not go to minus infinity.
LOG_OFFSET = 0.02


class ColorField:
    """Log colour of a frame's points, continued linearly in each point's tangent plane.

    Parameters
    ----------
    points, normals, colors : arrays [P, 3]
        Positions, unit normals, colours in [0, 1].
    lighting : fourd.appearance.lighting.Lighting, optional
        Divide each colour by the shading of its normal first (oriented normals needed).
    smoothing, k : int
        Each point's log colour and its gradient are the least-squares plane (in the tangent
        plane) through its ``max(k, smoothing)`` nearest neighbours' log colours: the fit's value
        at the point itself, so the noise is averaged without the bias a plain mean of
        irregularly placed neighbours has.

    A point's fit is made the first time a sample lands on it (:meth:`fit`), so a field read at
    a mesh's vertices costs about what those vertices need, not what the whole frame has.
    """

    def __init__(self, points, normals, colors, *, lighting=None, smoothing: int = 8, k: int = 16):
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals, dtype=np.float64)
        colors = np.asarray(colors, dtype=np.float64)
        if colors.shape != points.shape or normals.shape != points.shape:
            raise InputError(
                f"points, normals and colors must share one shape [P, 3], got "
                f"{list(points.shape)}, {list(normals.shape)}, {list(colors.shape)}"
            )
        if len(points) < 8:
            raise InputError("a colour field needs at least 8 points")
        if lighting is not None:
            colors = lighting.deshade(colors, normals)
        self.tree = cKDTree(points)
        self.points, self.normals = points, normals
        self.log_colors = np.log(np.clip(colors, 0.0, None) + LOG_OFFSET)
        self.k = max(k, smoothing)
        channels = colors.shape[1]
        # each point's fit is made the first time a sample needs it
        self.fitted = np.zeros(len(points), dtype=bool)
        self.values = np.zeros((len(points), channels))
        self.gradients = np.zeros((len(points), channels, 3))
        self.gradient_noise = np.zeros((len(points), channels))

    def fit(self, indices: np.ndarray) -> None:
        """Make the local fits of the points ``indices`` that do not have theirs yet."""
        missing = np.unique(indices[~self.fitted[indices]])
        if len(missing):
            fits = _local_linear_fit(
                self.tree, self.points, self.normals, self.log_colors, self.k, missing
            )
            self.values[missing], self.gradients[missing], self.gradient_noise[missing] = fits
            self.fitted[missing] = True

    def sample(self, positions: np.ndarray, *, with_gradients: bool = False):
        """Log colour ``[Q, 3]`` at ``positions [Q, 3]`` (and the gradients ``[Q, 3, 3]``,
        channel by coordinate, and their noise ``[Q, 3]``, when asked)."""
        positions = np.asarray(positions, dtype=np.float64)
        flat = positions.reshape(-1, 3)
        _, nearest = self.tree.query(flat, workers=-1)
        self.fit(nearest)
        gradients = self.gradients[nearest]
        values = self.values[nearest] + (gradients @ (flat - self.points[nearest])[:, :, None])[:, :, 0]
        values = values.reshape(positions.shape[:-1] + (values.shape[-1],))
        if with_gradients:
            noise = self.gradient_noise[nearest].reshape(positions.shape[:-1] + (values.shape[-1],))
            return values, gradients.reshape(positions.shape[:-1] + gradients.shape[-2:]), noise
        return values


#: A colour field read at ``R`` places keeps about this many of its points per place (every
#: ``P // (4 R)``-th point): a few per read are enough.
FIELD_POINTS_PER_READ = 4


def field_for_reads(points: np.ndarray, normals: np.ndarray, colors: np.ndarray, reads: int) -> ColorField:
    """The :class:`ColorField` of ``points [P, 3]`` (``normals``, ``colors [P, C]``) that will be
    read at about ``reads`` places: every ``P // (FIELD_POINTS_PER_READ * reads)``-th point."""
    stride = max(1, len(points) // (FIELD_POINTS_PER_READ * max(1, int(reads))))
    return ColorField(points[::stride], normals[::stride], colors[::stride])


def _local_linear_fit(tree, points, normals, values, k, at):
    """Per point of ``at`` (indices), the least-squares ``value + gradient . (q - p)`` (gradient in the tangent
    plane) through the log colours of its ``k`` nearest neighbours (itself included):
    ``(values [P, C], gradients [P, C, 3], gradient noise [P, C])`` (Park et al. 2017, eq. 6,
    with the intercept fitted too). The gradient noise is the expected squared length of the
    part of a gradient the colour noise makes: the fit's residual variance times the trace of
    the gradient block of its inverse normal matrix. A uniform colour has gradients of about
    that length and nothing else."""
    k = min(k + 1, len(points))
    _, near = tree.query(points[at], k=k, workers=-1)
    offset = points[near] - points[at][:, None, :]
    normals = normals[at]
    offset -= (offset @ normals[:, :, None]) * normals[:, None, :]
    design = np.empty(offset.shape[:2] + (4,))  # [P, k, 4]: intercept, tangent offset
    design[:, :, 0] = 1.0
    design[:, :, 1:] = offset
    transposed = design.transpose(0, 2, 1)
    system = transposed @ design
    system[:, 1:, 1:] += normals[:, :, None] * normals[:, None, :] * k
    near_values = values[near]
    inverse = np.linalg.inv(system)
    solution = inverse @ (transposed @ near_values)  # [P, 4, C]
    residual = near_values - design @ solution
    variance = np.einsum("pkc,pkc->pc", residual, residual) / max(k - 3, 1)  # [P, C]
    spread = inverse[:, 1, 1] + inverse[:, 2, 2] + inverse[:, 3, 3]
    return solution[:, 0, :], np.transpose(solution[:, 1:, :], (0, 2, 1)), variance * spread[:, None]
