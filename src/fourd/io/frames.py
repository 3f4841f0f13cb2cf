"""Input frames on disk: frame files and folders read into a
:class:`~fourd.sequence.PointCloudSequence`, and scan folders written back (:func:`write_frames`).

An input sequence is a folder of frame files, one per time step, ordered by the natural sort
of their names (``frame_2.ply`` before ``frame_10.ply``), with optional ``sensors.json`` and
``times.txt`` beside them; or a single ``.npz`` holding ``points [T, P, 3]``; or a single frame
file. Every problem raises :class:`fourd.errors.InputError` naming the file.

Frame formats (by extension, case-insensitive):

========  ==============================================================================
``.ply``  ASCII or binary (either byte order), float or double; ``x y z``, optional
          ``nx ny nz`` and ``red green blue``; faces, when present, make the frame a
          per-frame mesh (``Frame.faces``); other properties are ignored.
``.obj``  ``v`` lines (an optional colour ``v x y z r g b`` is kept); ``f`` lines, when
          present, make the frame a per-frame mesh.
``.xyz``  text rows ``x y z`` or ``x y z nx ny nz``.
``.pts``  like ``.xyz``, optionally with a point-count first line, or Leica-style rows
          ``x y z intensity [r g b]``.
``.npy``  ``[P, 3]`` or ``[P, 6]`` (points and normals).
``.npz``  ``points [P, 3]`` with optional ``normals`` and ``colors``.
========  ==============================================================================
"""

from __future__ import annotations

import json
import logging
import os
import re
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.io.atomic import atomic_dir
from fourd.io.meshfiles import read_obj, read_xyz, write_xyz
from fourd.io.ply import PlyMesh, read_ply, write_ply
from fourd.io.sidecars import read_sensors, read_times, sensor_table
from fourd.io.video import CAMERAS_FILE, VIDEO_FOLDER, read_video, write_video
from fourd.sequence import Frame, PointCloudSequence

log = logging.getLogger("fourd.io.frames")

#: Extensions of frame files, lower case.
FRAME_SUFFIXES: tuple[str, ...] = (".ply", ".obj", ".xyz", ".pts", ".npy", ".npz")
#: Files beside the frames that are not frames.
SIDECARS: tuple[str, ...] = ("sensors.json", "times.txt", "cameras.json")
#: Files kept beside frames that are plainly not frames (notes, logs, tables, pictures, other
#: settings): skipped with one log line. Any other unknown type (``.stl``, ``.pcd``, ``.e57``:
#: geometry fourd cannot read) stops the load.
NOT_FRAME_SUFFIXES: tuple[str, ...] = (
    ".json", ".txt", ".md", ".rst", ".csv", ".tsv", ".log", ".html", ".pdf", ".yaml", ".yml",
    ".toml", ".ini", ".cfg", ".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".mp4", ".mov",
)

__all__ = [
    "FRAME_SUFFIXES",
    "NOT_FRAME_SUFFIXES",
    "PlyMesh",
    "load_sequence",
    "natural_key",
    "read_frame",
    "read_ply",
    "open_sequence",
    "read_sensors",
    "read_times",
    "write_frames",
    "write_ply",
]


class _Raw(NamedTuple):
    points: np.ndarray
    normals: np.ndarray | None
    colors: np.ndarray | None
    columns: int | None  # raw table width for array/text formats (compared across a folder)
    faces: np.ndarray | None = None


def natural_key(name: str) -> tuple:
    """Sort key under which ``frame_2`` precedes ``frame_10`` (digit runs compare as numbers)."""
    parts = re.split(r"(\d+)", name)
    return tuple((0, int(p), p) if p.isdigit() else (1, 0, p.lower()) for p in parts)


def _load_npz(path: Path) -> dict:
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except PermissionError as error:
        raise InputError(f"cannot be read ({error.strerror})", path) from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as error:
        raise InputError(f"is not a readable .npz archive ({error})", path) from None


def _load_npy(path: Path) -> np.ndarray:
    try:
        return np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except PermissionError as error:
        raise InputError(f"cannot be read ({error.strerror})", path) from None
    except (OSError, ValueError, EOFError) as error:
        raise InputError(f"is not a readable .npy array ({error})", path) from None


def _table(array, path: Path, name: str) -> np.ndarray:
    array = np.asarray(array)
    if not (np.issubdtype(array.dtype, np.number) or array.dtype == bool):
        raise InputError(f"{name} holds {array.dtype} values, not numbers", path)
    if array.ndim != 2:
        raise InputError(f"{name} must be a 2-D table [P, 3], got shape {list(array.shape)}", path)
    return array.astype(np.float64)


def _read_raw(path: Path) -> _Raw:
    suffix = path.suffix.lower()
    if suffix == ".ply":
        ply = read_ply(path)
        return _Raw(ply.vertices, ply.normals, ply.colors, None, ply.faces)
    if suffix == ".obj":
        obj = read_obj(path)
        return _Raw(obj.vertices, None, obj.colors, None, obj.faces)
    if suffix in (".xyz", ".pts"):
        table = read_xyz(path)
        return _Raw(table.points, table.normals, table.colors, table.columns)
    if suffix == ".npy":
        table = _table(_load_npy(path), path, "the array")
        if table.shape[1] not in (3, 6):
            raise InputError(
                f"the array has shape {list(table.shape)}; expected [P, 3] (points) or [P, 6] (points and normals)",
                path,
            )
        return _Raw(
            table[:, :3], table[:, 3:] if table.shape[1] == 6 else None, None, table.shape[1]
        )
    if suffix == ".npz":
        data = _load_npz(path)
        if "points" not in data:
            raise InputError(
                f"has no 'points' array (found: {', '.join(sorted(data)) or 'nothing'})", path
            )
        points = np.asarray(data["points"])
        if points.ndim == 3 and len(points) == 1:
            points = points[0]
            data = {k: (v[0] if np.ndim(v) == 3 else v) for k, v in data.items()}
        if points.ndim == 3:
            raise InputError(
                f"holds a sequence of {len(points)} frames (points {list(points.shape)}); give it on its own, not inside a folder of frames",
                path,
            )
        points = _table(points, path, "points")
        if points.shape[1] != 3:
            raise InputError(f"points must have shape [P, 3], got {list(points.shape)}", path)
        extra = {}
        for key in ("normals", "colors"):
            if key in data:
                value = _table(data[key], path, key)
                if value.shape != points.shape:
                    raise InputError(
                        f"{key} has shape {list(value.shape)} but points has {list(points.shape)}",
                        path,
                    )
                extra[key] = value
        return _Raw(points, extra.get("normals"), extra.get("colors"), None)
    raise InputError(
        f"unknown file type {suffix or '(no extension)'!r}; frames must be one of {', '.join(FRAME_SUFFIXES)}",
        path,
    )


def _unit_normals(normals: np.ndarray | None, path) -> np.ndarray | None:
    """Normalise normals; drop them (with a warning) when some have zero length or are not finite."""
    if normals is None:
        return None
    lengths = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    bad = ~np.isfinite(lengths) | (lengths <= 1e-12)
    if bad.any():
        log.warning(
            "%s: %d normals have zero length or are not finite; ignoring this frame's normals",
            path,
            int(bad.sum()),
        )
        return None
    return normals / lengths[:, None]


def _make_frame(path, points, normals, colors, sensors, time, faces=None) -> Frame:
    if len(points) == 0:
        raise InputError("the frame has zero points", path)
    if not np.isfinite(points).all():  # (a flat test first: per-row reductions are slow)
        bad = ~np.isfinite(points).all(axis=1)
        raise InputError(
            f"{int(bad.sum())} points have NaN or infinite coordinates (first at point {int(np.argmax(bad))})",
            path,
        )
    if colors is not None and not np.isfinite(colors).all():
        log.warning("%s: colours with NaN or infinite values; ignoring them", path)
        colors = None
    try:
        return Frame(
            points=points,
            normals=_unit_normals(normals, path),
            colors=colors,
            sensors=sensors,
            time=time,
            faces=faces,
        )
    except InputError as error:
        raise InputError(error.problem, path) from None


def read_frame(
    path: str | os.PathLike, *, time: float = 0.0, sensors: np.ndarray | None = None
) -> Frame:
    """Read one frame file.

    Parameters
    ----------
    path : path-like
        A ``.ply``, ``.obj``, ``.xyz``, ``.pts``, ``.npy`` or ``.npz`` file (see the module
        docstring for the layouts).
    time : float
        The frame's time stamp.
    sensors : array [K, 3], optional
        Positions of the scanners that saw the frame.

    Returns
    -------
    Frame
        With ``faces`` when the file has faces (a per-frame mesh). Normals (when the file has
        them) are normalised; normals of zero length make the frame have none (a warning is
        logged).

    Raises
    ------
    InputError
        Missing or unreadable file, unknown extension, malformed or truncated content, zero
        points, NaN or infinite coordinates, a table that is not ``[P, 3]`` or ``[P, 6]``.
    """
    path = Path(path)
    raw = _read_guarded(path)
    return _make_frame(path, raw.points, raw.normals, raw.colors, sensors, time, raw.faces)


def _read_guarded(path: Path) -> _Raw:
    if not path.exists():
        raise InputError("does not exist", path)
    if path.is_dir():
        raise InputError("is a folder, not a frame file", path)
    try:
        return _read_raw(path)
    except InputError:
        raise
    except MemoryError:
        raise InputError("is too large to read into memory", path) from None
    except Exception as error:  # a parser failure we did not foresee: still one clear line
        raise InputError(
            f"cannot be read as a {path.suffix.lower() or 'frame'} file ({type(error).__name__}: {error})",
            path,
        ) from None


# ----------------------------------------------------------------------------- sequences


def _frame_files(folder: Path) -> list[Path]:
    try:
        entries = list(folder.iterdir())
    except PermissionError as error:
        raise InputError(f"cannot be listed ({error.strerror})", folder) from None
    except OSError as error:
        raise InputError(f"cannot be listed ({error})", folder) from None
    files, skipped = [], []
    for entry in entries:
        name = entry.name
        if (
            name.startswith(".")
            or name in SIDECARS
            or entry.stem.lower() == "truth"
            or name.lower() == "truth"
        ):
            continue
        if entry.is_dir():
            log.debug("%s: ignoring sub-folder", entry)
            continue
        if entry.suffix.lower() in NOT_FRAME_SUFFIXES:
            skipped.append(name)
            continue
        if entry.suffix.lower() not in FRAME_SUFFIXES:
            raise InputError(
                f"unknown file type {entry.suffix.lower() or '(no extension)'!r} in the frame folder; "
                f"frames must be one of {', '.join(FRAME_SUFFIXES)}",
                entry,
            )
        files.append(entry)
    if skipped:
        log.info("%s: not frames, skipped: %s", folder, ", ".join(sorted(skipped, key=natural_key)))
    files.sort(key=lambda p: natural_key(p.name))
    return files


def _npz_sequence(path: Path) -> PointCloudSequence:
    data = _load_npz(path)
    if "points" not in data:
        raise InputError(
            f"has no 'points' array (found: {', '.join(sorted(data)) or 'nothing'})", path
        )
    points = np.asarray(data["points"])
    if points.ndim == 2:
        return PointCloudSequence((read_frame(path),), (path.name,))
    if points.ndim != 3 or points.shape[2] != 3:
        raise InputError(
            f"points must have shape [T, P, 3] (or [P, 3]), got {list(points.shape)}", path
        )
    points = _table(points.reshape(-1, 3), path, "points").reshape(points.shape)
    if "loc" in data and "scale" in data:  # normalised data (e.g. ../shared/data): original units
        try:
            scale = np.asarray(data["scale"], dtype=np.float64)
            loc = np.asarray(data["loc"], dtype=np.float64)
            points = points * scale + loc
        except (TypeError, ValueError):
            raise InputError(
                f"'loc' {list(np.shape(data['loc']))} and 'scale' {list(np.shape(data['scale']))} do not apply to points",
                path,
            ) from None
    count = len(points)
    if count == 0:
        raise InputError("holds zero frames", path)
    extra = {}
    for key in ("normals", "colors"):
        if key in data:
            value = np.asarray(data[key])
            if value.shape != points.shape:
                raise InputError(
                    f"{key} has shape {list(value.shape)} but points has {list(points.shape)}", path
                )
            extra[key] = value.astype(np.float64)
    times = np.arange(count, dtype=np.float64)
    if "times" in data:
        times = np.asarray(data["times"], dtype=np.float64).ravel()
        if len(times) != count:
            raise InputError(f"has {len(times)} times but {count} frames", path)
        if not np.isfinite(times).all() or np.any(np.diff(times) <= 0):
            raise InputError("times must be finite and increase strictly", path)
    sensors: list = [None] * count
    if "sensors" in data:
        value = np.asarray(data["sensors"], dtype=np.float64)
        if value.ndim == 2:
            sensors = [sensor_table(value, path, "sensors")] * count
        elif value.ndim == 3 and len(value) == count:
            sensors = [sensor_table(v, path, f"sensors[{i}]") for i, v in enumerate(value)]
        else:
            raise InputError(
                f"sensors must have shape [K, 3] or [{count}, K, 3], got {list(value.shape)}", path
            )
    frames, names = [], []
    for t in range(count):
        name = f"{path.name}[{t}]"
        frames.append(
            _make_frame(
                f"{path}[frame {t}]",
                points[t],
                extra["normals"][t] if "normals" in extra else None,
                extra["colors"][t] if "colors" in extra else None,
                sensors[t],
                times[t],
            )
        )
        names.append(name)
    return PointCloudSequence(tuple(frames), tuple(names))


def _folder_listing(path: Path) -> tuple[list[Path], np.ndarray, list]:
    """A frame folder's files (natural order), their times (``times.txt``, default 0, 1,
    2, ...) and sensors (``sensors.json``, default None per frame)."""
    files = _frame_files(path)
    if not files:
        raise InputError(f"the folder holds no frame files ({', '.join(FRAME_SUFFIXES)})", path)
    count = len(files)
    times = np.arange(count, dtype=np.float64)
    if (path / "times.txt").exists():
        times = read_times(path / "times.txt", count)
    sensors: list = [None] * count
    if (path / "sensors.json").exists():
        sensors = read_sensors(path / "sensors.json", count)
    return files, times, sensors


def load_sequence(path: str | os.PathLike) -> PointCloudSequence:
    """Read a sequence of frames.

    Parameters
    ----------
    path : path-like
        A folder of frame files (natural sort order; hidden files, ``sensors.json``,
        ``times.txt`` and anything named ``truth`` are not frames), a single ``.npz`` with
        ``points [T, P, 3]`` (optional ``times [T]``, ``normals [T, P, 3]``, ``colors``,
        ``sensors [K, 3]`` or ``[T, K, 3]``, and ``loc``/``scale``: points are then
        ``points * scale + loc``, as in ``../shared/data``), or one frame file (a one-frame
        sequence). A folder may hold calibrated video: ``cameras.json`` and
        ``video/<camera>/<frame>.png`` (:mod:`fourd.io.video`).

    Returns
    -------
    PointCloudSequence
        Frame names are the file names; times come from ``times.txt`` (default 0, 1, 2, ...);
        sensors from ``sensors.json`` when present; ``video`` from ``cameras.json`` and
        ``video/`` when present (images read lazily, a frame at a time).

    Raises
    ------
    InputError
        Naming the file: missing path, no frame files, unknown extension, any bad frame (see
        :func:`read_frame`), frames with different table widths, a wrong ``times.txt``,
        ``sensors.json`` or ``cameras.json``, a missing or unreadable image, an image whose
        size disagrees with ``cameras.json``, a camera with more or fewer images than frames.

    Examples
    --------
    >>> import tempfile
    >>> frames = tuple(Frame(np.random.default_rng(t).random((50, 3)), time=t) for t in range(3))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_frames(PointCloudSequence(frames), folder)
    ...     seq = load_sequence(folder)
    >>> len(seq), seq.times, seq.names[0]
    (3, array([0., 1., 2.]), 'frame_0000.ply')
    """
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    if not path.is_dir():
        if path.suffix.lower() == ".npz":
            return _npz_sequence(path)
        return PointCloudSequence((read_frame(path),), (path.name,))
    files, times, sensors = _folder_listing(path)
    count = len(files)
    frames = []
    first_columns: tuple[int, Path] | None = None
    for i, file in enumerate(files):
        raw = _read_guarded(file)
        if raw.columns is not None:
            if first_columns is None:
                first_columns = (raw.columns, file)
            elif raw.columns != first_columns[0]:
                raise InputError(
                    f"mixed point dimensions: this frame has {raw.columns} columns but "
                    f"{first_columns[1].name} has {first_columns[0]}",
                    file,
                )
        frames.append(
            _make_frame(file, raw.points, raw.normals, raw.colors, sensors[i], times[i], raw.faces)
        )
    with_normals = sum(f.normals is not None for f in frames)
    if 0 < with_normals < len(frames):
        log.warning("%s: %d of %d frames have normals", path, with_normals, len(frames))
    return PointCloudSequence(tuple(frames), tuple(f.name for f in files), _folder_video(path, count))


def _folder_video(path: Path, count: int):
    """The video of the scan folder ``path`` of ``count`` frames, or None."""
    if (path / CAMERAS_FILE).exists():
        return read_video(path, frame_count=count)
    if (path / VIDEO_FOLDER).is_dir():
        log.warning("%s: a %s/ folder without %s; ignoring the video", path, VIDEO_FOLDER, CAMERAS_FILE)
    return None


def open_sequence(path: str | os.PathLike) -> FrameSource:
    """A sequence of frames read when asked (:class:`~fourd.frame_source.FrameSource`): a
    folder's frame files are listed now (with ``times.txt`` and ``sensors.json``) and each is
    read when a streamed method asks for it, so a whole capture need not fit in memory. A
    ``.npz`` or a single frame file is read whole (:func:`load_sequence`). A folder's video
    (``cameras.json`` and ``video/``) comes with it, its images decoded when used.

    Raises
    ------
    InputError
        As :func:`load_sequence` for the listing; a bad frame file when it is read.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    if not path.is_dir():
        return FrameSource.of(load_sequence(path))
    files, times, sensors = _folder_listing(path)

    def read(i: int) -> Frame:
        raw = _read_guarded(files[i])
        return _make_frame(files[i], raw.points, raw.normals, raw.colors, sensors[i], times[i], raw.faces)

    return FrameSource(times, tuple(f.name for f in files), read, _folder_video(path, len(files)))


def write_frames(
    seq: PointCloudSequence, folder: str | os.PathLike, *, format: str = "ply"
) -> None:
    """Write ``seq`` as a scan folder that :func:`load_sequence` reads back.

    One file per frame (``frame_0000.ply`` ...; binary little-endian PLY with normals,
    colours and faces when present (a per-frame mesh in double precision), or ``npy`` ``[P, 3|6]``, or ``xyz`` text), ``times.txt`` and, when
    the frames carry sensors, ``sensors.json`` (the fixed form when every frame has the same
    scanners), and, when the sequence has video, ``cameras.json`` and
    ``video/<camera>/frame_0000.png ...`` (:func:`fourd.io.video.write_video`). The folder is
    assembled under a temporary name and renamed into place: an existing folder of that name is
    replaced as a whole.

    Parameters
    ----------
    seq : PointCloudSequence
    folder : path-like
    format : {"ply", "npy", "xyz"}
    """
    format = format.lower().lstrip(".")
    if format not in ("ply", "npy", "xyz"):
        raise InputError(f"unknown frame format {format!r} (use ply, npy or xyz)")
    if format != "ply" and any(f.faces is not None for f in seq.frames):
        raise InputError(f"per-frame meshes are written as ply, not {format}")
    width = max(4, len(str(len(seq) - 1)))
    stems = [f"frame_{i:0{width}d}" for i in range(len(seq))]
    with atomic_dir(folder) as tmp:
        if seq.video is not None:
            write_video(tmp, seq.video, stems)
        for i, frame in enumerate(seq.frames):
            target = tmp / f"{stems[i]}.{format}"
            if format == "ply":
                # a mesh keeps double coordinates: its vertices are exact surface points
                write_ply(target, frame.points, normals=frame.normals, colors=frame.colors,
                          faces=frame.faces, double=frame.faces is not None)
            elif format == "xyz":
                write_xyz(target, frame.points, frame.normals)
            else:
                table = (
                    frame.points
                    if frame.normals is None
                    else np.concatenate([frame.points, frame.normals], axis=1)
                )
                with open(target, "wb") as stream:
                    np.save(stream, table)
        (tmp / "times.txt").write_text("".join(f"{t!r}\n" for t in seq.times.tolist()))
        sensors = [f.sensors for f in seq.frames]
        if any(s is not None for s in sensors):
            first = sensors[0]
            fixed = all(
                s is not None and s.shape == first.shape and np.array_equal(s, first)
                for s in sensors
            )
            if fixed:
                data = {"sensors": first.tolist()}
            else:
                data = {"frames": [[] if s is None else s.tolist() for s in sensors]}
            (tmp / "sensors.json").write_text(json.dumps(data))
