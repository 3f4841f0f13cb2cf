"""Writing reconstruction results, format chosen by the output path; reading them back.

==========================  ===================================================================
``.npz``                    ``vertices`` float32 [T, N, 3], ``faces`` int32 [F, 3], ``times``
                            [T], ``observed`` bool [T, N], optional ``rest`` [N, 3],
                            ``kind="animated"``; a MeshSequence: ``kind="meshes"``,
                            ``vertices_<t>``, ``faces_<t>``, ``times``.
``.glb``                    glTF 2.0 binary: morph targets + weights animation
                            (:mod:`fourd.io.glb`).
``.usd`` ``.usda`` ``.usdc``  time-sampled ``UsdGeom.Mesh`` (needs usd-core: ``fourd[usd]``).
``.pc2``                    Blender point cache + ``.obj`` topology beside it.
folder                      an existing folder, a path ending in ``/`` or a path without a
                            suffix: ``frame_0000.obj`` ... (or ``.ply``), ``times.txt`` and, for
                            an AnimatedMesh, ``observed.npy`` (bool [T, N]).
==========================  ===================================================================

Every file is written under a temporary name and renamed into place (:mod:`fourd.io.atomic`),
so an interrupted run never leaves a partial file under the requested name.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.atomic import atomic_dir, atomic_path
from fourd.io.glb import write_glb
from fourd.io.meshfiles import read_obj, write_obj
from fourd.io.pc2 import write_pc2
from fourd.io.ply import read_ply, write_ply
from fourd.io.readers import natural_key, read_times
from fourd.io.usd import USD_SUFFIXES, write_usd

log = logging.getLogger("fourd.io.writers")

#: Output suffixes :func:`save` understands (besides folders).
RESULT_SUFFIXES: tuple[str, ...] = (".npz", ".glb", *USD_SUFFIXES, ".pc2")
MESH_FORMATS = ("obj", "ply")

__all__ = ["RESULT_SUFFIXES", "check_output", "load_result", "output_kind", "save"]


def output_kind(path: str | os.PathLike) -> str:
    """The format :func:`save` would write to ``path``: ``"npz"``, ``"glb"``, ``"usd"``,
    ``"pc2"`` or ``"folder"``; InputError for an unknown suffix."""
    text = os.fspath(path)
    target = Path(text)
    if text.endswith(("/", os.sep)) or target.is_dir() or not target.suffix:
        return "folder"
    suffix = target.suffix.lower()
    if suffix in USD_SUFFIXES:
        return "usd"
    if suffix in RESULT_SUFFIXES:
        return suffix[1:]
    raise InputError(
        f"unknown output format {suffix!r}: use .npz, .glb, .usd, .usda, .usdc, .pc2 or a folder (a path ending in /)",
        path,
    )


def check_output(path: str | os.PathLike) -> str:
    """Check, before any long computation, that :func:`save` can write ``path``.

    Returns the output kind (see :func:`output_kind`). Raises InputError for an unknown
    suffix, a missing or unwritable parent folder, an existing file where a folder output is
    asked for, or a USD output without usd-core installed.
    """
    kind = output_kind(path)
    target = Path(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.exists():
        raise InputError("the output folder does not exist", parent)
    if not os.access(parent, os.W_OK):
        raise InputError("the output folder is not writable", parent)
    if kind == "folder" and target.exists() and not target.is_dir():
        raise InputError("exists and is not a folder", target)
    if kind == "usd":
        from fourd.io.usd import _pxr

        _pxr(path)
    return kind


def save(
    result: AnimatedMesh | MeshSequence,
    path: str | os.PathLike,
    *,
    mesh_format: str = "obj",
    fps: float | None = None,
    interpolation: str = "LINEAR",
) -> Path:
    """Write a reconstruction; the format follows ``path`` (see the module docstring).

    Parameters
    ----------
    result : AnimatedMesh or MeshSequence
    path : path-like
    mesh_format : {"obj", "ply"}
        Per-frame mesh files of a folder output.
    fps : float, optional
        For ``.glb`` and USD: ``times`` are frame numbers at this rate (default: seconds).
    interpolation : {"LINEAR", "STEP"}
        ``.glb`` keyframe interpolation between frames.

    Returns
    -------
    Path
        What was written (the folder for folder outputs).

    Raises
    ------
    InputError
        Unknown suffix, missing or unwritable output folder, a result that the format cannot
        hold (``.pc2`` of a MeshSequence), USD without usd-core.
    """
    if not isinstance(result, AnimatedMesh | MeshSequence):
        raise InputError(
            f"can only save an AnimatedMesh or MeshSequence, not a {type(result).__name__}", path
        )
    kind = output_kind(path)
    target = Path(path)
    try:
        if kind == "npz":
            _write_npz(target, result)
        elif kind == "glb":
            write_glb(target, result, fps=fps, interpolation=interpolation)
        elif kind == "usd":
            write_usd(target, result, fps=fps)
        elif kind == "pc2":
            write_pc2(target, result)
        else:
            _write_folder(target, result, mesh_format=mesh_format)
    except InputError:
        raise
    except PermissionError as error:
        raise InputError(f"cannot be written ({error.strerror})", path) from None
    except OSError as error:
        raise InputError(f"cannot be written ({error.strerror or error})", path) from None
    return target


def _write_npz(path: Path, result) -> None:
    if isinstance(result, AnimatedMesh):
        arrays = {
            "kind": np.array("animated"),
            "vertices": result.vertices.astype(np.float32),
            "faces": result.faces.astype(np.int32),
            "times": result.times,
            "observed": result.observed,
        }
        if result.rest is not None:
            arrays["rest"] = result.rest.astype(np.float32)
    else:
        arrays = {"kind": np.array("meshes"), "times": result.times}
        for t, (vertices, faces) in enumerate(result.meshes):
            arrays[f"vertices_{t}"] = vertices.astype(np.float32)
            arrays[f"faces_{t}"] = faces.astype(np.int32)
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        np.savez(stream, **arrays)


def _write_folder(path: Path, result, *, mesh_format: str) -> None:
    mesh_format = mesh_format.lower().lstrip(".")
    if mesh_format not in MESH_FORMATS:
        raise InputError(f"mesh_format must be 'obj' or 'ply', got {mesh_format!r}")
    count = result.frame_count
    width = max(4, len(str(count - 1)))
    with atomic_dir(path) as tmp:
        for t in range(count):
            vertices, faces = result.frame(t)
            target = tmp / f"frame_{t:0{width}d}.{mesh_format}"
            if mesh_format == "obj":
                write_obj(target, vertices, faces)
            else:
                write_ply(target, vertices, faces=faces)
        (tmp / "times.txt").write_text("".join(f"{t!r}\n" for t in result.times.tolist()))
        if isinstance(result, AnimatedMesh):
            with open(tmp / "observed.npy", "wb") as stream:
                np.save(stream, np.asarray(result.observed, dtype=bool))


def _rewrap(error: InputError, path) -> InputError:
    return InputError(error.problem, error.path or path)


def _load_npz(path: Path):
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except Exception as error:  # zip, pickle, header errors: one clear line
        raise InputError(
            f"is not a readable .npz result ({type(error).__name__}: {error})", path
        ) from None
    kind = str(arrays.get("kind", "animated"))
    try:
        if kind == "meshes":
            count = sum(1 for key in arrays if key.startswith("vertices_"))
            meshes = []
            for t in range(count):
                if f"vertices_{t}" not in arrays or f"faces_{t}" not in arrays:
                    raise InputError(f"frame {t} lacks vertices_{t} or faces_{t}", path)
                meshes.append((arrays[f"vertices_{t}"], arrays[f"faces_{t}"]))
            return MeshSequence(tuple(meshes), arrays.get("times"))
        missing = [key for key in ("vertices", "faces") if key not in arrays]
        if missing:
            raise InputError(f"is not a fourd result: no {' or '.join(missing)} array", path)
        return AnimatedMesh(
            faces=arrays["faces"],
            vertices=arrays["vertices"],
            times=arrays.get("times"),
            observed=arrays.get("observed"),
            rest=arrays.get("rest"),
        )
    except InputError as error:
        raise _rewrap(error, path) from None


def _load_folder(path: Path):
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
    meshes = []
    for file in files:
        if file.suffix.lower() == ".obj":
            mesh = read_obj(file)
        else:
            mesh = read_ply(file)
        meshes.append((mesh.vertices, mesh.faces))
    times = read_times(path / "times.txt", len(meshes)) if (path / "times.txt").exists() else None
    first_v, first_f = meshes[0]
    shared = all(len(v) == len(first_v) and np.array_equal(f, first_f) for v, f in meshes)
    try:
        if shared and len(first_v):
            observed = _read_observed(path / "observed.npy", (len(meshes), len(first_v)))
            return AnimatedMesh(first_f, np.stack([v for v, _ in meshes]), times, observed=observed)
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


def load_result(path: str | os.PathLike) -> AnimatedMesh | MeshSequence:
    """Read a result written by :func:`save`: an ``.npz`` or a folder of per-frame meshes.

    A folder whose meshes all share the same faces (and vertex count) is an AnimatedMesh
    (``observed`` from ``observed.npy``, all True without it); otherwise a MeshSequence.
    Times come from ``times.txt`` when present.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    if path.is_dir():
        return _load_folder(path)
    if path.suffix.lower() == ".npz":
        return _load_npz(path)
    raise InputError("can read back results in .npz or a folder of .obj/.ply meshes", path)


def as_result(result) -> AnimatedMesh | MeshSequence:
    """``result`` itself when it is an AnimatedMesh or MeshSequence, else read it from a path."""
    if isinstance(result, (AnimatedMesh, MeshSequence)):
        return result
    if isinstance(result, (str, os.PathLike)):
        return load_result(result)
    raise InputError(
        f"expected an AnimatedMesh, MeshSequence or a result file, got {type(result).__name__}"
    )
