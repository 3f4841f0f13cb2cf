"""A mesh's surface low-passed at a wavelength: what is left of it without its folds.

Thin-plate smoothing: the smoothed positions ``b`` minimise ``|b - x|_M^2 + t |M^-1 L b|_M^2``,
so ``(M + t L M^-1 L) b = M x``, with the cotangent Laplacian ``L`` (negative weights clamped),
the lumped mass ``M`` and ``t = (wavelength / 2 pi)^4``. A sinusoidal bump of wavelength ``w``
keeps ``1 / (1 + (wavelength / w)^4)`` of its amplitude: a fold at half the cutoff wavelength
loses 94% of it, a shape twice as broad keeps 94%. The bi-Laplacian barely shrinks curved
shapes (a tube of radius ``r`` moves inwards by about ``t / r^3``), unlike Laplacian smoothing.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from fourd.geometry.laplacian import cotangent_laplacian, mass_matrix

__all__ = ["low_pass_surface"]


def low_pass_surface(vertices: np.ndarray, faces: np.ndarray, wavelength: float,
                     values: np.ndarray | None = None) -> np.ndarray:
    """The surface low-passed at ``wavelength`` (input units; see the module docstring):
    vertices [N, 3]. Vertices without a face stay where they are.

    With ``values`` [N, K] (a displacement, say), those are low-passed over the surface
    instead: the same filter, the surface's own geometry."""
    vertices = np.asarray(vertices, dtype=np.float64)
    signal = vertices if values is None else np.asarray(values, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    mass = mass_matrix(vertices, faces).diagonal().copy()
    used = mass > 0
    if not used.any() or not wavelength > 0:
        return signal.copy()
    mass[~used] = mass[used].min()
    laplacian = cotangent_laplacian(vertices, faces, clamp_negative=True)
    t = (wavelength / (2 * np.pi)) ** 4
    system = (sp.diags(mass) + t * (laplacian @ sp.diags(1.0 / mass) @ laplacian)).tocsc()
    return splu(system).solve(mass.reshape((-1,) + (1,) * (signal.ndim - 1)) * signal)
