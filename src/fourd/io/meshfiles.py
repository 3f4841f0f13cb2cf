"""Plain-text geometry files: Wavefront OBJ (vertices and faces) and XYZ/PTS point lists."""

from __future__ import annotations

import io
import os
import re
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.errors import InputError
from fourd.geometry.parameterization import indexed_corners
from fourd.io.atomic import atomic_path

_VERTEX_LINE = re.compile(r"(?m)^v[ \t]+([^\r\n]*)")
_FACE_LINE = re.compile(r"(?m)^f[ \t]+([^\r\n]*)")
_TEXCOORD_LINE = re.compile(r"(?m)^vt[ \t]+([^\r\n]*)")
_CORNER_TAIL = re.compile(r"/[^\s]*")
_CORNER_TEXCOORD = re.compile(r"[^\s/]+/([^\s/]+)(?:/[^\s]*)?")
# a face corner without a texture index ("7", "7//3") or with a relative one ("7/-1")
_CORNER_WITHOUT_TEXCOORD = re.compile(r"(?:^|\s)(?:[^\s/]+(?=\s|$)|[^\s/]*//|[^\s/]+/-)")


def _loadtxt(text: str, dtype=np.float64, comments=None) -> np.ndarray | None:
    """A whitespace table parsed by numpy's C reader, or None when it is not a clean table
    (different widths, non-numbers, nothing at all): the caller then parses line by line for a
    precise message."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            table = np.loadtxt(io.StringIO(text), dtype=dtype, comments=comments, ndmin=2)
    except (ValueError, TypeError):
        return None
    return table if table.size else None


def read_text(path: str | os.PathLike) -> str:
    """The file's text (UTF-8, undecodable bytes replaced); InputError when it cannot be read."""
    path = Path(path)
    try:
        return path.read_bytes().decode("utf-8", errors="replace")
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a file", path) from None
    except OSError as error:
        raise InputError(f"cannot be read ({error.strerror or error})", path) from None


def _numbers(
    rows: list[list[str]], path, what: str, first_line: list[int] | None = None
) -> np.ndarray:
    """``rows`` of string tokens -> float64 [R, W]; every row must have the same width W."""
    widths = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    if len(rows) and np.any(widths != widths[0]):
        i = int(np.argmax(widths != widths[0]))
        where = f" (line {first_line[i]})" if first_line else ""
        raise InputError(
            f"{what} rows have different numbers of columns: {widths[0]} and {widths[i]}{where}",
            path,
        )
    try:
        return np.array(rows, dtype=np.float64).reshape(len(rows), -1)
    except ValueError:
        raise InputError(f"a {what} row holds a value that is not a number", path) from None


class ObjMesh(NamedTuple):
    """What :func:`read_obj` found: ``vertices`` float64 [N, 3], ``colors`` [N, 3] or None
    (from ``v x y z r g b`` lines), ``faces`` int64 [F, 3] (polygons fan-triangulated),
    ``uv`` float64 [F, 3, 2] or None (the ``vt`` of each triangle corner, when every face
    corner names one with a positive index)."""

    vertices: np.ndarray
    colors: np.ndarray | None
    faces: np.ndarray
    uv: np.ndarray | None = None


def read_obj(path: str | os.PathLike, *, faces: bool = True) -> ObjMesh:
    """Read the ``v`` (and, with ``faces=True``, ``f``) lines of a Wavefront OBJ file.

    Face corners may be written ``i``, ``i/t``, ``i//n`` or ``i/t/n``; negative (relative)
    indices are resolved against the vertices read so far.
    """
    path = Path(path)
    text = read_text(path)
    fast = _read_obj_fast(text, faces)
    if fast is not None:
        table, triangles = fast
    else:
        table, triangles = _read_obj_lines(text, faces, path)
    colors = None
    if table.shape[1] == 6:
        colors = table[:, 3:]
        colors = np.clip(colors / 255.0 if colors.size and colors.max() > 1.0 else colors, 0.0, 1.0)
    if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(table)):
        raise InputError(f"faces index vertices outside the {len(table)} vertices", path)
    uv = _corner_texcoords(text, len(triangles)) if faces and len(triangles) else None
    return ObjMesh(np.ascontiguousarray(table[:, :3]), colors, triangles, uv)


def _corner_texcoords(text: str, triangle_count: int) -> np.ndarray | None:
    """The ``vt`` of every triangle corner ``[F, 3, 2]`` (fanned as the faces are), or None
    when the file has no ``vt`` lines or a corner names none (or a relative one)."""
    lines = _TEXCOORD_LINE.findall(text)
    if not lines:
        return None
    table = _loadtxt("\n".join(lines))
    if table is None or table.shape[1] < 2:
        return None
    joined = "\n".join(_FACE_LINE.findall(text))
    if _CORNER_WITHOUT_TEXCOORD.search(joined):
        return None
    fields = _CORNER_TEXCOORD.sub(r"\1", joined)  # each corner "v/t/n" -> "t"
    uniform = _loadtxt(fields, dtype=np.int64)
    if uniform is not None:
        polygons = [uniform]
    else:  # mixed polygon sizes: one array per line
        try:
            polygons = [np.array(line.split(), dtype=np.int64)[None] for line in fields.splitlines()]
        except ValueError:
            return None
    corners = np.concatenate([_fan(p) for p in polygons])
    if len(corners) != triangle_count or corners.min() < 1 or corners.max() > len(table):
        return None
    return table[:, :2][corners - 1]


def _fan(polygons: np.ndarray) -> np.ndarray:
    """Polygons ``[P, n]`` (corner indices) fanned into triangles ``[P * (n - 2), 3]``, each
    polygon's triangles together, in order."""
    fan = [
        np.stack([polygons[:, 0], polygons[:, i], polygons[:, i + 1]], axis=1)
        for i in range(1, polygons.shape[1] - 1)
    ]
    return np.stack(fan, axis=1).reshape(-1, 3)


def _read_obj_fast(text: str, faces: bool):
    """Vectorised OBJ parse for the common case (uniform ``v`` rows, uniform positive faces)."""
    vertex_lines = _VERTEX_LINE.findall(text)
    table = _loadtxt("\n".join(vertex_lines)) if vertex_lines else np.zeros((0, 3))
    if table is None or table.shape[1] < 3 or table.shape[1] > 7:
        return None
    if table.shape[1] in (6, 7):  # x y z [w] r g b
        table = np.concatenate([table[:, :3], table[:, -3:]], axis=1)
    elif table.shape[1] == 4:  # x y z w
        table = table[:, :3]
    triangles = np.zeros((0, 3), dtype=np.int64)
    face_lines = _FACE_LINE.findall(text) if faces else []
    if face_lines:
        corners = _loadtxt(_CORNER_TAIL.sub("", "\n".join(face_lines)), dtype=np.int64)
        if corners is None or corners.shape[1] < 3 or corners.min() < 1:
            return None  # relative indices, mixed polygon sizes, or malformed: line by line
        triangles = _fan(corners - 1)
    return table, triangles


def _read_obj_lines(text: str, faces: bool, path):
    vertex_rows, face_rows = [], []
    seen = 0
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith(("v ", "v\t")):
            words = line.split()[1:]
            if len(words) < 3:
                raise InputError(
                    f"line {number}: a vertex needs 3 coordinates, found {len(words)}", path
                )
            vertex_rows.append(words[:3] if len(words) not in (6, 7) else words[:3] + words[-3:])
            seen += 1
        elif faces and line.startswith(("f ", "f\t")):
            try:
                corners = [int(word.split("/")[0]) for word in line.split()[1:]]
            except ValueError:
                raise InputError(f"line {number}: malformed face {line.strip()!r}", path) from None
            if len(corners) < 3:
                raise InputError(f"line {number}: a face needs at least 3 corners", path)
            corners = [c - 1 if c > 0 else seen + c for c in corners]
            face_rows.extend(
                [corners[0], corners[i], corners[i + 1]] for i in range(1, len(corners) - 1)
            )
    widths = {len(r) for r in vertex_rows}
    if len(widths) > 1:  # some lines with colours, some without: keep the coordinates
        vertex_rows = [r[:3] for r in vertex_rows]
    table = _numbers(vertex_rows, path, "vertex") if vertex_rows else np.zeros((0, 3))
    return table, np.array(face_rows, dtype=np.int64).reshape(-1, 3)


def write_obj(
    path: str | os.PathLike,
    vertices: np.ndarray,
    faces: np.ndarray | None = None,
    *,
    uv: np.ndarray | None = None,
    colors: np.ndarray | None = None,
) -> None:
    """Write ``v`` and ``f`` lines (1-based, vertex order kept) atomically.

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3], optional
    uv : array [F, 3, 2], optional
        Per-corner texture coordinates: ``vt`` lines (one per distinct UV) and ``f v/vt``
        corners.
    colors : array [N, 3], optional
        In [0, 1], written as they are (sRGB-encoded as the input gave them) on the ``v``
        lines: ``v x y z r g b``, the extension Blender, MeshLab and fourd's reader know.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = (
        np.zeros((0, 3), dtype=np.int64)
        if faces is None
        else np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    )
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii") as stream:
        stream.write("# written by fourd\n")
        if colors is not None:
            table = np.concatenate([vertices, np.clip(np.asarray(colors, float), 0, 1).reshape(-1, 3)], axis=1)
            stream.write("v %.9g %.9g %.9g %.6g %.6g %.6g\n" * len(table) % tuple(table.ravel()))
        else:
            stream.write("v %.9g %.9g %.9g\n" * len(vertices) % tuple(vertices.ravel()))
        if uv is not None and len(faces):
            values, indices = indexed_corners(uv)
            stream.write("vt %.9g %.9g\n" * len(values) % tuple(values.ravel()))
            corners = np.stack([faces.ravel() + 1, indices + 1], axis=1).reshape(-1, 6)
            stream.write("f %d/%d %d/%d %d/%d\n" * len(corners) % tuple(corners.ravel()))
        elif len(faces):
            stream.write("f %d %d %d\n" * len(faces) % tuple((faces + 1).ravel()))


class PointTable(NamedTuple):
    """What :func:`read_xyz` found: ``points`` [P, 3], ``normals`` [P, 3] or None, ``colors``
    [P, 3] or None, and ``columns`` (the width of the table in the file)."""

    points: np.ndarray
    normals: np.ndarray | None
    colors: np.ndarray | None
    columns: int


def read_xyz(path: str | os.PathLike) -> PointTable:
    """Read an XYZ or PTS text point list.

    Columns: 3 (``x y z``) or 6 (``x y z nx ny nz``); a ``.pts`` file may also have 4
    (``x y z intensity``) or 7 (``x y z intensity r g b``, colours 0-255) columns and a first
    line holding the point count. Blank lines and lines starting with ``#`` or ``//`` are skipped.
    """
    path = Path(path)
    text = read_text(path)
    pts = path.suffix.lower() == ".pts"
    table = _loadtxt(text, comments="#")
    declared = None
    if table is None and pts:  # maybe a point-count first line
        head, _, rest = text.lstrip().partition("\n")
        if head.strip().isdigit():
            table = _loadtxt(rest, comments="#")
            declared = int(head.strip())
    if table is not None and (declared is None or declared == len(table)):
        return _point_table(table, pts, path)
    return _read_xyz_lines(text, pts, path)


def _read_xyz_lines(text: str, pts: bool, path) -> PointTable:
    rows, lines = [], []
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.replace(",", " ").split()
        if not words or words[0].startswith(("#", "//")):
            continue
        rows.append(words)
        lines.append(number)
    declared = None
    if rows and len(rows[0]) == 1:
        if not rows[0][0].isdigit():
            raise InputError(
                f"line {lines[0]}: expected a point count or x y z, found {rows[0][0]!r}", path
            )
        declared = int(rows[0][0])
        rows, lines = rows[1:], lines[1:]
    table = _numbers(rows, path, "point", lines) if rows else np.zeros((0, 3))
    if declared is not None and declared != len(table):
        raise InputError(
            f"the first line promises {declared} points but {len(table)} rows follow", path
        )
    return _point_table(table, pts, path)


def _point_table(table: np.ndarray, pts: bool, path) -> PointTable:
    width = table.shape[1]
    allowed = (3, 4, 6, 7) if pts else (3, 6)
    if width not in allowed:
        expected = (
            "3 (x y z), 4 (x y z intensity), 6 (x y z nx ny nz) or 7 (x y z intensity r g b)"
            if pts
            else "3 (x y z) or 6 (x y z nx ny nz)"
        )
        raise InputError(f"rows have {width} columns; expected {expected}", path)
    normals = table[:, 3:6] if width == 6 else None
    colors = np.clip(table[:, 4:7] / 255.0, 0.0, 1.0) if width == 7 else None
    return PointTable(np.ascontiguousarray(table[:, :3]), normals, colors, width)


def write_xyz(
    path: str | os.PathLike, points: np.ndarray, normals: np.ndarray | None = None
) -> None:
    """Write ``x y z [nx ny nz]`` rows atomically."""
    table = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if normals is not None:
        table = np.concatenate(
            [table, np.asarray(normals, dtype=np.float64).reshape(-1, 3)], axis=1
        )
    line = " ".join(["%.9g"] * table.shape[1]) + "\n"
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii") as stream:
        stream.write(line * len(table) % tuple(table.ravel()))
