"""USD export (``.usd``, ``.usda``, ``.usdc``) through usd-core's ``pxr`` (an optional extra),
and :func:`read_usd` to read it back.

An :class:`~fourd.animation.AnimatedMesh` becomes one ``UsdGeom.Mesh`` at ``/Root/Mesh`` with
fixed ``faceVertexCounts``/``faceVertexIndices`` and time-sampled ``points``, ``normals``
(``vertex`` interpolation) and ``extent`` (one sample per frame); a point-only result (no
faces) becomes a ``UsdGeom.Points``. A :class:`~fourd.animation.MeshSequence` becomes one
mesh whose topology is time-sampled too.

An AnimatedMesh's other data, when it has it: ``uv`` as ``primvars:st`` (``texCoord2f[]``,
``faceVarying``, indexed: one value per distinct corner UV), ``colors`` as
``primvars:displayColor`` (``vertex``, time-sampled, linear as USD renders colour), and
``observed`` always as ``primvars:observed`` (``float[]``, ``vertex``, time-sampled: 1 where
the vertex had data, 0 where it was filled in).

The stage's metadata: ``upAxis`` (``Y``, or ``Z`` for Z-up data: the points are not rotated),
``metersPerUnit`` 1 (positions are taken to be metres: scale other units with ``scale``, e.g.
``--scale 0.001`` for millimetres; USD's own fallback would be centimetres),
``timeCodesPerSecond`` = ``framesPerSecond`` = the frame rate, and start and end time codes.
The time code of a frame is its frame number at that rate (:mod:`fourd.io.timebase`).

References
----------
Pixar, "Universal Scene Description", UsdGeom schema (``UsdGeomMesh``, ``UsdGeomPointBased``).
"""

from __future__ import annotations

import contextlib
import os

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.geometry.parameterization import indexed_corners
from fourd.io.atomic import atomic_path
from fourd.io.axes import check_up
from fourd.io.colorspace import srgb_to_linear
from fourd.io.timebase import time_base

USD_SUFFIXES = (".usd", ".usda", ".usdc")
#: The stage's ``metersPerUnit``: fourd writes positions as metres.
METERS_PER_UNIT = 1.0


#: Attribute of the root prim holding the result's times (time codes are frame numbers).
TIMES_ATTRIBUTE = "fourd:times"

def _pxr(path, verb: str = "writing"):
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise InputError(
            f'{verb} USD needs usd-core, which is not installed: pip install "fourd[usd]"', path
        ) from None
    return Sdf, Usd, UsdGeom, Vt


def write_usd(
    path: str | os.PathLike,
    result: AnimatedMesh | MeshSequence,
    *,
    fps: float | None = None,
    time_unit: str | None = None,
    up: str = "y",
) -> None:
    """Write ``result`` as a USD stage (see the module docstring), atomically.

    Parameters
    ----------
    path : path-like
    result : AnimatedMesh or MeshSequence
    fps, time_unit : optional
        The time base of ``result.times`` (:func:`fourd.io.timebase.time_base`): the time code
        of frame ``k`` is ``times[k]`` as a frame number at ``fps`` frames per second, which
        is the stage's ``timeCodesPerSecond`` and ``framesPerSecond``.
    up : {"y", "z"}
        The stage's ``upAxis``; the points are written as they are.

    Raises
    ------
    InputError
        When ``pxr`` is not importable (saying ``pip install "fourd[usd]"``), the suffix is
        not ``.usd``, ``.usda`` or ``.usdc``, or ``fps``, ``time_unit`` or ``up`` is wrong.
    """
    suffix = os.fspath(path).lower()
    if not suffix.endswith(USD_SUFFIXES):
        raise InputError("a USD file must end in .usd, .usda or .usdc", path)
    up = check_up(up)
    Sdf, Usd, UsdGeom, Vt = _pxr(path)
    if isinstance(result, AnimatedMesh):
        frames = [(result.vertices[k], result.faces) for k in range(result.frame_count)]
        fixed_topology = True
    elif isinstance(result, MeshSequence):
        frames = list(result.meshes)
        fixed_topology = False
    else:
        raise InputError(f"cannot write a {type(result).__name__} as USD", path)
    base = time_base(result.times, fps=fps, unit=time_unit)
    codes = base.frames(result.times)
    rate = float(base.fps)
    points_only = all(len(f) == 0 for _, f in frames)
    with atomic_path(path) as tmp:
        with contextlib.suppress(OSError):
            os.remove(tmp)  # Usd.Stage.CreateNew wants to create the file itself
        stage = Usd.Stage.CreateNew(str(tmp))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, METERS_PER_UNIT)
        root = UsdGeom.Xform.Define(stage, "/Root")
        stage.SetDefaultPrim(root.GetPrim())
        # the result's own times, so that reading back gives them exactly (time codes are frames)
        root.GetPrim().CreateAttribute(TIMES_ATTRIBUTE, Sdf.ValueTypeNames.DoubleArray).Set(
            Vt.DoubleArray([float(t) for t in result.times])
        )
        stage.SetStartTimeCode(float(codes[0]))
        stage.SetEndTimeCode(float(codes[-1]))
        stage.SetTimeCodesPerSecond(rate)
        stage.SetFramesPerSecond(rate)
        if points_only:
            geom = UsdGeom.Points.Define(stage, "/Root/Points")
        else:
            geom = UsdGeom.Mesh.Define(stage, "/Root/Mesh")
            geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            geom.CreateDoubleSidedAttr(True)
            counts_attr = geom.CreateFaceVertexCountsAttr()
            indices_attr = geom.CreateFaceVertexIndicesAttr()
            if fixed_topology:
                faces = frames[0][1]
                counts_attr.Set(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
                indices_attr.Set(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()))
        points_attr = geom.CreatePointsAttr()
        extent_attr = geom.CreateExtentAttr()
        normals_attr = None
        if not points_only:
            normals_attr = geom.CreateNormalsAttr()
            geom.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        colors_var = observed_var = None
        if fixed_topology:
            primvars = UsdGeom.PrimvarsAPI(geom)
            if result.uv is not None and not points_only:
                values, indices = indexed_corners(result.uv)
                st = primvars.CreatePrimvar(
                    "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
                )
                st.Set(Vt.Vec2fArray.FromNumpy(values.astype(np.float32)))
                st.SetIndices(Vt.IntArray.FromNumpy(indices.astype(np.int32)))
            if result.colors is not None:
                colors_var = geom.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex)
            observed_var = primvars.CreatePrimvar(
                "observed", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex
            )
        for k, (vertices, faces) in enumerate(frames):
            code = Usd.TimeCode(float(codes[k]))
            points = vertices.astype(np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), code)
            if len(points):
                extent = np.stack([points.min(axis=0), points.max(axis=0)])
                extent_attr.Set(Vt.Vec3fArray.FromNumpy(extent), code)
            if normals_attr is not None:
                normals = vertex_normals(vertices, faces).astype(np.float32)
                normals_attr.Set(Vt.Vec3fArray.FromNumpy(normals), code)
            if colors_var is not None:
                linear = srgb_to_linear(result.colors[k]).astype(np.float32)
                colors_var.Set(Vt.Vec3fArray.FromNumpy(linear), code)
            if observed_var is not None:
                flags = result.observed[k].astype(np.float32)
                observed_var.Set(Vt.FloatArray.FromNumpy(flags), code)
            if not points_only and not fixed_topology:
                counts_attr.Set(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)), code)
                indices_attr.Set(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()), code)
        stage.GetRootLayer().Save()
        del stage


def read_usd(path: str | os.PathLike) -> AnimatedMesh | MeshSequence:
    """Read a USD stage written by :func:`write_usd`: its first ``UsdGeom.Mesh`` (or
    ``UsdGeom.Points``), one frame per time sample of ``points`` (times are the time codes).
    The same faces and vertex count in every frame make an AnimatedMesh (``observed`` all
    True: USD does not hold it), else a MeshSequence. Polygons are fan-triangulated.

    Raises
    ------
    InputError
        Without ``pxr`` (saying ``pip install "fourd[usd]"``), an unreadable stage, or one
        without a mesh or points.
    """
    _, Usd, UsdGeom, _ = _pxr(path, "reading")
    try:
        stage = Usd.Stage.Open(os.fspath(path))
    except Exception:  # pxr.Tf.ErrorException, whose text is pxr's source location
        raise InputError("is not a readable USD stage (usd-core could not open it)", path) from None
    if stage is None:
        raise InputError("is not a readable USD stage", path)
    geom = None
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Points):
            geom = prim
            break
    if geom is None:
        raise InputError("holds no UsdGeom.Mesh or UsdGeom.Points", path)
    points_attr = UsdGeom.PointBased(geom).GetPointsAttr()
    codes = list(points_attr.GetTimeSamples()) or [Usd.TimeCode.Default()]
    is_mesh = geom.IsA(UsdGeom.Mesh)
    mesh = UsdGeom.Mesh(geom) if is_mesh else None

    def faces_at(code) -> np.ndarray:
        if mesh is None:
            return np.zeros((0, 3), dtype=np.int64)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(code) or [], dtype=np.int64)
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(code) or [], dtype=np.int64)
        return _triangulate(counts, indices, path)

    frames = []
    for code in codes:
        points = np.asarray(points_attr.Get(code) or [], dtype=np.float64).reshape(-1, 3)
        frames.append((points, faces_at(code)))
    times = None if len(codes) == 1 and not points_attr.GetTimeSamples() else [float(c) for c in codes]
    written = stage.GetDefaultPrim().GetAttribute(TIMES_ATTRIBUTE) if stage.GetDefaultPrim() else None
    if written and written.Get() is not None and len(written.Get()) == len(frames):
        times = [float(t) for t in written.Get()]
    same = all(len(v) == len(frames[0][0]) and np.array_equal(f, frames[0][1]) for v, f in frames)
    try:
        if same and len(frames[0][0]):
            return AnimatedMesh(frames[0][1], np.stack([v for v, _ in frames]), times)
        return MeshSequence(tuple(frames), times)
    except InputError as error:
        raise InputError(error.problem, error.path or path) from None


def _triangulate(counts: np.ndarray, indices: np.ndarray, path) -> np.ndarray:
    """Triangles [F, 3] of polygons given as USD ``faceVertexCounts`` and ``faceVertexIndices``
    (each polygon fanned from its first corner)."""
    if counts.sum() != len(indices):
        raise InputError(
            f"faceVertexCounts add up to {int(counts.sum())} but there are {len(indices)} "
            "faceVertexIndices",
            path,
        )
    if len(counts) and (counts == 3).all():
        return indices.reshape(-1, 3)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    triangles = [
        (indices[s], indices[s + k], indices[s + k + 1])
        for s, n in zip(starts.tolist(), counts.tolist(), strict=True)
        for k in range(1, n - 1)
    ]
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)
