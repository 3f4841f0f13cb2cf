"""A result as a folder of per-frame meshes: ``frame_0000.obj`` ... (or ``.ply``), ``times.txt``
and, for an :class:`~fourd.animation.AnimatedMesh`, ``observed.npy`` (bool ``[T, N]``).

An AnimatedMesh's ``colors`` go on each frame's vertices (OBJ ``v x y z r g b``, PLY
``red green blue``), as the input gave them (sRGB); its ``uv`` into every OBJ frame as ``vt``
lines and ``f v/vt`` corners (PLY has no per-corner texture coordinates: write OBJ for UVs).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.atomic import atomic_dir
from fourd.io.frames import natural_key
from fourd.io.meshfiles import read_obj, write_obj
from fourd.io.ply import read_ply, write_ply
from fourd.io.sidecars import read_times

#: Mesh file formats of a folder result.
MESH_FORMATS = ("obj", "ply")


def write_mesh_folder(path: Path, result: AnimatedMesh | MeshSequence, *, mesh_format: str = "obj") -> None:
    """Write ``result`` as a folder of per-frame meshes (see the module docstring), atomically."""
    mesh_format = mesh_format.lower().lstrip(".")
    if mesh_format not in MESH_FORMATS:
        raise InputError(f"mesh_format must be 'obj' or 'ply', got {mesh_format!r}")
    count = result.frame_count
    width = max(4, len(str(count - 1)))
    with atomic_dir(path) as tmp:
        animated = isinstance(result, AnimatedMesh)
        uv = result.uv if animated else None
        for t in range(count):
            vertices, faces = result.frame(t)
            colors = result.colors[t] if animated and result.colors is not None else None
            target = tmp / f"frame_{t:0{width}d}.{mesh_format}"
            if mesh_format == "obj":
                write_obj(target, vertices, faces, uv=uv, colors=colors)
            else:
                write_ply(target, vertices, faces=faces, colors=colors)
        (tmp / "times.txt").write_text("".join(f"{t!r}\n" for t in result.times.tolist()))
        if isinstance(result, AnimatedMesh):
            with open(tmp / "observed.npy", "wb") as stream:
                np.save(stream, np.asarray(result.observed, dtype=bool))



def _rewrap(error: InputError, path) -> InputError:
    return InputError(error.problem, error.path or path)


def read_mesh_folder(path: Path) -> AnimatedMesh | MeshSequence:
    """Read a folder of per-frame meshes: an AnimatedMesh when every mesh has the same faces
    (and vertex count), else a MeshSequence. The AnimatedMesh takes its ``uv`` from the first
    frame's ``vt`` corners and its ``colors`` from the frames' vertex colours when every frame
    has them."""
    try:
        files = [
            p
            for p in path.iterdir()
            if p.suffix.lower() in (".obj", ".ply") and not p.name.startswith(".")
        ]
    except OSError as error:
        raise InputError(f"cannot be listed ({error.strerror or error})", path) from None
    if not files:
        raise InputError("the folder holds no .obj or .ply meshes", path)
    files.sort(key=lambda p: natural_key(p.name))
    meshes, colors, uvs = [], [], []
    for file in files:
        if file.suffix.lower() == ".obj":
            mesh = read_obj(file)
            uvs.append(mesh.uv)
        else:
            mesh = read_ply(file)
            uvs.append(None)
        meshes.append((mesh.vertices, mesh.faces))
        colors.append(mesh.colors)
    times = read_times(path / "times.txt", len(meshes)) if (path / "times.txt").exists() else None
    first_v, first_f = meshes[0]
    shared = all(len(v) == len(first_v) and np.array_equal(f, first_f) for v, f in meshes)
    try:
        if shared and len(first_v):
            observed = _read_observed(path / "observed.npy", (len(meshes), len(first_v)))
            return AnimatedMesh(
                first_f, np.stack([v for v, _ in meshes]), times, observed=observed,
                uv=uvs[0] if uvs[0] is not None and len(first_f) else None,
                colors=None if any(c is None for c in colors) else np.stack(colors),
            )
        return MeshSequence(tuple(meshes), times)
    except InputError as error:
        raise _rewrap(error, path) from None


def _read_observed(path: Path, shape: tuple[int, int]) -> np.ndarray | None:
    """The ``observed`` flags [T, N] of a folder result, None when it has no such file."""
    if not path.exists():
        return None
    try:
        observed = np.load(path, allow_pickle=False)
    except Exception as error:  # header, truncation: one clear line
        raise InputError(f"is not a readable .npy array ({type(error).__name__}: {error})", path) from None
    if observed.dtype != bool or observed.shape != shape:
        raise InputError(
            f"must be a bool array of shape {list(shape)} (frames, vertices), "
            f"got {observed.dtype} {list(observed.shape)}",
            path,
        )
    return observed
