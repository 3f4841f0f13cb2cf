"""Reconstruction results on disk: :func:`save` picks the format from the output path,
:func:`load_result` reads every one of them back (:data:`READERS`, the one place that maps a
format to its reader: ``fourd evaluate``, ``fourd view`` and ``fourd info`` go through it).

==========================  ===================================================================
``.npz``                    (:mod:`fourd.io.npz`) ``vertices`` float32 [T, N, 3], ``faces`` int32 [F, 3], ``times``
                            [T], ``observed`` bool [T, N], optional ``rest`` [N, 3],
                            ``kind="animated"``; a MeshSequence: ``kind="meshes"``,
                            ``vertices_<t>``, ``faces_<t>``, ``times``.
``.glb``                    glTF 2.0 binary: morph targets + weights animation
                            (:mod:`fourd.io.glb`).
``.usd`` ``.usda`` ``.usdc``  time-sampled ``UsdGeom.Mesh`` (needs usd-core: ``fourd[usd]``).
``.abc``                    Alembic ``OPolyMesh`` with time-sampled points and normals (needs
                            alembic3d: ``fourd[abc]``; :mod:`fourd.io.abc`).
``.pc2``                    Blender point cache + ``.obj`` topology beside it.
folder                      an existing folder, a path ending in ``/`` or a path without a
                            suffix: ``frame_0000.obj`` ... (or ``.ply``), ``times.txt`` and, for
                            an AnimatedMesh, ``observed.npy`` (bool [T, N]).
==========================  ===================================================================

Every file is written under a temporary name and renamed into place (:mod:`fourd.io.atomic`),
so an interrupted run never leaves a partial file under the requested name.

Times are converted for each format through one time base (:mod:`fourd.io.timebase`: frame
numbers or seconds, and a frame rate); ``scale`` and ``up`` (:mod:`fourd.io.axes`) change the
written positions and the declared up axis, never the reconstruction.

Read back, ``.glb``, USD and ``.pc2`` give ``observed`` all True (they do not hold it,
:data:`OBSERVED_KINDS` do) and no rest pose; ``.glb`` times are its key times in seconds.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.abc import read_abc, write_abc
from fourd.io.axes import check_up, scaled
from fourd.io.glb import read_glb, write_glb
from fourd.io.meshfolder import read_mesh_folder, write_mesh_folder
from fourd.io.npz import read_npz, write_npz
from fourd.io.pc2 import read_pc2_result, write_pc2
from fourd.io.timebase import time_base
from fourd.io.usd import USD_SUFFIXES, read_usd, write_usd

log = logging.getLogger("fourd.io.results")

#: Output suffixes :func:`save` understands (besides folders).
RESULT_SUFFIXES: tuple[str, ...] = (".npz", ".glb", *USD_SUFFIXES, ".abc", ".pc2")

#: Output kinds (:func:`output_kind`) that hold one connectivity for every frame. A
#: MeshSequence still goes in, baked by :func:`fourd.io.pc2.one_connectivity`, but that mesh
#: holds every frame's vertices and is written once per frame: ``T x (sum of N_t)`` points,
#: quadratic in the frames. The other kinds keep each frame's own mesh.
ONE_CONNECTIVITY_KINDS: tuple[str, ...] = ("pc2",)

#: Output kind -> the function that reads it back (path -> AnimatedMesh | MeshSequence).
READERS = {
    "npz": read_npz,
    "glb": read_glb,
    "usd": read_usd,
    "pc2": read_pc2_result,
    "abc": read_abc,
    "folder": read_mesh_folder,
}

#: Output kinds that hold the ``observed`` flags (the others read back as all observed).
OBSERVED_KINDS: tuple[str, ...] = ("npz", "abc", "folder")

__all__ = [
    "ONE_CONNECTIVITY_KINDS",
    "OBSERVED_KINDS",
    "READERS",
    "RESULT_SUFFIXES",
    "check_output",
    "load_result",
    "output_kind",
    "result_kind",
    "save",
]


def output_kind(path: str | os.PathLike) -> str:
    """The format :func:`save` would write to ``path``: ``"npz"``, ``"glb"``, ``"usd"``,
    ``"abc"``, ``"pc2"`` or ``"folder"``; InputError for an unknown suffix."""
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
        f"unknown output format {suffix!r}: use .npz, .glb, .usd, .usda, .usdc, .abc, .pc2 or a folder (a path ending in /)",
        path,
    )


def check_output(path: str | os.PathLike, *, create_parents: bool = False) -> str:
    """Check, before any long computation, that :func:`save` can write ``path``.

    Parameters
    ----------
    path : path-like
        The output (see the module docstring).
    create_parents : bool
        Accept a missing output folder when it can be created: its nearest existing ancestor
        is a folder where new entries can be made (``fourd reconstruct`` then creates it
        before saving). False: the output folder must exist, as :func:`save` needs.

    Returns
    -------
    str
        The output kind (see :func:`output_kind`).

    Raises
    ------
    InputError
        An unknown suffix; a file where a folder is expected (the output folder, or one of its
        ancestors); a missing output folder (without ``create_parents``); a folder where no
        file can be made (no permission, a read-only file system, ``/proc``), found by
        creating and removing a temporary entry there; an existing file where a folder output
        is asked for; a USD output without usd-core installed, an ``.abc`` output without
        alembic3d.
    """
    kind = output_kind(path)
    target = Path(path)
    parent = target.parent if str(target.parent) else Path(".")
    existing = parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{existing} is a file, not a folder", path)
    if existing != parent and not create_parents:
        raise InputError("the output folder does not exist", parent)
    if not os.access(existing, os.W_OK):
        raise InputError("the output folder is not writable", existing)
    _probe_writable(existing, folder_entry=existing != parent, output=path)
    if kind == "folder" and target.exists() and not target.is_dir():
        raise InputError("exists and is not a folder", target)
    if kind == "usd":
        from fourd.io.usd import _pxr

        _pxr(path)
    if kind == "abc":
        from fourd.io.abc import _alembic

        _alembic(path)
    return kind


def _probe_writable(folder: Path, *, folder_entry: bool, output) -> None:
    """Create and remove a temporary file (or, with ``folder_entry``, a folder) in ``folder``:
    the permission bits do not tell (root may write anywhere but ``/proc``, a read-only
    mount keeps its bits)."""
    try:
        if folder_entry:
            os.rmdir(tempfile.mkdtemp(prefix=".fourd-check.", dir=folder))
        else:
            handle, name = tempfile.mkstemp(prefix=".fourd-check.", dir=folder)
            os.close(handle)
            os.remove(name)
    except OSError as error:
        raise InputError(
            f"cannot write in the output folder {folder} ({error.strerror or error})", output
        ) from None


def save(
    result: AnimatedMesh | MeshSequence,
    path: str | os.PathLike,
    *,
    mesh_format: str = "obj",
    fps: float | None = None,
    time_unit: str | None = None,
    interpolation: str = "LINEAR",
    up: str = "y",
    scale: float = 1.0,
    glb_encoding: str = "quantized",
) -> Path:
    """Write a reconstruction; the format follows ``path`` (see the module docstring).

    Parameters
    ----------
    result : AnimatedMesh or MeshSequence
    path : path-like
    mesh_format : {"obj", "ply"}
        Per-frame mesh files of a folder output.
    fps : float, optional
        Frames per second (:func:`fourd.io.timebase.time_base`): the duration of a frame when
        the times are frame numbers (default 30), the rate of the frame-based timelines (USD
        time codes, ``.pc2`` frames) when they are seconds (default: measured from them).
    time_unit : {"frames", "seconds"}, optional
        What ``result.times`` count; by default whole numbers are frame numbers, anything
        else seconds. Used by ``.glb``, USD, ``.abc`` and ``.pc2``.
    interpolation : {"LINEAR", "STEP"}
        ``.glb`` keyframe interpolation between frames.
    up : {"y", "z"}
        The data's up axis (:mod:`fourd.io.axes`): ``"z"`` rotates ``.glb`` and ``.abc``
        positions to their Y up and writes USD's ``upAxis`` as ``Z``; the other formats keep
        the data's axes.
    scale : float
        Every written position is multiplied by it (all formats), e.g. 0.001 for millimetres
        to metres.
    glb_encoding : {"quantized", "float"}
        ``.glb`` morph targets: compact (``KHR_mesh_quantization``, about half the size) or
        plain float32 (:func:`fourd.io.glb.write_glb`).

    Returns
    -------
    Path
        What was written (the folder for folder outputs).

    Raises
    ------
    InputError
        Unknown suffix, missing or unwritable output folder, USD without usd-core, ``.abc``
        without alembic3d, a bad ``fps``, ``time_unit``, ``up`` or ``scale``.
    """
    if not isinstance(result, AnimatedMesh | MeshSequence):
        raise InputError(
            f"can only save an AnimatedMesh or MeshSequence, not a {type(result).__name__}", path
        )
    kind = output_kind(path)
    target = Path(path)
    up = check_up(up)
    time_base(result.times, fps=fps, unit=time_unit)  # checks them whatever the format
    if scale != 1:
        result = scaled(result, scale)
    timing = {"fps": fps, "time_unit": time_unit}
    try:
        if kind == "npz":
            write_npz(target, result)
        elif kind == "glb":
            write_glb(target, result, interpolation=interpolation, up=up,
                      encoding=glb_encoding, **timing)
        elif kind == "usd":
            write_usd(target, result, up=up, **timing)
        elif kind == "abc":
            write_abc(target, result, up=up, **timing)
        elif kind == "pc2":
            write_pc2(target, result, **timing)
        else:
            write_mesh_folder(target, result, mesh_format=mesh_format)
    except InputError:
        raise
    except PermissionError as error:
        raise InputError(f"cannot be written ({error.strerror})", path) from None
    except OSError as error:
        raise InputError(f"cannot be written ({error.strerror or error})", path) from None
    return target


def result_kind(path: str | os.PathLike) -> str:
    """The format of the existing result ``path`` (a key of :data:`READERS`); InputError when
    it does not exist or is no result format."""
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    if path.is_dir():
        return "folder"
    suffix = path.suffix.lower()
    if suffix in USD_SUFFIXES:
        return "usd"
    if suffix in RESULT_SUFFIXES and suffix[1:] in READERS:
        return suffix[1:]
    known = ", ".join(s for s in RESULT_SUFFIXES)
    raise InputError(
        f"not a result format fourd reads ({suffix or 'no suffix'}): {known} or a folder of "
        ".obj/.ply meshes",
        path,
    )


def load_result(path: str | os.PathLike) -> AnimatedMesh | MeshSequence:
    """Read a result written by :func:`save`, in any of its formats (:data:`READERS`).

    A folder whose meshes all share the same faces (and vertex count) is an AnimatedMesh
    (``observed`` from ``observed.npy``, all True without it); otherwise a MeshSequence.
    Times come from ``times.txt`` when present. See the module docstring for what ``.glb``,
    USD and ``.pc2`` do not hold.
    """
    return READERS[result_kind(path)](Path(path))


def as_result(result) -> AnimatedMesh | MeshSequence:
    """``result`` itself when it is an AnimatedMesh or MeshSequence, else read it from a path."""
    if isinstance(result, (AnimatedMesh, MeshSequence)):
        return result
    if isinstance(result, (str, os.PathLike)):
        return load_result(result)
    raise InputError(
        f"expected an AnimatedMesh, MeshSequence or a result file, got {type(result).__name__}"
    )
