"""Material properties of a mesh for material-aware deformation (Popa 2009, thesis
``004_f87f5acf96d50b57.txt``, section 2.4.1).

* **Bending stiffness** ``phi_ij`` lives on the interior edges, one value per pair of faces
  sharing an edge (:func:`fourd.geometry.meshes.face_adjacency` gives their order); it decides
  how similar the transformations of two neighbouring triangles are (equation 2.1). An
  anisotropic material has three values per edge, for rotations about the x, y and z axes
  (section 2.6).
* **Shearing stiffness** ``psi_i`` lives on the faces; it decides how closely a triangle
  follows its blended transformation when the vertices are placed (equation 2.3).

Stiffnesses are positive, typically in ``[epsilon, 1]``.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency

__all__ = ["Material", "from_shearing", "load_material", "save_material", "uniform_material"]


@dataclasses.dataclass(frozen=True, eq=False)
class Material:
    """Stiffness fields of one mesh connectivity.

    Attributes
    ----------
    bending : float64 [E] or [E, 3]
        Bending stiffness per interior edge, in the order of
        :func:`fourd.geometry.meshes.face_adjacency` of the faces; ``[E, 3]`` for an
        anisotropic material (about the x, y, z axes).
    shearing : float64 [F]
        Shearing stiffness per face.
    """

    bending: np.ndarray
    shearing: np.ndarray

    def __post_init__(self):
        bending = np.asarray(self.bending, dtype=np.float64)
        shearing = np.asarray(self.shearing, dtype=np.float64)
        if bending.ndim not in (1, 2) or (bending.ndim == 2 and bending.shape[1] != 3):
            raise InputError(f"bending must be [E] or [E, 3], got {list(bending.shape)}")
        if shearing.ndim != 1:
            raise InputError(f"shearing must be [F], got {list(shearing.shape)}")
        for name, values in (("bending", bending), ("shearing", shearing)):
            if not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise InputError(f"{name} stiffness must be positive and finite")
        object.__setattr__(self, "bending", bending)
        object.__setattr__(self, "shearing", shearing)

    @property
    def anisotropic(self) -> bool:
        """Whether the bending stiffness has one value per rotation axis."""
        return self.bending.ndim == 2

    def check(self, faces: np.ndarray, pairs: np.ndarray | None = None) -> None:
        """Raise :class:`~fourd.errors.InputError` unless this material fits ``faces``
        (``pairs``: their :func:`~fourd.geometry.meshes.face_adjacency`, when known)."""
        pairs = face_adjacency(faces)[0] if pairs is None else pairs
        if len(self.shearing) != len(faces) or len(self.bending) != len(pairs):
            raise InputError(
                f"the material has {len(self.shearing)} faces and {len(self.bending)} edges, "
                f"the mesh {len(faces)} faces and {len(pairs)} interior edges: another mesh?"
            )


def uniform_material(faces: np.ndarray, stiffness: float = 1.0) -> Material:
    """The same bending and shearing stiffness everywhere."""
    pairs, _ = face_adjacency(faces)
    return Material(np.full(len(pairs), float(stiffness)), np.full(len(faces), float(stiffness)))


def from_shearing(faces: np.ndarray, shearing: np.ndarray) -> Material:
    """The thesis' simplified interface (2.4.1): one field painted on the faces, the bending
    stiffness of an edge the mean of its two faces' values, ``phi_ij = (psi_i + psi_j) / 2``."""
    shearing = np.asarray(shearing, dtype=np.float64)
    pairs, _ = face_adjacency(faces)
    return Material(0.5 * (shearing[pairs[:, 0]] + shearing[pairs[:, 1]]), shearing)


def save_material(material: Material, path: str | os.PathLike) -> None:
    """Write ``bending`` and ``shearing`` to an ``.npz`` file, atomically."""
    from fourd.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, bending=material.bending, shearing=material.shearing)


def load_material(path: str | os.PathLike) -> Material:
    """Read a material written by :func:`save_material`."""
    try:
        with np.load(path) as data:
            return Material(data["bending"], data["shearing"])
    except (OSError, KeyError, ValueError) as error:
        raise InputError(f"not a material file ({error})", path) from None
