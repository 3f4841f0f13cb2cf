"""Colour encodings of written vertex colours.

fourd keeps colours as the input gave them: 0-1 floats, sRGB-encoded when they came from a
scanner, a PLY or an OBJ file (8-bit colours almost always are). Formats whose colours are
linear by specification or convention (glTF's ``COLOR_0``, USD's ``displayColor``,
Alembic's ``Cd`` as Houdini and Maya read it) get them through :func:`srgb_to_linear`;
formats that store 8-bit or display colours (PLY, OBJ) keep them as they are.

References
----------
IEC 61966-2-1:1999 (sRGB), the piecewise transfer function.
"""

from __future__ import annotations

import numpy as np

__all__ = ["linear_to_srgb", "srgb_to_linear"]


def srgb_to_linear(colors: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear ones (same shape).

    Examples
    --------
    >>> srgb_to_linear(np.array([0.0, 0.5, 1.0])).round(4).tolist()
    [0.0, 0.214, 1.0]
    """
    c = np.clip(np.asarray(colors, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(colors: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] to sRGB-encoded ones, the inverse of :func:`srgb_to_linear`.

    Examples
    --------
    >>> linear_to_srgb(srgb_to_linear(np.array([0.02, 0.5, 0.9]))).round(6).tolist()
    [0.02, 0.5, 0.9]
    """
    c = np.clip(np.asarray(colors, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)
