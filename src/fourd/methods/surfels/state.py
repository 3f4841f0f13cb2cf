"""The surfel state (positions, normals, local rotations over time) and its parameterisation
for Gauss-Newton: offsets in the tangent plane for the normals (eq. 11), rotation vectors to
first order for the rotations (eq. 12), re-normalised and re-orthonormalised after a step.

The unknowns of one step are one vector laid out as (:class:`Layout`): the positions
``[T, S, 3]``, then the normal offsets ``(u, v)`` ``[T, S, 2]``, then the rotation vectors
``c`` ``[T - 1, S, 3]`` (``A_i^(t)`` maps frame ``t`` to ``t + 1`` around surfel ``i``).

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.1 "Numerical optimization" (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fourd.geometry.rotations import best_rotations


@dataclass(frozen=True)
class SurfelState:
    """Surfel trajectories: ``T`` frames of the same ``S`` surfels (index = correspondence).

    positions : float64 [T, S, 3]
    normals : float64 [T, S, 3]
        Unit after :func:`retract`; :func:`move` (the model's first-order parameterisation)
        lets them grow.
    rotations : float64 [T - 1, S, 3, 3]
        ``A_i^(t)``, the local rotation from frame ``t`` to ``t + 1`` of eq. (9); orthonormal
        after :func:`retract`.
    """

    positions: np.ndarray
    normals: np.ndarray
    rotations: np.ndarray

    def __post_init__(self):
        p, n, r = self.positions, self.normals, self.rotations
        if p.ndim != 3 or p.shape[2] != 3 or p.shape[0] < 1:
            raise ValueError(f"positions must have shape [T >= 1, S, 3], got {list(p.shape)}")
        if n.shape != p.shape:
            raise ValueError(
                f"normals must have the positions' shape {list(p.shape)}, got {list(n.shape)}"
            )
        frames, count = p.shape[:2]
        if r.shape != (frames - 1, count, 3, 3):
            raise ValueError(
                f"rotations must have shape {[frames - 1, count, 3, 3]}, got {list(r.shape)}"
            )

    @property
    def frames(self) -> int:
        return self.positions.shape[0]

    @property
    def count(self) -> int:
        return self.positions.shape[1]


def surfel_state(
    positions: np.ndarray, normals: np.ndarray, rotations: np.ndarray | None = None
) -> SurfelState:
    """A :class:`SurfelState` from positions [T, S, 3] (or [S, 3] for one frame) and normals of
    the same shape (normalised here); rotations default to the identity."""
    positions = np.asarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if positions.ndim == 2:
        positions, normals = positions[None], normals[None]
    normals = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-300)
    if rotations is None:
        rotations = np.broadcast_to(np.eye(3), (len(positions) - 1, positions.shape[1], 3, 3))
    return SurfelState(positions.copy(), normals, np.array(rotations, dtype=np.float64))


@dataclass(frozen=True)
class Layout:
    """Where each unknown of a :class:`SurfelState` sits in the step vector."""

    frames: int
    count: int

    @property
    def normals_start(self) -> int:
        return self.frames * self.count * 3

    @property
    def rotations_start(self) -> int:
        return self.normals_start + self.frames * self.count * 2

    @property
    def size(self) -> int:
        return self.rotations_start + max(self.frames - 1, 0) * self.count * 3

    def position(self, frame, surfel):
        """First column of the position of ``surfel`` in ``frame`` (arrays broadcast)."""
        return (np.asarray(frame) * self.count + surfel) * 3

    def normal(self, frame, surfel):
        """First column of the normal offset ``(u, v)``."""
        return self.normals_start + (np.asarray(frame) * self.count + surfel) * 2

    def rotation(self, frame, surfel):
        """First column of the rotation vector of ``A_surfel^(frame)``."""
        return self.rotations_start + (np.asarray(frame) * self.count + surfel) * 3

    def split(self, step: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``step`` [size] as (positions [T, S, 3], offsets [T, S, 2], rotations [T-1, S, 3])."""
        step = np.asarray(step, dtype=np.float64)
        if step.shape != (self.size,):
            raise ValueError(f"step must have shape [{self.size}], got {list(step.shape)}")
        t, s = self.frames, self.count
        return (
            step[: self.normals_start].reshape(t, s, 3),
            step[self.normals_start : self.rotations_start].reshape(t, s, 2),
            step[self.rotations_start :].reshape(max(t - 1, 0), s, 3),
        )


def layout(state: SurfelState) -> Layout:
    """The :class:`Layout` of ``state``'s unknowns."""
    return Layout(state.frames, state.count)


def moving_frames(lay: Layout, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which frames have a position or normal offset among the unknowns ``columns`` (int [k]
    of ``lay``), bool [T], and which steps a rotation vector, bool [T - 1]."""
    free = np.zeros(lay.size, dtype=bool)
    free[np.asarray(columns, dtype=np.int64)] = True
    t, s = lay.frames, lay.count
    frames = free[: lay.normals_start].reshape(t, s * 3).any(axis=1)
    frames |= free[lay.normals_start : lay.rotations_start].reshape(t, s * 2).any(axis=1)
    steps = free[lay.rotations_start :].reshape(max(t - 1, 0), s * 3).any(axis=1)
    return frames, steps


def tangent_basis(normals: np.ndarray) -> np.ndarray:
    """Orthonormal tangent vectors ``(t_u, t_v)`` of eq. (11) as the columns of [..., 3, 2],
    a smooth function of the normal direction [..., 3] away from the x axis."""
    n = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-300)
    helper = np.zeros_like(n)
    along_x = np.abs(n[..., 0]) > 0.9
    helper[..., 0] = ~along_x
    helper[..., 1] = along_x
    u = np.cross(n, helper)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    return np.stack([u, np.cross(n, u)], axis=-1)


def at_surfels(values: np.ndarray, surfels: np.ndarray) -> np.ndarray:
    """``values[:, surfels]`` for per-frame arrays ``[T, S, ...]`` -> ``[T, len(surfels), ...]``,
    in C order: the fancy index ``[:, surfels]`` puts the gathered axis outermost in memory, and
    every product on the result then ran several times slower (a [14, 8,508, 3, 2] gather 1.19
    ms and a product on it 3.13 ms, against 0.28 and 0.38 ms)."""
    return np.take(values, surfels, axis=1)


def skew(vectors: np.ndarray) -> np.ndarray:
    """Cross-product matrices [..., 3, 3] of ``vectors`` [..., 3]: ``skew(c) @ y = c x y``."""
    c = np.asarray(vectors, dtype=np.float64)
    zero = np.zeros(c.shape[:-1])
    return np.stack(
        [
            np.stack([zero, -c[..., 2], c[..., 1]], axis=-1),
            np.stack([c[..., 2], zero, -c[..., 0]], axis=-1),
            np.stack([-c[..., 1], c[..., 0], zero], axis=-1),
        ],
        axis=-2,
    )


def move(state: SurfelState, step: np.ndarray) -> SurfelState:
    """``state`` moved by ``step`` [:attr:`Layout.size`] in the model's parameterisation:
    positions plus their offsets, normals ``n + u t_u + v t_v`` (eq. 11, not normalised),
    rotations ``(I + C) A`` (eq. 12, first order, not orthonormal). The energies' gradients
    are derivatives along this map at ``step = 0``."""
    positions, offsets, vectors = layout(state).split(step)
    normals = state.normals + np.einsum("tsab,tsb->tsa", tangent_basis(state.normals), offsets)
    rotations = state.rotations + skew(vectors) @ state.rotations
    return SurfelState(state.positions + positions, normals, rotations)


def retract(state: SurfelState, step: np.ndarray) -> SurfelState:
    """:func:`move`, then normals made unit and rotations the nearest orthonormal ones (the
    polar factor), so the next step has a fresh tangent basis and first-order rotation."""
    moved = move(state, step)
    normals = moved.normals / np.linalg.norm(moved.normals, axis=-1, keepdims=True)
    rotations = moved.rotations
    if rotations.size:
        # best_rotations maximises trace(R S); the polar factor of M maximises trace(R M^T)
        shape = rotations.shape
        rotations = best_rotations(np.swapaxes(rotations, -1, -2).reshape(-1, 3, 3)).reshape(shape)
    return SurfelState(moved.positions, normals, rotations)
