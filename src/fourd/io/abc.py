"""Alembic (``.abc``) export and import through the ``alembic3d`` wheel (an optional extra:
``pip install 'fourd[abc]'``; its API is PyAlembic's).

Layout of a written archive (Ogawa)::

    /fourd              OXform (identity)
      /fourdShape       OPolyMesh: one sample per frame, at the frame's time in seconds
                        P        positions, float32 [N, 3] (Y up: Z-up data is rotated)
                        N        vertex normals, float32 [N, 3] (kVertexScope), per frame
                        faceIndices / faceCounts (3 per face), clockwise as Alembic wants
                        uv       per-corner texture coordinates (kFacevaryingScope, indexed),
                                 when the AnimatedMesh has ``uv``
                        .arbGeomParams/observed   float [N] per frame: 1 where the vertex had
                                                  data (AnimatedMesh only)
                        .arbGeomParams/Cd         colour [N] per frame (C3f, kVertexScope,
                                                  linear), when the AnimatedMesh has ``colors``
                        .userProperties/fourdTimes  the result's own times (frame numbers or
                                                  seconds, as in the input)

An :class:`~fourd.animation.AnimatedMesh` keeps one topology (``kHomogenousTopology``: every
reader sees a deforming mesh); a :class:`~fourd.animation.MeshSequence` writes each frame's
own faces (``kHeterogenousTopology``, which Blender and Houdini play as a changing mesh). Frame times go into a uniform ``TimeSampling`` when evenly spaced, an acyclic one
otherwise (see :mod:`fourd.io.timebase`); the archive records the frame rate as its DCC FPS
hint. Alembic winds polygons clockwise (right-handed Y up), fourd counter-clockwise: the
indices are reversed on writing and again on reading.

References
----------
Alembic 1.8, ``AbcGeom::OPolyMeshSchema``; Maya's AbcExport documentation ("polygon winding
order in Alembic is clockwise").
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.geometry.parameterization import indexed_corners
from fourd.io.atomic import atomic_path
from fourd.io.axes import check_up, z_up_to_y_up
from fourd.io.colorspace import linear_to_srgb, srgb_to_linear
from fourd.io.timebase import time_base

#: Names of the transform and the mesh in a written archive.
XFORM_NAME = "fourd"
MESH_NAME = "fourdShape"
#: The user property holding the result's own times.
TIMES_PROPERTY = "fourdTimes"
#: Evenly spaced times (relative spread of the steps under this) get a uniform time sampling.
UNIFORM_TOLERANCE = 1e-6

__all__ = ["read_abc", "write_abc"]


def _alembic(path, doing: str = "writing"):
    """``(Abc, AbcCoreAbstract, AbcGeom, imath)`` or InputError saying what to install."""
    try:
        import imath
        from alembic3d import Abc, AbcCoreAbstract, AbcGeom
    except ImportError:
        raise InputError(
            f"{doing} .abc needs the alembic3d package: pip install 'fourd[abc]'", path
        ) from None
    return Abc, AbcCoreAbstract, AbcGeom, imath


def _time_sampling(AbcCoreAbstract, seconds: np.ndarray, fps: float):
    steps = np.diff(seconds)
    if not len(steps):
        return AbcCoreAbstract.TimeSampling(1.0 / fps, float(seconds[0]))
    mean = float(steps.mean())
    if np.ptp(steps) <= UNIFORM_TOLERANCE * mean:
        return AbcCoreAbstract.TimeSampling(mean, float(seconds[0]))
    vector = AbcCoreAbstract.TimeVector()
    for value in seconds.tolist():
        vector.append(value)
    return AbcCoreAbstract.TimeSampling(
        AbcCoreAbstract.TimeSamplingType(AbcCoreAbstract.AcyclicFlag.kAcyclic), vector
    )


def write_abc(
    path: str | os.PathLike,
    result: AnimatedMesh | MeshSequence,
    *,
    fps: float | None = None,
    time_unit: str | None = None,
    up: str = "y",
) -> None:
    """Write ``result`` as an Alembic archive (see the module docstring), atomically.

    Parameters
    ----------
    path : path-like
        Ends in ``.abc``.
    result : AnimatedMesh or MeshSequence
        A result without faces is written as a polygon mesh without faces (its points).
    fps, time_unit : optional
        The time base of ``result.times`` (:func:`fourd.io.timebase.time_base`): sample times
        are the times in seconds.
    up : {"y", "z"}
        The data's up axis; Z-up data is rotated to Alembic's Y up (``(x, y, z) -> (x, z,
        -y)``).

    Raises
    ------
    InputError
        ``alembic3d`` not installed (saying ``pip install 'fourd[abc]'``), a suffix other than
        ``.abc``, a bad ``fps``, ``time_unit`` or ``up``.
    """
    if not os.fspath(path).lower().endswith(".abc"):
        raise InputError("an Alembic file must end in .abc", path)
    up = check_up(up)
    if isinstance(result, AnimatedMesh):
        frames = [(result.vertices[k], result.faces) for k in range(result.frame_count)]
    elif isinstance(result, MeshSequence):
        frames = list(result.meshes)
    else:
        raise InputError(f"cannot write a {type(result).__name__} as .abc", path)
    Abc, AbcCoreAbstract, AbcGeom, imath = _alembic(path)
    base = time_base(result.times, fps=fps, unit=time_unit)
    seconds = base.seconds(result.times)
    from fourd import __version__

    with atomic_path(path, suffix=".abc") as tmp:
        with contextlib.suppress(OSError):
            os.remove(tmp)  # the archive creates its own file
        archive = Abc.CreateArchiveWithInfo(
            str(tmp), float(base.fps), f"fourd {__version__}", "animated mesh from 4D scans"
        )
        index = archive.addTimeSampling(_time_sampling(AbcCoreAbstract, seconds, base.fps))
        xform = AbcGeom.OXform(archive.getTop(), XFORM_NAME)
        mesh = AbcGeom.OPolyMesh(xform, MESH_NAME, index)
        schema = mesh.getSchema()
        times = Abc.ODoubleArrayProperty(schema.getUserProperties(), TIMES_PROPERTY)
        times.setValue(imath.DoubleArrayFromBuffer(np.ascontiguousarray(result.times, np.float64)))
        observed = colors = uvs = None
        if isinstance(result, AnimatedMesh):
            observed = AbcGeom.OFloatGeomParam(
                schema.getArbGeomParams(), "observed", False,
                AbcGeom.GeometryScope.kVertexScope, 1, index,
            )
            if result.colors is not None:
                colors = AbcGeom.OC3fGeomParam(
                    schema.getArbGeomParams(), "Cd", False,
                    AbcGeom.GeometryScope.kVertexScope, 1, index,
                )
            if result.uv is not None and len(result.faces):
                values, indices = indexed_corners(result.uv)
                indices = indices.reshape(-1, 3)[:, ::-1].ravel()  # clockwise, like the faces
                uvs = AbcGeom.OV2fGeomParamSample(
                    imath.V2fArrayFromBuffer(np.ascontiguousarray(values, np.float32)),
                    imath.UnsignedIntArray(imath.DoubleArrayFromBuffer(indices.astype(np.float64))),
                    AbcGeom.GeometryScope.kFacevaryingScope,
                )
        vertex = AbcGeom.GeometryScope.kVertexScope
        with_normals = any(len(faces) for _, faces in frames)
        for k, (vertices, faces) in enumerate(frames):
            if up == "z":
                vertices = z_up_to_y_up(vertices)
            points = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
            sample = AbcGeom.OPolyMeshSchemaSample(
                imath.V3fArrayFromBuffer(points),
                imath.IntArrayFromBuffer(np.ascontiguousarray(faces[:, ::-1], np.int32).ravel()),
                imath.IntArrayFromBuffer(np.full(len(faces), 3, dtype=np.int32)),
            )
            if with_normals:
                normals = vertex_normals(vertices, faces).astype(np.float32)
                sample.setNormals(
                    AbcGeom.ON3fGeomParamSample(imath.V3fArrayFromBuffer(normals), vertex)
                )
            if uvs is not None:
                sample.setUVs(uvs)
            schema.set(sample)
            if colors is not None:
                linear = np.ascontiguousarray(srgb_to_linear(result.colors[k]), np.float32)
                colors.set(AbcGeom.OC3fGeomParamSample(
                    imath.C3fArray(imath.V3fArrayFromBuffer(linear)), vertex
                ))
            if observed is not None:
                flags = np.ascontiguousarray(result.observed[k], dtype=np.float32)
                observed.set(
                    AbcGeom.OFloatGeomParamSample(imath.FloatArrayFromBuffer(flags), vertex)
                )
        # The archive is written when its last reference goes.
        del uvs, colors, observed, times, schema, mesh, xform, archive


def _find_mesh(Abc, AbcGeom, top, path):
    """The first polygon mesh under ``top`` (depth first)."""
    stack = [top]
    while stack:
        node = stack.pop()
        for i in reversed(range(node.getNumChildren())):
            child = node.getChild(i)
            if AbcGeom.IPolyMesh.matches(child.getHeader()):
                return AbcGeom.IPolyMesh(node, child.getName())
            stack.append(child)
    raise InputError("holds no polygon mesh", path)


def read_abc(path: str | os.PathLike) -> AnimatedMesh | MeshSequence:
    """Read the first polygon mesh of an Alembic archive (every sample, in order).

    Returns an AnimatedMesh when every sample has the same faces and vertex count (times from
    the ``fourdTimes`` property when fourd wrote the file, else the sample times in seconds;
    ``observed`` from the ``observed`` attribute, ``uv`` from the face-varying UVs of the first
    sample of an all-triangle mesh, ``colors`` from a vertex-scope ``Cd`` (linear, returned
    sRGB-encoded), each when present), else a MeshSequence. Faces
    with more than three corners are fanned into triangles; positions are as stored (a
    transform above the mesh is not applied).

    Raises
    ------
    InputError
        ``alembic3d`` not installed, a missing or unreadable file, an archive without a mesh.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    Abc, _, AbcGeom, _ = _alembic(path, "reading")
    try:
        archive = Abc.IArchive(str(path))
    except Exception as error:  # the library's own exception types are not exported
        raise InputError(f"is not a readable Alembic archive ({error})", path) from None
    mesh = _find_mesh(Abc, AbcGeom, archive.getTop(), path)
    schema = mesh.getSchema()
    sampling = schema.getTimeSampling()
    count = schema.getNumSamples()
    if count == 0:
        raise InputError("its mesh has no samples", path)
    seconds = np.array([sampling.getSampleTime(k) for k in range(count)], dtype=np.float64)
    # (ISampleSelector(int) resolves to the time overload in these bindings: select by time)
    selectors = [Abc.ISampleSelector(float(t)) for t in seconds]
    meshes = []
    for selector in selectors:
        sample = schema.getValue(selector)
        vertices = np.array(sample.getPositions(), dtype=np.float64).reshape(-1, 3)
        indices = np.array(sample.getFaceIndices(), dtype=np.int64)
        counts = np.array(sample.getFaceCounts(), dtype=np.int64)
        meshes.append((vertices, _triangles(indices, counts, path)))
    times = _stored_times(Abc, schema, count)
    if times is None:
        times = seconds
    first_v, first_f = meshes[0]
    shared = all(len(v) == len(first_v) and np.array_equal(f, first_f) for v, f in meshes)
    try:
        if shared:
            observed = _observed(Abc, AbcGeom, schema, selectors, len(first_v))
            return AnimatedMesh(
                first_f, np.stack([v for v, _ in meshes]), times, observed,
                uv=_uvs(schema, selectors[0], first_f, path),
                colors=_colors(AbcGeom, schema, selectors, len(first_v)),
            )
        return MeshSequence(tuple(meshes), times)
    except InputError as error:
        raise InputError(error.problem, path) from None


def _triangles(indices: np.ndarray, counts: np.ndarray, path) -> np.ndarray:
    """Alembic's clockwise polygons as counter-clockwise triangles [F, 3] (fans)."""
    if counts.sum() != len(indices) or (counts < 3).any():
        raise InputError("its face counts and face indices disagree", path)
    if (counts == 3).all():  # (also no faces at all)
        return indices.reshape(-1, 3)[:, ::-1].copy()
    starts = np.cumsum(counts) - counts
    triangles = [
        indices[s + np.array([0, j, j + 1])]
        for s, n in zip(starts.tolist(), counts.tolist(), strict=True)
        for j in range(1, n - 1)
    ]
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)[:, ::-1].copy()


def _stored_times(Abc, schema, count: int) -> np.ndarray | None:
    properties = schema.getUserProperties()
    if not properties.valid() or properties.getPropertyHeader(TIMES_PROPERTY) is None:
        return None
    times = np.array(Abc.IDoubleArrayProperty(properties, TIMES_PROPERTY).getValue(), np.float64)
    return times if times.shape == (count,) else None


def _observed(Abc, AbcGeom, schema, selectors, vertex_count: int) -> np.ndarray | None:
    params = schema.getArbGeomParams()
    if not params.valid() or params.getPropertyHeader("observed") is None:
        return None
    param = AbcGeom.IFloatGeomParam(params, "observed")
    rows = [np.array(param.getExpandedValue(s).getVals(), dtype=np.float32) for s in selectors]
    if any(row.shape != (vertex_count,) for row in rows):
        return None
    return np.stack(rows) > 0.5


def _uvs(schema, selector, faces: np.ndarray, path) -> np.ndarray | None:
    """Per-corner UVs [F, 3, 2] of an all-triangle mesh from face-varying UVs, else None."""
    param = schema.getUVsParam()
    if not param.valid() or param.getNumSamples() == 0:
        return None
    sample = param.getIndexedValue(selector)
    values = np.array(sample.getVals(), dtype=np.float64).reshape(-1, 2)
    if sample.isIndexed() and sample.getIndices() is not None:
        indices = np.array(sample.getIndices(), dtype=np.int64)
    else:
        indices = np.arange(len(values))
    if len(indices) != 3 * len(faces) or (len(indices) and indices.max() >= len(values)):
        return None  # per-vertex UVs or polygons fanned on reading: not per triangle corner
    return values[indices.reshape(-1, 3)[:, ::-1]]


def _colors(AbcGeom, schema, selectors, vertex_count: int) -> np.ndarray | None:
    params = schema.getArbGeomParams()
    if not params.valid() or params.getPropertyHeader("Cd") is None:
        return None
    if not AbcGeom.IC3fGeomParam.matches(params.getPropertyHeader("Cd")):
        return None
    param = AbcGeom.IC3fGeomParam(params, "Cd")
    rows = []
    for selector in selectors:
        vals = param.getExpandedValue(selector).getVals()
        rows.append(np.array(vals, dtype=np.float64).reshape(-1, 3))
    if any(row.shape != (vertex_count, 3) for row in rows):
        return None
    return linear_to_srgb(np.stack(rows))
