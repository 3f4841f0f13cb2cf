"""The interface between methods that build a space-time implicit function and methods that
use one (e.g. template sliding over a flow method's 4D function).

A 4D field is any object with these two methods; times are in the sequence's time units.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Field4D(Protocol):
    """A space-time implicit function ``f(x, t)``, negative inside, zero on the surface."""

    def value(self, points: np.ndarray, times: np.ndarray | float) -> np.ndarray:
        """``f`` at ``points`` [M, 3] and ``times`` (scalar or [M]); returns [M]."""
        ...

    def gradient(self, points: np.ndarray, times: np.ndarray | float) -> np.ndarray:
        """``(df/dx, df/dy, df/dz, df/dt)`` at ``points`` [M, 3], ``times``; returns [M, 4]."""
        ...
