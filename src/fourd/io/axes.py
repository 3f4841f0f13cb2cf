"""Output conventions: the up axis of the data and a scale applied to written positions.

fourd keeps the input's axes and units through the reconstruction; only the written file
changes. ``scale`` multiplies every position of every output format (e.g. ``0.001`` turns
millimetre scans into metres, the unit glTF specifies and fourd's USD files declare).
``up`` says which axis is up in the data: ``"y"`` (the default; glTF, Alembic, USD's
default, Maya, Houdini) or ``"z"`` (Blender, 3ds Max, many scanners and robots). Formats
that fix the up axis (glTF by its specification, Alembic by convention) get Z-up data turned
Y-up by :func:`z_up_to_y_up`; USD records the axis (``upAxis``) and keeps the points as they
are; the other formats (``.npz``, ``.pc2``, folders) have no up axis and keep the data's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError

#: Up axes the writers understand.
UP_AXES = ("y", "z")

#: The rotation taking Z-up coordinates to Y-up ones: -90 degrees about X, ``(x, y, z) ->
#: (x, z, -y)`` (what Blender's glTF exporter does); a proper rotation, so triangles keep
#: their winding and normals their side.
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

__all__ = ["UP_AXES", "Z_UP_TO_Y_UP", "check_up", "scaled", "transformed", "z_up_to_y_up"]


def check_up(up: str) -> str:
    """``up`` lower-cased when it is one of :data:`UP_AXES`, else InputError."""
    value = str(up).lower()
    if value not in UP_AXES:
        raise InputError(f"the up axis must be 'y' or 'z', got {up!r}")
    return value


def z_up_to_y_up(points: np.ndarray) -> np.ndarray:
    """``points`` [..., 3] (Z up) in Y-up coordinates: ``(x, y, z) -> (x, z, -y)``.

    Examples
    --------
    >>> z_up_to_y_up(np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])).tolist()
    [[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]
    """
    return np.asarray(points, dtype=np.float64) @ Z_UP_TO_Y_UP.T


def transformed(result: AnimatedMesh | MeshSequence, matrix: np.ndarray) -> AnimatedMesh | MeshSequence:
    """``result`` with every position (and the rest pose) multiplied by ``matrix`` [3, 3],
    everything else (times, observed, UVs, colours) kept; ``result`` itself when ``matrix``
    is the identity."""
    matrix = np.asarray(matrix, dtype=np.float64)
    if np.array_equal(matrix, np.eye(3)):
        return result
    if isinstance(result, AnimatedMesh):
        rest = None if result.rest is None else result.rest @ matrix.T
        return replace(result, vertices=result.vertices @ matrix.T, rest=rest)
    return MeshSequence(tuple((v @ matrix.T, f) for v, f in result.meshes), result.times)


def scaled(result: AnimatedMesh | MeshSequence, scale: float) -> AnimatedMesh | MeshSequence:
    """``result`` with its positions multiplied by ``scale`` (a positive finite number).

    Raises
    ------
    InputError
        ``scale`` zero, negative (it would mirror the shape), or not finite.
    """
    try:
        scale = float(scale)
    except (TypeError, ValueError):
        raise InputError(f"the scale must be a number, got {scale!r}") from None
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"the scale must be a positive number, got {scale:g}")
    return transformed(result, scale * np.eye(3))
