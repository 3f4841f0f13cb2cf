"""PLY (Stanford polygon file) reading and writing with numpy only.

Binary bodies are decoded with :func:`numpy.frombuffer` and a structured dtype (one call per
element without list properties), so a 100k-point scan reads in milliseconds. ASCII bodies are
split into tokens once and converted in bulk. Face lists with a constant length (the usual
triangles) take a vectorised path too; variable-length lists fall back to a per-row loop.

References
----------
G. Turk, "The PLY polygon file format", 1994 (http://paulbourke.net/dataformats/ply/).
"""

from __future__ import annotations

import logging
import os
import re
import struct
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.errors import InputError
from fourd.io.atomic import atomic_path

log = logging.getLogger("fourd.io.ply")

#: PLY scalar type names (both the classic and the sized spellings) -> numpy type codes.
PLY_TYPES: dict[str, str] = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4",
    "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}  # fmt: skip

_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))
_COLOR_NAMES = (
    ("red", "green", "blue"),
    ("r", "g", "b"),
    ("diffuse_red", "diffuse_green", "diffuse_blue"),
)
_FACE_LISTS = ("vertex_indices", "vertex_index")
_END_HEADER = re.compile(rb"(?m)^end_header[ \t]*\r?$")


class PlyMesh(NamedTuple):
    """What :func:`read_ply` found.

    Attributes
    ----------
    vertices : ndarray, float64 [N, 3]
    normals : ndarray, float64 [N, 3] or None
        As stored (not normalised).
    colors : ndarray, float64 [N, 3] or None
        In [0, 1] (integer channels are divided by their type's maximum).
    faces : ndarray, int64 [F, 3]
        Triangles (polygons fan-triangulated); empty when the file has none or when read with
        ``faces=False``.
    properties : dict of str -> ndarray [N]
        Every scalar vertex property as stored (including x, y, z and any extras).
    """

    vertices: np.ndarray
    normals: np.ndarray | None
    colors: np.ndarray | None
    faces: np.ndarray
    properties: dict


class _Property(NamedTuple):
    name: str
    code: str  # numpy type code of the value (or of the list items)
    count_code: str | None = None  # numpy type code of the list length; None for scalars


class _Element(NamedTuple):
    name: str
    count: int
    properties: list

    @property
    def has_list(self) -> bool:
        return any(p.count_code is not None for p in self.properties)


def _parse_header(data: bytes, path) -> tuple[str | None, list[_Element], int]:
    """Return ``(byte order or None for ascii, elements, offset of the body)``."""
    if not data.startswith(b"ply"):
        raise InputError("not a PLY file (it does not start with 'ply')", path)
    match = _END_HEADER.search(data)
    if match is None:
        raise InputError("malformed PLY header: no 'end_header' line", path)
    end = match.start()
    body = data.find(b"\n", end)
    body = len(data) if body < 0 else body + 1
    try:
        text = data[:end].decode("ascii")
    except UnicodeDecodeError:
        raise InputError("malformed PLY header: it is not ASCII text", path) from None
    order = "unset"
    elements: list[_Element] = []
    for number, line in enumerate(text.splitlines()[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        keyword = words[0]
        if keyword == "format":
            if len(words) != 3 or words[1] not in _FORMATS:
                raise InputError(f"malformed PLY header line {number}: {line.strip()!r}", path)
            order = _FORMATS[words[1]]
        elif keyword == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise InputError(f"malformed PLY header line {number}: {line.strip()!r}", path)
            elements.append(_Element(words[1], int(words[2]), []))
        elif keyword == "property":
            if not elements:
                raise InputError(f"PLY header line {number}: a property before any element", path)
            if len(words) == 3 and words[1] in PLY_TYPES:
                prop = _Property(words[2], PLY_TYPES[words[1]])
            elif (
                len(words) == 5
                and words[1] == "list"
                and words[2] in PLY_TYPES
                and words[3] in PLY_TYPES
                and PLY_TYPES[words[2]][0] in "iu"
            ):
                prop = _Property(words[4], PLY_TYPES[words[3]], PLY_TYPES[words[2]])
            else:
                raise InputError(f"malformed PLY header line {number}: {line.strip()!r}", path)
            if any(p.name == prop.name for p in elements[-1].properties):
                raise InputError(f"PLY header: property {prop.name!r} is declared twice", path)
            elements[-1].properties.append(prop)
        else:
            raise InputError(f"malformed PLY header line {number}: {line.strip()!r}", path)
    if order == "unset":
        raise InputError("malformed PLY header: no 'format' line", path)
    return order, elements, body


def _truncated(element: _Element, path) -> InputError:
    return InputError(
        f"truncated PLY: the header promises {element.count} {element.name} rows but the file ends early",
        path,
    )


# ---------------------------------------------------------------------------------- binary


def _binary_scalar(data, offset, element, order, path):
    dtype = np.dtype([(p.name, order + p.code) for p in element.properties])
    need = dtype.itemsize * element.count
    if len(data) - offset < need:
        raise _truncated(element, path)
    rows = np.frombuffer(data, dtype=dtype, count=element.count, offset=offset)
    return {p.name: rows[p.name] for p in element.properties}, offset + need


def _binary_list(data, offset, element, order, path):
    """An element with list properties: vectorised when every row has the same list lengths."""
    if element.count == 0:
        return {p.name: np.zeros((0, 0)) for p in element.properties}, offset
    # lengths of the lists in the first row give a candidate fixed-size row layout
    fields, cursor = [], offset
    for p in element.properties:
        if p.count_code is None:
            fields.append((p.name, order + p.code))
            cursor += np.dtype(p.code).itemsize
            continue
        size = np.dtype(p.count_code).itemsize
        if len(data) < cursor + size:
            raise _truncated(element, path)
        length = int(np.frombuffer(data, order + p.count_code, 1, cursor)[0])
        fields.append((f"__count_{p.name}", order + p.count_code))
        fields.append((p.name, order + p.code, (length,)))
        cursor += size + length * np.dtype(p.code).itemsize
    dtype = np.dtype(fields)
    if len(data) - offset >= dtype.itemsize * element.count:
        rows = np.frombuffer(data, dtype=dtype, count=element.count, offset=offset)
        fixed = all(
            np.all(rows[f"__count_{p.name}"] == rows.dtype[p.name].shape[0])
            for p in element.properties
            if p.count_code is not None
        )
        if fixed:
            return {
                p.name: rows[p.name] for p in element.properties
            }, offset + dtype.itemsize * element.count
    return _binary_list_rows(data, offset, element, order, path)


def _binary_list_rows(data, offset, element, order, path):
    """Row-by-row fallback for variable-length lists (e.g. mixed triangles and quads)."""
    out = {p.name: [] for p in element.properties}
    formats = {}
    for p in element.properties:
        counter = (
            None if p.count_code is None else struct.Struct(order + np.dtype(p.count_code).char)
        )
        formats[p.name] = (struct.Struct(order + np.dtype(p.code).char), counter)
    try:
        for _ in range(element.count):
            for p in element.properties:
                value, counter = formats[p.name]
                if counter is None:
                    out[p.name].append(value.unpack_from(data, offset)[0])
                    offset += value.size
                else:
                    length = counter.unpack_from(data, offset)[0]
                    offset += counter.size
                    if length < 0 or offset + length * value.size > len(data):
                        raise struct.error("past the end")
                    out[p.name].append(np.frombuffer(data, order + p.code, length, offset))
                    offset += length * value.size
    except struct.error:
        raise _truncated(element, path) from None
    result = {}
    for p in element.properties:
        result[p.name] = np.asarray(out[p.name]) if p.count_code is None else out[p.name]
    return result, offset


def _min_row_bytes(element: _Element) -> int:
    return sum(np.dtype(p.count_code or p.code).itemsize for p in element.properties)


# ----------------------------------------------------------------------------------- ascii


def _ascii_element(tokens, position, element, path):
    names = [p.name for p in element.properties]
    if not element.has_list:
        width = len(names)
        stop = position + width * element.count
        if stop > len(tokens):
            raise _truncated(element, path)
        try:
            values = np.array(tokens[position:stop], dtype=np.float64).reshape(element.count, width)
        except ValueError:
            raise InputError(
                f"malformed PLY: a {element.name} row holds a value that is not a number", path
            ) from None
        return {name: values[:, i] for i, name in enumerate(names)}, stop
    # fast path: every row has the lengths of the first row
    try:
        if element.count == 0:
            return {name: np.zeros((0, 0)) for name in names}, position
        layout, cursor = [], position
        for p in element.properties:
            if p.count_code is None:
                layout.append((p.name, None))
                cursor += 1
            else:
                length = int(tokens[cursor])
                layout.append((p.name, length))
                cursor += 1 + length
        width = cursor - position
        stop = position + width * element.count
        if stop <= len(tokens):
            block = np.array(tokens[position:stop], dtype=np.float64).reshape(element.count, width)
            result, column, fixed = {}, 0, True
            for name, length in layout:
                if length is None:
                    result[name] = block[:, column]
                    column += 1
                else:
                    fixed &= bool(np.all(block[:, column] == length))
                    result[name] = block[:, column + 1 : column + 1 + length]
                    column += 1 + length
            if fixed:
                return result, stop
        # slow path: row by row
        out = {name: [] for name in names}
        for _ in range(element.count):
            for p in element.properties:
                if p.count_code is None:
                    out[p.name].append(float(tokens[position]))
                    position += 1
                else:
                    length = int(tokens[position])
                    if length < 0 or position + 1 + length > len(tokens):
                        raise IndexError
                    out[p.name].append(
                        np.array(tokens[position + 1 : position + 1 + length], dtype=np.float64)
                    )
                    position += 1 + length
    except IndexError:
        raise _truncated(element, path) from None
    except ValueError:
        raise InputError(
            f"malformed PLY: a {element.name} row holds a value that is not a number", path
        ) from None
    return {
        p.name: (np.asarray(out[p.name]) if p.count_code is None else out[p.name])
        for p in element.properties
    }, position


# ---------------------------------------------------------------------------------- public


def _triangulate(lists, path) -> np.ndarray:
    """Fan-triangulate polygon index lists ([F, k] array or a list of 1-D arrays)."""
    if isinstance(lists, np.ndarray) and lists.ndim == 2:
        k = lists.shape[1]
        if len(lists) == 0 or k < 3:
            if len(lists) and k:
                raise InputError(f"PLY faces with {k} corners (need at least 3)", path)
            return np.zeros((0, 3), dtype=np.int64)
        polys = lists.astype(np.int64)
        fan = [
            np.stack([polys[:, 0], polys[:, i], polys[:, i + 1]], axis=1) for i in range(1, k - 1)
        ]
        return np.stack(fan, axis=1).reshape(-1, 3)  # each polygon's triangles stay together
    groups: dict[int, list] = {}
    for poly in lists:
        groups.setdefault(len(poly), []).append(poly)
    if any(k < 3 for k in groups):
        raise InputError("PLY faces with fewer than 3 corners", path)
    parts = [_triangulate(np.asarray(polys), path) for _, polys in sorted(groups.items())]
    return np.concatenate(parts, axis=0) if parts else np.zeros((0, 3), dtype=np.int64)


def _columns(props: dict, choices) -> tuple[np.ndarray | None, str | None]:
    for names in choices:
        if all(n in props for n in names):
            return np.stack([props[n] for n in names], axis=1), props[names[0]].dtype
    return None, None


def read_ply(path: str | os.PathLike, *, faces: bool = True) -> PlyMesh:
    """Read a PLY file (ASCII, binary little or big endian; any scalar types).

    Parameters
    ----------
    path : path-like
    faces : bool
        Read the face element too (``False`` skips it: faster for point clouds; the file's
        length is still checked against what the header promises for fixed-size rows).

    Returns
    -------
    PlyMesh

    Raises
    ------
    InputError
        Missing or unreadable file, malformed header, a body shorter than the header promises,
        non-numeric values, no ``vertex`` element or no ``x, y, z`` properties.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError("does not exist", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a PLY file", path) from None
    except OSError as error:
        raise InputError(f"cannot be read ({error.strerror or error})", path) from None
    try:
        return _decode(data, path, faces)
    except InputError:
        raise
    except (ValueError, TypeError, IndexError, OverflowError, struct.error, MemoryError) as error:
        raise InputError(f"malformed PLY ({type(error).__name__}: {error})", path) from None


def _decode(data: bytes, path: Path, faces: bool) -> PlyMesh:
    order, elements, offset = _parse_header(data, path)
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise InputError("the PLY header declares no 'vertex' element", path)
    vertex_index = names.index("vertex")
    found: dict[str, dict] = {}
    if order is None:
        tokens = data[offset:].split()
        position = 0
        for i, element in enumerate(elements):
            if i > vertex_index and not faces:
                break
            found[element.name], position = _ascii_element(tokens, position, element, path)
    else:
        for i, element in enumerate(elements):
            if i > vertex_index and not faces:
                minimum = sum(_min_row_bytes(e) * e.count for e in elements[i:])
                if len(data) - offset < minimum:
                    raise _truncated(element, path)
                break
            if element.has_list:
                found[element.name], offset = _binary_list(data, offset, element, order, path)
            else:
                found[element.name], offset = _binary_scalar(data, offset, element, order, path)
    vertex = {k: v for k, v in found["vertex"].items() if isinstance(v, np.ndarray) and v.ndim == 1}
    points, _ = _columns(vertex, (("x", "y", "z"),))
    if points is None:
        raise InputError("the PLY vertex element has no x, y, z properties", path)
    points = points.astype(np.float64)
    normals, _ = _columns(vertex, _NORMAL_NAMES)
    normals = None if normals is None else normals.astype(np.float64)
    colors, color_type = _columns(vertex, _COLOR_NAMES)
    if colors is not None:
        colors = _unit_colors(colors, color_type)
    triangles = np.zeros((0, 3), dtype=np.int64)
    if faces and "face" in found:
        face = found["face"]
        key = next((k for k in _FACE_LISTS if k in face), None)
        if key is not None:
            triangles = _triangulate(face[key], path)
            if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(points)):
                raise InputError(
                    f"PLY faces index vertices up to {int(triangles.max())} but there are {len(points)}",
                    path,
                )
    properties = {k: v for k, v in vertex.items()}
    return PlyMesh(points, normals, colors, triangles, properties)


def _unit_colors(colors: np.ndarray, dtype) -> np.ndarray:
    dtype = np.dtype(dtype)
    if np.issubdtype(dtype, np.integer):
        scaled = colors.astype(np.float64) / float(np.iinfo(dtype).max)
    else:
        scaled = colors.astype(np.float64)
        if scaled.size and np.nanmax(scaled) > 1.0:
            scaled = scaled / 255.0
    return np.clip(scaled, 0.0, 1.0)


def write_ply(
    path: str | os.PathLike,
    vertices: np.ndarray,
    *,
    normals: np.ndarray | None = None,
    colors: np.ndarray | None = None,
    faces: np.ndarray | None = None,
    binary: bool = True,
    big_endian: bool = False,
    double: bool = False,
) -> None:
    """Write a PLY file atomically (temporary name, then rename).

    Parameters
    ----------
    path : path-like
    vertices : array [N, 3]
    normals : array [N, 3], optional
        Stored as ``nx, ny, nz``.
    colors : array [N, 3], optional
        In [0, 1]; stored as ``uchar red, green, blue``.
    faces : int array [F, 3], optional
        Stored as ``list uchar int vertex_indices``.
    binary : bool
        Binary body (default) or ASCII.
    big_endian : bool
        Binary byte order (little endian by default).
    double : bool
        Store coordinates and normals as ``double`` instead of ``float``.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    count = len(vertices)
    real = "double" if double else "float"
    order = ">" if big_endian else "<"
    fields = [
        ("x", "f8" if double else "f4"),
        ("y", "f8" if double else "f4"),
        ("z", "f8" if double else "f4"),
    ]
    columns = [vertices]
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64).reshape(count, 3)
        fields += [(n, fields[0][1]) for n in ("nx", "ny", "nz")]
        columns.append(normals)
    if colors is not None:
        colors = np.asarray(colors, dtype=np.float64).reshape(count, 3)
        fields += [(c, "u1") for c in ("red", "green", "blue")]
        columns.append(np.clip(np.round(colors * 255.0), 0, 255))
    faces = np.zeros((0, 3), dtype=np.int64) if faces is None else np.asarray(faces).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= count):
        raise InputError(
            f"faces index vertices up to {int(faces.max())} but there are {count}", path
        )
    fmt = ("binary_big_endian" if big_endian else "binary_little_endian") if binary else "ascii"
    header = ["ply", f"format {fmt} 1.0", "comment written by fourd", f"element vertex {count}"]
    header += [f"property {real if code[0] == 'f' else 'uchar'} {name}" for name, code in fields]
    if len(faces):
        header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    header_bytes = ("\n".join(header) + "\nend_header\n").encode("ascii")
    table = np.concatenate(columns, axis=1) if len(columns) > 1 else vertices
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        stream.write(header_bytes)
        if binary:
            rows = np.empty(count, dtype=[(name, order + code) for name, code in fields])
            for i, (name, _) in enumerate(fields):
                rows[name] = table[:, i]
            stream.write(rows.tobytes())
            if len(faces):
                tri = np.empty(len(faces), dtype=[("n", "u1"), ("v", order + "i4", (3,))])
                tri["n"] = 3
                tri["v"] = faces
                stream.write(tri.tobytes())
        else:
            precision = "%.17g" if double else "%.9g"
            formats = [precision if code[0] == "f" else "%d" for _, code in fields]
            line = " ".join(formats) + "\n"
            stream.write((line * count % tuple(table.ravel())).encode("ascii"))
            if len(faces):
                stream.write(("3 %d %d %d\n" * len(faces) % tuple(faces.ravel())).encode("ascii"))
