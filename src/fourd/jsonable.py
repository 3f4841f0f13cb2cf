"""Turning results, metrics and options into plain JSON values."""

from __future__ import annotations

import dataclasses
import math

import numpy as np


def jsonable(value):
    """``value`` with numpy arrays and scalars, tuples and dataclasses turned into plain JSON
    types; non-finite floats become ``None`` (JSON has no NaN). Other objects become strings."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return jsonable(dataclasses.asdict(value))
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)
