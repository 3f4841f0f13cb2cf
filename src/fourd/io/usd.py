"""USD export (``.usd``, ``.usda``, ``.usdc``) through usd-core's ``pxr`` (an optional extra).

An :class:`~fourd.animation.AnimatedMesh` becomes one ``UsdGeom.Mesh`` at ``/Root/Mesh`` with
fixed ``faceVertexCounts``/``faceVertexIndices`` and time-sampled ``points`` and ``extent``
(one sample per frame); a point-only result (no faces) becomes a ``UsdGeom.Points``. A
:class:`~fourd.animation.MeshSequence` becomes one mesh whose topology is time-sampled too.

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
from fourd.io.atomic import atomic_path

USD_SUFFIXES = (".usd", ".usda", ".usdc")


def _pxr(path):
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise InputError(
            'writing USD needs usd-core, which is not installed: pip install "fourd[usd]"', path
        ) from None
    return Sdf, Usd, UsdGeom, Vt


def write_usd(
    path: str | os.PathLike, result: AnimatedMesh | MeshSequence, *, fps: float | None = None
) -> None:
    """Write ``result`` as a USD stage, atomically.

    Time code of frame ``k`` is ``times[k]``; ``timeCodesPerSecond`` (and
    ``framesPerSecond``) is ``fps`` when given (times are frame numbers), else 1 (times are
    seconds). The stage's start and end time codes are the first and last times; ``Y`` is up.

    Raises
    ------
    InputError
        When ``pxr`` is not importable (saying ``pip install "fourd[usd]"``) or the suffix is
        not ``.usd``, ``.usda`` or ``.usdc``.
    """
    suffix = os.fspath(path).lower()
    if not suffix.endswith(USD_SUFFIXES):
        raise InputError("a USD file must end in .usd, .usda or .usdc", path)
    Sdf, Usd, UsdGeom, Vt = _pxr(path)
    if isinstance(result, AnimatedMesh):
        frames = [(result.vertices[k], result.faces) for k in range(result.frame_count)]
        fixed_topology = True
    elif isinstance(result, MeshSequence):
        frames = list(result.meshes)
        fixed_topology = False
    else:
        raise InputError(f"cannot write a {type(result).__name__} as USD", path)
    codes = np.asarray(result.times, dtype=np.float64)
    rate = float(fps) if fps else 1.0
    points_only = all(len(f) == 0 for _, f in frames)
    with atomic_path(path) as tmp:
        with contextlib.suppress(OSError):
            os.remove(tmp)  # Usd.Stage.CreateNew wants to create the file itself
        stage = Usd.Stage.CreateNew(str(tmp))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        root = UsdGeom.Xform.Define(stage, "/Root")
        stage.SetDefaultPrim(root.GetPrim())
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
        for k, (vertices, faces) in enumerate(frames):
            code = Usd.TimeCode(float(codes[k]))
            points = vertices.astype(np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), code)
            if len(points):
                extent = np.stack([points.min(axis=0), points.max(axis=0)])
                extent_attr.Set(Vt.Vec3fArray.FromNumpy(extent), code)
            if not points_only and not fixed_topology:
                counts_attr.Set(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)), code)
                indices_attr.Set(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()), code)
        stage.GetRootLayer().Save()
        del stage
