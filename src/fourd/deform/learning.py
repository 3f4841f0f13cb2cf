"""Stiffness learned from example poses (thesis ``004_f87f5acf96d50b57.txt``, section 2.7).

For each example pose ``s`` and triangle ``i`` the deformation gradient ``T_si = V~_si V_0i^-1``
(:func:`~fourd.deform.frames.deformation_gradients`) is split by the polar decomposition into a
rotation ``Q_si`` and a stretch ``S_si`` (``T = S Q``). An edge that bends in some pose separates
the rotations of its two triangles, a face that shears has a stretch away from the identity:

* ``phi~_ij = max_s |Q_si - Q_sj|_F^2``, ``phi_ij = 1 - phi~_ij / max phi~ + epsilon``;
* ``psi~_i = max_s |S_si - I|_F^2``, ``psi_i = 1 - psi~_i / max psi~ + epsilon``.

The thesis clamps "the bottom 1% of the values before scaling": the largest 1% of the
measured bending and distortion (the lowest 1% of the stiffness) are clamped to the 99th
percentile, so a few extreme triangles (a badly tracked one) do not squeeze every other
stiffness towards 1.
"""

from __future__ import annotations

import numpy as np

from fourd.deform.frames import deformation_gradients
from fourd.deform.material import Material
from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency
from fourd.geometry.rotations import best_rotations

__all__ = ["learn_material"]


def _scaled(measure: np.ndarray, epsilon: float, clamp: float) -> np.ndarray:
    top = np.percentile(measure, 100 * (1 - clamp)) if len(measure) else 0.0
    measure = np.minimum(measure, top)
    largest = float(measure.max()) if len(measure) else 0.0
    if largest <= 1e-12:  # nothing bent or sheared: uniform
        return np.ones_like(measure)
    return 1.0 - measure / largest + epsilon


def learn_material(
    rest: np.ndarray, poses: np.ndarray, faces: np.ndarray, *, epsilon: float = 0.05, clamp: float = 0.01
) -> Material:
    """A :class:`~fourd.deform.material.Material` from example poses of one mesh.

    Parameters
    ----------
    rest : float64 [N, 3]
        The reference mesh ``P_0``.
    poses : float64 [S, N, 3]
        Example poses with the same connectivity (the frames of an animated mesh).
    faces : int [F, 3]
    epsilon : float
        The smallest stiffness (0.05): the most bent edge and the most sheared face still
        resist a little.
    clamp : float
        Fraction of the largest measurements clamped before scaling (0.01).
    """
    rest = np.asarray(rest, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if poses.ndim != 3 or poses.shape[1:] != rest.shape:
        raise InputError(f"poses must be [S, {len(rest)}, 3] like the rest mesh, got {list(poses.shape)}")
    pairs, _ = face_adjacency(faces)
    bending = np.zeros(len(pairs))
    shearing = np.zeros(len(faces))
    for pose in poses:
        gradients = deformation_gradients(rest, pose, faces)
        rotations = best_rotations(np.transpose(gradients, (0, 2, 1)))  # polar factor Q of T
        stretch = gradients @ np.transpose(rotations, (0, 2, 1))  # S = T Q^T
        difference = rotations[pairs[:, 0]] - rotations[pairs[:, 1]]
        bending = np.maximum(bending, np.einsum("eij,eij->e", difference, difference))
        distortion = stretch - np.eye(3)
        shearing = np.maximum(shearing, np.einsum("fij,fij->f", distortion, distortion))
    return Material(_scaled(bending, epsilon, clamp), _scaled(shearing, epsilon, clamp))
