"""The shared ground-truth motion data (``../shared/data`` beside the project).

Four sequences are read from there (see its ``README.md``): the animated meshes ``crane``,
``horse-gallop`` and ``elephant-gallop`` (one connectivity, so vertex ``i`` is the true
correspondence), and the point sequence ``dfaust-hopping`` (point ``i`` is the same body point
in every frame), returned as an :class:`~fourd.AnimatedMesh` without faces.

Nothing is downloaded: when the folder is absent, :func:`shared_data_dir` returns ``None`` and
:func:`load_shared` raises :class:`~fourd.InputError` naming the file it looked for.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError

logger = logging.getLogger("fourd.synth.data")

ENVIRONMENT_VARIABLE = "FOURD_DATA"

#: Shared sequence name -> file name inside the shared data folder.
SHARED = {
    "crane": "crane.npz",
    "horse-gallop": "horse-gallop.npz",
    "elephant-gallop": "elephant-gallop.npz",
    "dfaust-hopping": "dfaust-hopping.npz",
}


def _repository_root() -> Path | None:
    """The folder holding ``pyproject.toml`` above this file (``None`` for an installed wheel)."""
    for parent in Path(__file__).resolve().parents:
        if (parent / "pyproject.toml").is_file():
            return parent
    return None


def shared_data_dir() -> Path | None:
    """The shared data folder, or ``None`` when it cannot be found.

    Looked for, in order: the environment variable ``FOURD_DATA``; ``../shared/data`` relative
    to the current directory; ``<repository>/../shared/data`` where ``<repository>`` is the
    project root found from this file's location.

    Returns
    -------
    pathlib.Path or None
        An existing folder.
    """
    candidates = []
    env = os.environ.get(ENVIRONMENT_VARIABLE)
    if env:
        candidates.append(Path(env))
    candidates.append(Path.cwd() / ".." / "shared" / "data")
    root = _repository_root()
    if root is not None:
        candidates.append(root / ".." / "shared" / "data")
    for candidate in candidates:
        if candidate.is_dir():
            return candidate.resolve()
    return None


def shared_path(name: str) -> Path:
    """Path of shared sequence ``name``; raises :class:`InputError` when unknown or missing."""
    if name not in SHARED:
        raise InputError(f"unknown shared sequence {name!r}; known: {', '.join(SHARED)}")
    folder = shared_data_dir()
    if folder is None:
        looked = Path.cwd() / ".." / "shared" / "data" / SHARED[name]
        raise InputError(
            f"shared data folder not found (set {ENVIRONMENT_VARIABLE} or place it at ../shared/data)",
            looked,
        )
    path = folder / SHARED[name]
    if not path.is_file():
        raise InputError("shared data file is missing", path)
    return path


def load_shared(name: str) -> AnimatedMesh:
    """Read a shared ground-truth sequence as an :class:`~fourd.AnimatedMesh`.

    Parameters
    ----------
    name : {"crane", "horse-gallop", "elephant-gallop", "dfaust-hopping"}

    Returns
    -------
    AnimatedMesh
        ``vertices`` float64 ``[T, N, 3]`` (Y up, in the data's own units), ``faces`` ``[F, 3]``
        and ``times`` ``0 .. T-1``. For ``dfaust-hopping`` the faces are empty (``[0, 3]``) and
        the points are un-normalised (``points * scale + loc``), so the units are metres as in
        Dynamic FAUST.

    Raises
    ------
    InputError
        Unknown name, or the file is missing or does not hold the expected keys.

    References
    ----------
    Vlasic, Baran, Matusik, Popović, "Articulated Mesh Animation from Multi-view Silhouettes",
    SIGGRAPH 2008 (crane). Sumner & Popović, "Deformation Transfer for Triangle Meshes",
    SIGGRAPH 2004 (horse, elephant). Bogo et al., "Dynamic FAUST", CVPR 2017 (dfaust-hopping).
    """
    path = shared_path(name)
    try:
        with np.load(path) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError) as error:
        raise InputError(f"cannot read ({error})", path) from None
    if name == "dfaust-hopping":
        missing = {"points", "loc", "scale"} - arrays.keys()
        if missing:
            raise InputError(f"missing keys {sorted(missing)}", path)
        points = arrays["points"].astype(np.float64)
        loc = arrays["loc"].astype(np.float64).reshape(1, 1, 3)
        scale = float(np.asarray(arrays["scale"], dtype=np.float64))
        vertices = points * scale + loc
        faces = np.zeros((0, 3), dtype=np.int64)
    else:
        missing = {"vertices", "faces"} - arrays.keys()
        if missing:
            raise InputError(f"missing keys {sorted(missing)}", path)
        vertices = arrays["vertices"].astype(np.float64)
        faces = arrays["faces"].astype(np.int64)
    logger.debug("read %s: %d frames, %d vertices", path, vertices.shape[0], vertices.shape[1])
    return AnimatedMesh(faces=faces, vertices=vertices, times=np.arange(len(vertices), dtype=float))
