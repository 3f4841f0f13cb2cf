"""Blender / 3ds Max point cache (``.pc2``) with the topology as an ``.obj`` beside it.

Layout (little endian): ``b"POINTCACHE2\\0"``, int32 version (1), int32 point count, float32
start frame, float32 sample rate (frames per sample), int32 sample count, then float32
``x, y, z`` for every point of every sample. Blender's Mesh Cache modifier reads it onto the
mesh imported from the ``.obj`` (import with "keep vertex order"); an AnimatedMesh's ``uv``
goes into that ``.obj`` (``vt`` corners, which split no vertex in Blender). :func:`read_pc2_result`
reads both back as an AnimatedMesh.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.atomic import atomic_path
from fourd.io.meshfiles import read_obj, write_obj
from fourd.io.timebase import time_base

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


def one_connectivity(meshes: MeshSequence) -> AnimatedMesh:
    """Per-frame meshes as one connectivity, for formats that cannot change it: the disjoint
    union of every frame's mesh, where frame ``t`` shows its own mesh and collapses each
    other frame's mesh onto one point (that mesh's own centroid), so its triangles vanish
    (the usual way to bake changing topology into a fixed-topology cache). ``observed``
    marks each frame's own vertices. ``N`` is the sum of the frames' vertex counts.

    Examples
    --------
    >>> tri = (np.eye(3), np.array([[0, 1, 2]]))
    >>> anim = one_connectivity(MeshSequence((tri, (2 * np.eye(3), np.array([[0, 1, 2]])))))
    >>> anim.vertices.shape, anim.faces.tolist()
    ((2, 6, 3), [[0, 1, 2], [3, 4, 5]])
    >>> bool(np.ptp(anim.vertices[0, 3:], axis=0).max() == 0)  # frame 1's mesh hidden in frame 0
    True
    """
    counts = [len(v) for v, _ in meshes.meshes]
    starts = np.concatenate([[0], np.cumsum(counts)])
    faces = np.concatenate([f + starts[k] for k, (_, f) in enumerate(meshes.meshes)])
    centroids = np.stack([v.mean(axis=0) for v, _ in meshes.meshes])
    vertices = np.repeat(centroids, counts, axis=0)[None].repeat(len(meshes), axis=0)
    observed = np.zeros((len(meshes), starts[-1]), dtype=bool)
    for k, (v, _) in enumerate(meshes.meshes):
        vertices[k, starts[k]:starts[k + 1]] = v
        observed[k, starts[k]:starts[k + 1]] = True
    return AnimatedMesh(faces=faces, vertices=vertices, times=meshes.times, observed=observed)


def write_pc2(
    path: str | os.PathLike,
    anim: AnimatedMesh,
    *,
    fps: float | None = None,
    time_unit: str | None = None,
) -> Path:
    """Write ``anim`` as ``path`` (``.pc2``) plus the topology ``path.with_suffix(".obj")``.

    The header counts frames: ``times`` become frame numbers through their time base
    (``fps``, ``time_unit``: :func:`fourd.io.timebase.time_base`; frame numbers stay as they
    are, seconds are multiplied by the frame rate), the start frame is the first of them and
    the sample rate (frames per sample) their mean step (uneven steps are logged). A
    :class:`MeshSequence` (meshes whose
    connectivity changes, e.g. a shape that splits) is written through
    :func:`one_connectivity`. Returns the path of the ``.obj``.
    """
    if isinstance(anim, MeshSequence):
        log.info(
            "%s: the meshes change connectivity; the point cache holds all %d of them, each "
            "shown in its own frame and collapsed to a point in the others", path, len(anim),
        )
        anim = one_connectivity(anim)
    if not isinstance(anim, AnimatedMesh):
        raise InputError(
            f"a .pc2 point cache needs an AnimatedMesh or a MeshSequence, got {type(anim).__name__}",
            path,
        )
    path = Path(path)
    times = time_base(anim.times, fps=fps, unit=time_unit).frames(anim.times)
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
    write_obj(topology, anim.vertices[0], anim.faces, uv=anim.uv)
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


def read_pc2_result(path: str | os.PathLike) -> AnimatedMesh:
    """Read a ``.pc2`` and the ``.obj`` beside it (what :func:`write_pc2` writes) as an
    AnimatedMesh: times ``start + rate * k``; ``observed`` all True (the cache does not hold
    it). Per-frame meshes written through :func:`one_connectivity` come back as that one
    connectivity.

    Raises
    ------
    InputError
        A bad cache (:func:`read_pc2`), a missing ``.obj``, or an ``.obj`` whose vertex count
        is not the cache's.
    """
    path = Path(path)
    cache = read_pc2(path)
    topology = path.with_suffix(".obj")
    if not topology.exists():
        raise InputError(f"the topology {topology.name} is missing beside it", path)
    mesh = read_obj(topology)
    points = cache.vertices.shape[1]
    if len(mesh.vertices) != points:
        raise InputError(
            f"the point cache has {points} points but {topology.name} has {len(mesh.vertices)} vertices",
            path,
        )
    rate = cache.rate if cache.rate > 0 else 1.0  # a foreign cache may leave it 0
    times = cache.start + rate * np.arange(len(cache.vertices))
    try:
        return AnimatedMesh(mesh.faces, cache.vertices.astype(np.float64), times)
    except InputError as error:
        raise InputError(error.problem, error.path or path) from None
