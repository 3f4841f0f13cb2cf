"""The 1D search for an anchor's rotation when the user drags a vertex (thesis
``004_f87f5acf96d50b57.txt``, section 2.5).

A dragged vertex moves in a plane, so its anchor triangle's rotation is about that plane's
normal: one angle. The angle minimises a functional of the deformed mesh; the thesis found the
stiffness-weighted change of triangle areas, ``sum_i (psi_i (A_i - A'_i))^2``, the most natural
and the most stable (2.5.1). The minimum lies near the last angle (the drag is continuous), in
``[last - 1, last + 1]`` radians, where it is found by a binary search on the derivative's sign
(forward differences, about 12 evaluations) or by the vertex of a parabola through three
samples (4 evaluations, a few degrees off) (2.5.2).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fourd.geometry.meshes import face_areas

__all__ = ["area_change", "binary_search", "parabola_search"]


def area_change(rest_areas: np.ndarray, vertices: np.ndarray, faces: np.ndarray, shearing: np.ndarray) -> float:
    """The area-preserving functional ``sum_i (psi_i (A_i - A'_i))^2``."""
    return float(np.sum((shearing * (rest_areas - face_areas(vertices, faces))) ** 2))


def binary_search(
    energy: Callable[[float], float], centre: float, *, half_width: float = 1.0,
    iterations: int = 7, step: float = 1e-3,
) -> float:
    """The angle in ``[centre - half_width, centre + half_width]`` where the forward-difference
    derivative of ``energy`` changes sign (2 evaluations per iteration).

    Examples
    --------
    >>> round(binary_search(lambda a: (a - 0.3) ** 2, 0.0, iterations=20), 3)
    0.3
    """
    low, high = centre - half_width, centre + half_width
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        if energy(middle + step) - energy(middle) > 0:
            high = middle
        else:
            low = middle
    return 0.5 * (low + high)


def parabola_search(energy: Callable[[float], float], centre: float, *, half_width: float = 1.0) -> float:
    """The vertex of the parabola through ``energy`` at ``centre`` and ``centre +- half_width``,
    clipped to that interval (3 evaluations; the caller's final solve is the fourth).

    Examples
    --------
    >>> round(parabola_search(lambda a: 2 * (a + 0.25) ** 2 + 1, 0.0), 6)
    -0.25
    """
    left, middle, right = energy(centre - half_width), energy(centre), energy(centre + half_width)
    curvature = left - 2 * middle + right
    if curvature <= 0:  # no minimum inside: the lower end
        return centre - half_width if left < right else centre + half_width
    offset = 0.5 * half_width * (left - right) / curvature
    return float(np.clip(centre + offset, centre - half_width, centre + half_width))
