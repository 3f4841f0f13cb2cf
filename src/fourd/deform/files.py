"""The deform commands' files: meshes, results, materials and the anchors file.

The anchors file (JSON) says which triangles move and how, which vertices stay and which are
dragged::

    {
      "anchors": [
        {"face": 12},                                       # identity: held as it is
        {"face": 873, "rotation": [0.0, 0.0, 0.5]},         # rotation vector, radians
        {"face": 900, "axis": [0, 1, 0], "degrees": 30, "scale": 1.2}
      ],
      "fixed": [0, 1, 2],                                   # vertices kept in place (optional)
      "drag": [{"vertex": 4051, "position": [0.1, 0.9, 0.3], "axis": [0, 0, 1]}]
    }

``anchors`` entries take a ``rotation`` vector or an ``axis`` with ``degrees``, and an optional
uniform ``scale`` (1). ``drag`` entries move a vertex to ``position``; their anchor triangle's
rotation is searched about ``axis`` (optional; default: the normal of the plane through the
fixed vertices, the vertex and its new position). Face and vertex indices are 0-based, in the
mesh's own order.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from fourd.errors import InputError

__all__ = ["AnchorSpec", "read_anchors", "read_mesh", "read_poses", "write_mesh"]


class AnchorSpec(NamedTuple):
    """An anchors file: ``faces`` int [K], ``transforms`` float64 [K, 3, 3], ``fixed`` int [M] or
    None, ``handles`` int [H], ``positions`` float64 [H, 3], ``axes`` float64 [H, 3] or None."""

    faces: np.ndarray
    transforms: np.ndarray
    fixed: np.ndarray | None
    handles: np.ndarray
    positions: np.ndarray
    axes: np.ndarray | None


def _vector(value, what: str, path) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise InputError(f"{what} must be three numbers, got {value!r}", path)
    return array


def _transform(entry: dict, index: int, path) -> np.ndarray:
    if "rotation" in entry:
        rotation = Rotation.from_rotvec(_vector(entry["rotation"], f"anchors[{index}].rotation", path))
    elif "axis" in entry:
        axis = _vector(entry["axis"], f"anchors[{index}].axis", path)
        if np.linalg.norm(axis) == 0:
            raise InputError(f"anchors[{index}].axis is zero", path)
        rotation = Rotation.from_rotvec(np.radians(float(entry.get("degrees", 0.0))) * axis / np.linalg.norm(axis))
    else:
        rotation = Rotation.identity()
    scale = float(entry.get("scale", 1.0))
    if not scale > 0:
        raise InputError(f"anchors[{index}].scale must be positive, got {scale}", path)
    return scale * rotation.as_matrix()


def read_anchors(path: str | os.PathLike, vertex_count: int, face_count: int) -> AnchorSpec:
    """Read and check an anchors file (module docstring) for a mesh of the given size."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"cannot read the anchors file ({error})", path) from None
    except json.JSONDecodeError as error:
        raise InputError(f"not JSON ({error})", path) from None
    if not isinstance(data, dict):
        raise InputError('must be a JSON object with "anchors", "fixed" and/or "drag"', path)
    try:
        anchors = list(data.get("anchors", []))
        drags = list(data.get("drag", []))
        faces = np.array([int(entry["face"]) for entry in anchors], dtype=np.int64)
        transforms = np.array([_transform(entry, i, path) for i, entry in enumerate(anchors)]).reshape(-1, 3, 3)
        fixed = None if data.get("fixed") is None else np.array([int(v) for v in data["fixed"]], dtype=np.int64)
        handles = np.array([int(entry["vertex"]) for entry in drags], dtype=np.int64)
        positions = np.array([_vector(entry["position"], f"drag[{i}].position", path) for i, entry in enumerate(drags)]).reshape(-1, 3)
        given = [entry.get("axis") for entry in drags]
    except (KeyError, TypeError, ValueError) as error:
        if isinstance(error, InputError):
            raise
        raise InputError(f"malformed entry ({type(error).__name__}: {error})", path) from None
    if len(faces) == 0 and len(handles) == 0:
        raise InputError('no "anchors" and no "drag": nothing to deform', path)
    for name, values, limit in (("face", faces, face_count), ("vertex", handles, vertex_count),
                                ("fixed vertex", fixed if fixed is not None else np.zeros(0, int), vertex_count)):
        bad = values[(values < 0) | (values >= limit)]
        if len(bad):
            raise InputError(f"{name} index {int(bad[0])} is out of range (the mesh has {limit})", path)
    axes = None
    if any(axis is not None for axis in given):
        axes = np.array([_vector(axis, f"drag[{i}].axis", path) if axis is not None else [0.0, 0.0, 0.0]
                         for i, axis in enumerate(given)])
    return AnchorSpec(faces, transforms, fixed, handles, positions, axes)


def read_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices [N, 3], faces [F, 3])`` of a mesh file (``.obj``, ``.ply``) or of a fourd
    result (its rest shape, else its first frame)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".obj":
        from fourd.io.meshfiles import read_obj

        mesh = read_obj(path)
        vertices, faces = mesh.vertices, mesh.faces
    elif suffix == ".ply":
        from fourd.io.ply import read_ply

        mesh = read_ply(path)
        vertices, faces = mesh.vertices, mesh.faces
    else:
        from fourd.animation import AnimatedMesh
        from fourd.io.results import load_result

        result = load_result(path)
        if not isinstance(result, AnimatedMesh):
            raise InputError("holds per-frame meshes without one connectivity: nothing to deform", path)
        vertices = result.rest if result.rest is not None else result.vertices[0]
        faces = result.faces
    if len(faces) == 0:
        raise InputError("has no triangles", path)
    return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)


def read_poses(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rest [N, 3], poses [T, N, 3], faces [F, 3])`` of an animated-mesh result: the rest shape
    (its ``rest``, else frame 0) and every frame as an example pose."""
    from fourd.animation import AnimatedMesh
    from fourd.io.results import load_result

    result = load_result(path)
    if not isinstance(result, AnimatedMesh) or len(result.faces) == 0:
        raise InputError("is not an animated mesh with one connectivity: no poses to learn from", path)
    rest = result.rest if result.rest is not None else result.vertices[0]
    return np.asarray(rest, float), np.asarray(result.vertices, float), np.asarray(result.faces, np.int64)


def write_mesh(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Write a posed mesh as ``.obj`` or ``.ply`` (by extension), atomically."""
    suffix = Path(path).suffix.lower()
    if suffix == ".obj":
        from fourd.io.meshfiles import write_obj

        write_obj(path, vertices, faces)
    elif suffix == ".ply":
        from fourd.io.ply import write_ply

        write_ply(path, vertices, faces=faces)
    else:
        raise InputError("the posed mesh is written as .obj or .ply", path)
