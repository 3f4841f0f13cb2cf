"""Blender / 3ds Max point cache (``.pc2``) with the topology as an ``.obj`` beside it.

Layout (little endian): ``b"POINTCACHE2\\0"``, int32 version (1), int32 point count, float32
start frame, float32 sample rate (frames per sample), int32 sample count, then float32
``x, y, z`` for every point of every sample. Blender's Mesh Cache modifier reads it onto the
mesh imported from the ``.obj`` (import with "keep vertex order").
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.io.atomic import atomic_path
from fourd.io.meshfiles import write_obj

log = logging.getLogger("fourd.io.pc2")

MAGIC = b"POINTCACHE2\0"
HEADER = np.dtype(
    [
        ("magic", "S12"),
        ("version", "<i4"),
        ("points", "<i4"),
        ("start", "<f4"),
        ("rate", "<f4"),
        ("samples", "<i4"),
    ]
)


class PointCache(NamedTuple):
    """What :func:`read_pc2` found: ``vertices`` float32 [T, N, 3], ``start`` frame, ``rate``."""

    vertices: np.ndarray
    start: float
    rate: float


def write_pc2(path: str | os.PathLike, anim: AnimatedMesh) -> Path:
    """Write ``anim`` as ``path`` (``.pc2``) plus the topology ``path.with_suffix(".obj")``.

    ``times`` are read as frame numbers: the start frame is ``times[0]`` and the sample rate
    the mean time step (uneven steps are logged). Returns the path of the ``.obj``.
    """
    if not isinstance(anim, AnimatedMesh):
        raise InputError(
            f"a .pc2 point cache needs one connectivity for all frames; this is a {type(anim).__name__} "
            "(write a folder of meshes or .npz instead)",
            path,
        )
    path = Path(path)
    times = anim.times
    steps = np.diff(times)
    rate = float(steps.mean()) if len(steps) else 1.0
    if len(steps) and np.ptp(steps) > 1e-6 * max(1.0, abs(rate)):
        log.warning(
            "%s: frame times are not evenly spaced; the point cache uses their mean step %g",
            path,
            rate,
        )
    header = np.zeros(1, dtype=HEADER)
    header[0] = (MAGIC, 1, anim.vertex_count, float(times[0]), rate, anim.frame_count)
    topology = path.with_suffix(".obj")
    had_topology = topology.exists()
    write_obj(topology, anim.vertices[0], anim.faces)
    try:
        with atomic_path(path) as tmp, open(tmp, "wb") as stream:
            stream.write(header.tobytes())
            stream.write(anim.vertices.astype("<f4").tobytes())
    except BaseException:
        if not had_topology:  # leave nothing behind from a failed write
            topology.unlink(missing_ok=True)
        raise
    return topology


def read_pc2(path: str | os.PathLike) -> PointCache:
    """Read a ``.pc2`` point cache (validating its header and length)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"cannot be read ({error.strerror or error})", path) from None
    if len(data) < HEADER.itemsize or not data.startswith(MAGIC):
        raise InputError("not a POINTCACHE2 file", path)
    header = np.frombuffer(data, HEADER, 1)[0]
    points, samples = int(header["points"]), int(header["samples"])
    need = HEADER.itemsize + points * samples * 12
    if points < 0 or samples < 0 or len(data) != need:
        raise InputError(
            f"the header promises {samples} samples of {points} points but the file has {len(data)} bytes",
            path,
        )
    vertices = np.frombuffer(data, "<f4", points * samples * 3, HEADER.itemsize).reshape(
        samples, points, 3
    )
    return PointCache(vertices, float(header["start"]), float(header["rate"]))
