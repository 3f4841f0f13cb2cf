"""fourd's own result file (``.npz``): what :func:`fourd.save` writes for ``*.npz``.

An :class:`~fourd.animation.AnimatedMesh`: ``kind="animated"``, ``vertices`` float32
``[T, N, 3]``, ``faces`` int32 ``[F, 3]``, ``times`` ``[T]``, ``observed`` bool ``[T, N]``,
optional ``rest`` float32 ``[N, 3]``, ``uv`` float32 ``[F, 3, 2]`` (per face corner) and
``colors`` uint8 ``[T, N, 3]`` (0-255, as the input's colours were encoded). A :class:`~fourd.animation.MeshSequence`:
``kind="meshes"``, ``vertices_<t>``, ``faces_<t>``, ``times``.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.atomic import atomic_path


def write_npz(path: Path, result: AnimatedMesh | MeshSequence) -> None:
    """Write ``result`` as a fourd ``.npz`` (see the module docstring), atomically."""
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
        if result.uv is not None:
            arrays["uv"] = result.uv.astype(np.float32)
        if result.colors is not None:
            arrays["colors"] = np.round(result.colors * 255).astype(np.uint8)
    else:
        arrays = {"kind": np.array("meshes"), "times": result.times}
        for t, (vertices, faces) in enumerate(result.meshes):
            arrays[f"vertices_{t}"] = vertices.astype(np.float32)
            arrays[f"faces_{t}"] = faces.astype(np.int32)
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        np.savez(stream, **arrays)


def _rewrap(error: InputError, path) -> InputError:
    return InputError(error.problem, error.path or path)


def read_npz(path: Path) -> AnimatedMesh | MeshSequence:
    """Read a fourd ``.npz`` result written by :func:`write_npz`."""
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
            uv=arrays.get("uv"),
            colors=_colors(arrays.get("colors")),
        )
    except InputError as error:
        raise _rewrap(error, path) from None


def _colors(stored: np.ndarray | None) -> np.ndarray | None:
    """Stored colours to 0-1 floats: uint8 as fourd writes them, floats as they are."""
    if stored is None:
        return None
    if np.issubdtype(stored.dtype, np.integer):
        return stored / 255.0
    return stored


def streamed_output(path: str | os.PathLike) -> Path:
    """``path`` as the output of a streamed run, which writes a fourd ``.npz`` (one line
    naming it otherwise)."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise InputError(
            "a streamed run writes a fourd .npz (fourd.load_result and fourd.save convert it)",
            path,
        )
    return path


class _CountedWriter:
    """An open output of ``count`` frames, ``written`` of them so far, each handed to
    ``append``."""

    def __init__(self, count: int, append: Callable[[np.ndarray, np.ndarray], None]):
        self.count, self.written = int(count), 0
        self._append = append

    def check_complete(self, path) -> None:
        if self.written != self.count:
            raise InputError(f"only {self.written} of {self.count} frames were written", path)


class FrameWriter(_CountedWriter):
    """Appends frames to an open output (:func:`npz_frames`, :func:`fourd.io.pc2.pc2_frames`):
    :meth:`write` takes the next frames' vertices ``[k, N, 3]`` and observed flags ``[k, N]``."""

    def __init__(self, count: int, vertex_count: int, append: Callable[[np.ndarray, np.ndarray], None]):
        super().__init__(count, append)
        self.vertex_count = int(vertex_count)

    def write(self, vertices: np.ndarray, observed: np.ndarray) -> None:
        """Append frames (no more than the output was opened for)."""
        vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, self.vertex_count, 3)
        observed = np.asarray(observed, dtype=bool).reshape(len(vertices), self.vertex_count)
        if self.written + len(vertices) > self.count:
            raise ValueError(f"{self.written + len(vertices)} frames written to an output of {self.count}")
        self._append(vertices, observed)
        self.written += len(vertices)


@contextmanager
def npz_frames(
    path: str | os.PathLike,
    *,
    faces: np.ndarray,
    times: np.ndarray,
    rest: np.ndarray | None = None,
) -> Iterator[FrameWriter]:
    """Write an AnimatedMesh ``.npz`` (:func:`write_npz`'s layout) frame by frame: yields a
    :class:`FrameWriter` whose frames go straight to the file's ``vertices`` (memory holds
    the ``observed`` flags, one byte per vertex and frame). The file appears, complete, when
    the block ends without an error and every frame of ``times`` was written (atomically:
    an interrupted run leaves no file)."""
    faces = np.asarray(faces, dtype=np.int32).reshape(-1, 3)
    times = np.asarray(times, dtype=np.float64).ravel()
    vertex_count = int(np.max(faces)) + 1 if rest is None else len(rest)
    observed = np.zeros((len(times), vertex_count), dtype=bool)
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", allowZip64=True) as archive:
        with archive.open("vertices.npy", "w", force_zip64=True) as entry:
            header = {"descr": "<f4", "fortran_order": False, "shape": (len(times), vertex_count, 3)}
            np.lib.format.write_array_header_2_0(entry, header)
            writer = None

            def append(vertices, seen):
                observed[writer.written : writer.written + len(vertices)] = seen
                entry.write(vertices.astype("<f4").tobytes())

            writer = FrameWriter(len(times), vertex_count, append)
            yield writer
            writer.check_complete(path)
        arrays = {"kind": np.array("animated"), "faces": faces, "times": times, "observed": observed}
        if rest is not None:
            arrays["rest"] = np.asarray(rest, dtype=np.float32)
        for name, array in arrays.items():
            _write_entry(archive, name, array)


class MeshWriter(_CountedWriter):
    """Appends the frames of a :class:`~fourd.animation.MeshSequence` to an open ``.npz``
    (:func:`npz_meshes`): :meth:`write` takes the next frame's vertices ``[N, 3]`` and faces
    ``[F, 3]``."""

    def write(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        """Append one frame (no more than the output was opened for)."""
        if self.written == self.count:
            raise ValueError(f"{self.written + 1} frames written to an output of {self.count}")
        self._append(
            np.asarray(vertices, dtype="<f4").reshape(-1, 3),
            np.asarray(faces, dtype="<i4").reshape(-1, 3),
        )
        self.written += 1


@contextmanager
def npz_meshes(path: str | os.PathLike, *, times: np.ndarray) -> Iterator[MeshWriter]:
    """Write a MeshSequence ``.npz`` (:func:`write_npz`'s layout) frame by frame: yields a
    :class:`MeshWriter` whose frames go straight to the file, so memory holds none of them.
    The file appears, complete, when the block ends without an error and every frame of
    ``times`` was written (atomically: an interrupted run leaves no file)."""
    times = np.asarray(times, dtype=np.float64).ravel()
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", allowZip64=True) as archive:
        writer = None

        def append(vertices, faces):
            _write_entry(archive, f"vertices_{writer.written}", vertices)
            _write_entry(archive, f"faces_{writer.written}", faces)

        writer = MeshWriter(len(times), append)
        yield writer
        writer.check_complete(path)
        _write_entry(archive, "kind", np.array("meshes"))
        _write_entry(archive, "times", times)


def _write_entry(archive: zipfile.ZipFile, name: str, array: np.ndarray) -> None:
    """``array`` as the archive's ``name.npy`` (zip64: entries may pass 4 GB)."""
    with archive.open(f"{name}.npy", "w", force_zip64=True) as entry:
        np.lib.format.write_array(entry, array, allow_pickle=False)


class FrameReader:
    """An AnimatedMesh ``.npz`` open for reading frame by frame (:func:`npz_frame_reader`):
    ``faces``, ``times``, ``observed`` [T, N] and ``rest`` (or None) in memory, the vertices
    read on demand by :meth:`frames`."""

    def __init__(self, archive: zipfile.ZipFile, path: Path, arrays: dict):
        self._archive, self._path = archive, path
        self.faces, self.times = arrays["faces"], arrays["times"]
        self.observed, self.rest = arrays["observed"], arrays.get("rest")
        self.vertex_count = len(self.observed[0]) if len(self.observed) else 0

    def frames(self) -> Iterator[np.ndarray]:
        """Every frame's vertices, float64 [N, 3], in order, one at a time in memory."""
        with self._archive.open("vertices.npy") as entry:
            version = np.lib.format.read_magic(entry)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, fortran, dtype = read_header(entry)
            if fortran or len(shape) != 3 or shape[1:] != (self.vertex_count, 3):
                raise InputError(f"vertices of shape {list(shape)} do not match its observed flags",
                                 self._path)
            size = self.vertex_count * 3 * dtype.itemsize
            for _ in range(shape[0]):
                data = entry.read(size)
                if len(data) != size:
                    raise InputError("is truncated (vertices end early)", self._path)
                yield np.frombuffer(data, dtype=dtype).reshape(-1, 3).astype(np.float64)


@contextmanager
def npz_frame_reader(path: str | os.PathLike) -> Iterator[FrameReader]:
    """Open an AnimatedMesh ``.npz`` (:func:`write_npz`'s or :func:`npz_frames`' layout) to
    read its frames one at a time (:class:`FrameReader`): memory holds one frame of vertices
    (and the observed flags), not the whole animation."""
    path = Path(path)
    try:
        archive = zipfile.ZipFile(path)
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except (zipfile.BadZipFile, OSError) as error:
        raise InputError(f"is not a readable .npz result ({error})", path) from None
    with archive:
        names = set(archive.namelist())
        missing = [n for n in ("vertices", "faces", "times", "observed") if f"{n}.npy" not in names]
        if missing:
            raise InputError(f"is not a fourd animated mesh: no {', '.join(missing)} array", path)
        arrays = {}
        for name in ("faces", "times", "observed", "rest"):
            if f"{name}.npy" in names:
                with archive.open(f"{name}.npy") as entry:
                    arrays[name] = np.lib.format.read_array(entry, allow_pickle=False)
        yield FrameReader(archive, path, arrays)
