"""glTF 2.0 binary (``.glb``) export of animations, and :func:`read_glb` to read them back.

An :class:`~fourd.animation.AnimatedMesh` becomes one mesh whose base is frame 0 (POSITION and
NORMAL) and whose morph targets are the other frames (POSITION and NORMAL deltas from frame
0); one animation drives the morph ``weights`` over ``times`` with one-hot keys (frame ``k``
has weight 1 on target ``k - 1``), so LINEAR interpolation blends consecutive frames and STEP
shows them as they are. Blender's glTF importer turns the targets into shape keys; three.js
plays the clip with an ``AnimationMixer``.

Size: by default (``encoding="quantized"``) the morph targets are stored compactly with
``KHR_mesh_quantization`` (a required extension; three.js, Babylon.js and Blender read it):
position deltas as normalized int16 over the animation's extent, normal deltas as normalized
int8 (int16 or float32 for a target where 8 bits would turn a normal by more than
:data:`NORMAL_TOLERANCE_DEGREES`), and the mesh's node carries the uniform scale and the
translation that undo the quantization (an importer shows them as the object's transform).
That halves the file; ``encoding="float"`` writes plain float32 and an identity node.

What else an AnimatedMesh carries, when it has it:

- ``uv`` -> ``TEXCOORD_0`` (``v`` flipped to glTF's downward convention). glTF holds one UV per
  vertex, so vertices on UV seams are duplicated (:func:`fourd.geometry.parameterization.split_seams`):
  vertex ``i < N`` is still the result's vertex ``i``, the copies follow, with the same
  trajectories and normals (shading stays smooth across seams).
- ``colors`` -> ``COLOR_0`` (linear, unsigned short): glTF has no per-frame vertex colours,
  so it is each vertex's mean colour over the frames where it was observed.
- ``observed`` -> ``_OBSERVED`` (float, 1 observed, 0 filled in), of frame 0 only, for the same
  reason.

A :class:`~fourd.animation.MeshSequence` (per-frame meshes, each with its own connectivity)
becomes one node per frame, each with its own mesh, and an animation of the nodes' ``scale``
(1 while the frame is current, 0 otherwise, STEP): a player switches meshes per frame. It is
not a deforming mesh (no shape keys in Blender, one object per frame) and is written float32.

Keyframe times are the frame times in seconds (:mod:`fourd.io.timebase`). glTF is Y up by
specification: Z-up data (``up="z"``) is rotated on writing, ``(x, y, z) -> (x, z, -y)``.

:func:`read_glb` reads both layouts back: one mesh node is an AnimatedMesh (frame ``k`` is the
base plus the morph targets weighted by the ``k``-th key of the weights animation), several
are a MeshSequence (one node per frame). Times are the animation's key times (seconds); a
``.glb`` does not hold ``observed`` (read back as all True) nor the rest pose.

References
----------
Khronos Group, "glTF 2.0 Specification", sections 3.6.2 (accessors, data alignment), 3.7.2.2
(morph targets) and 3.11 (animations); "KHR_mesh_quantization" (extension specification).
"""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.geometry.parameterization import split_seams
from fourd.io.atomic import atomic_path
from fourd.io.axes import Z_UP_TO_Y_UP, check_up, transformed
from fourd.io.colorspace import srgb_to_linear
from fourd.io.timebase import TimeBase, time_base

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
BYTE = 5120
SHORT = 5122
UNSIGNED_SHORT = 5123
UNSIGNED_INT = 5125
FLOAT = 5126

#: Encodings of an AnimatedMesh's morph targets (:func:`write_glb`).
ENCODINGS = ("quantized", "float")
#: The glTF extension quantized morph targets need (three.js, Babylon.js, Blender read it).
QUANTIZATION = "KHR_mesh_quantization"
#: Worst direction error, in degrees, allowed for a quantized morph target's normals; a target
#: whose normals cannot be written within it as 8-bit (then 16-bit) deltas keeps float ones.
NORMAL_TOLERANCE_DEGREES = 1.0

_COMPONENTS = {
    np.dtype("float32"): FLOAT,
    np.dtype("int8"): BYTE,
    np.dtype("int16"): SHORT,
    np.dtype("uint16"): UNSIGNED_SHORT,
    np.dtype("uint32"): UNSIGNED_INT,
}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


class _Blob:
    """Accumulates accessors over one binary buffer (4-byte aligned views)."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.parts: list[bytes] = []
        self.length = 0

    def add(
        self,
        array: np.ndarray,
        kind: str,
        *,
        target: int | None = None,
        bounds: bool = False,
        normalized: bool = False,
    ) -> int:
        """An accessor of ``kind`` over ``array`` ``[count, columns]`` (or flat): columns past
        the kind's width are padding, written and skipped with a byte stride (glTF wants every
        vertex attribute element 4-byte aligned: int16 VEC3 is stored as 4 shorts)."""
        from pygltflib import Accessor, BufferView

        array = np.ascontiguousarray(array)
        component = _COMPONENTS[array.dtype]
        width = _WIDTHS[kind]
        rows = array.reshape(len(array), -1) if array.ndim > 1 else array.reshape(-1, width)
        stride = rows.shape[1] * rows.itemsize if rows.shape[1] != width else None
        data = rows.tobytes()
        self.gltf.bufferViews.append(
            BufferView(buffer=0, byteOffset=self.length, byteLength=len(data), target=target,
                       byteStride=stride)
        )
        self.parts.append(data)
        self.length += len(data)
        padding = (-self.length) % 4
        if padding:
            self.parts.append(b"\0" * padding)
            self.length += padding
        flat = rows[:, :width]
        accessor = Accessor(
            bufferView=len(self.gltf.bufferViews) - 1,
            byteOffset=0,
            componentType=component,
            normalized=True if normalized else None,
            count=len(flat),
            type=kind,
        )
        if bounds:
            cast = float if component == FLOAT else int
            accessor.min = [cast(v) for v in flat.min(axis=0)]
            accessor.max = [cast(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def finish(self) -> bytes:
        from pygltflib import Buffer

        blob = b"".join(self.parts)
        self.gltf.buffers.append(Buffer(byteLength=len(blob)))
        return blob


#: The animation's ``extras`` key holding the result's own times (the keys are seconds).
TIMES_EXTRA = "fourd_times"
#: The mesh's ``extras`` key naming the result vertex each UV-seam copy repeats.
SEAM_EXTRA = "fourd_seams"

def _indices(blob: _Blob, faces: np.ndarray, vertex_count: int) -> int:
    dtype = np.uint16 if vertex_count < 65535 else np.uint32
    return blob.add(faces.astype(dtype).ravel(), "SCALAR", target=ELEMENT_ARRAY_BUFFER, bounds=True)


def _new_gltf():
    from pygltflib import GLTF2, Asset, Material, PbrMetallicRoughness, Scene

    gltf = GLTF2(asset=Asset(version="2.0", generator="fourd"))
    gltf.scenes.append(Scene(nodes=[]))
    gltf.scene = 0
    gltf.materials.append(
        Material(
            name="fourd",
            doubleSided=True,
            pbrMetallicRoughness=PbrMetallicRoughness(
                baseColorFactor=[0.8, 0.8, 0.82, 1.0], metallicFactor=0.0, roughnessFactor=0.7
            ),
        )
    )
    return gltf


def _seconds(times: np.ndarray, clock: TimeBase) -> np.ndarray:
    seconds = clock.seconds(times)
    if seconds[0] < 0:  # glTF keyframe times must be non-negative
        seconds = seconds - seconds[0]
    return seconds.astype(np.float32)


def _padded(array: np.ndarray, dtype) -> np.ndarray:
    """``array`` [M, 3] as ``dtype`` [M, 4] (the fourth column zero): 4-byte aligned rows."""
    out = np.zeros((len(array), 4), dtype=dtype)
    out[:, :3] = array
    return out


def _dequantization(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """``(centre [3], size)`` of the quantized positions: the node's translation and uniform
    scale. The base frame, ``(v0 - centre) / size``, and every delta, ``(vk - v0) / size``,
    lie in [-1, 1], so the deltas fit normalized int16 (a step of ``size / 32767``)."""
    lo, hi = vertices.min(axis=(0, 1)), vertices.max(axis=(0, 1))
    centre = (lo + hi) / 2
    size = float(np.abs(vertices[0] - centre).max(initial=0.0))
    for frame in vertices[1:]:
        size = max(size, float(np.abs(frame - vertices[0]).max(initial=0.0)))
    return centre, (size if size > 0 else 1.0)


def _snorm(values: np.ndarray, dtype) -> np.ndarray:
    limit = np.iinfo(dtype).max
    return np.clip(np.round(values * limit), -limit, limit).astype(dtype)


def _normal_delta(base: np.ndarray, normal: np.ndarray):
    """The smallest encoding of a morph target's normal deltas within
    :data:`NORMAL_TOLERANCE_DEGREES`: ``(array [M, 4 or 3], normalized)``.

    A normalized delta must lie in [-1, 1] but ``normal - base`` reaches 2 where a normal
    turns by more than 90 degrees. Renderers normalize the morphed normal (the glTF
    specification asks them to), so any positive multiple ``c * normal - base`` does as
    well: ``c`` is the largest one in (0, 1] that keeps every component in range. Where no
    ``c`` works well (a normal almost reversed along an axis) the target keeps float deltas.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(normal > 0, (1 + base) / normal, np.inf)
        down = np.where(normal < 0, (1 - base) / -normal, np.inf)
    scale = np.minimum(1.0, np.minimum(up, down).min(axis=1))[:, None]
    wanted = scale * normal - base
    cosine = np.cos(np.radians(NORMAL_TOLERANCE_DEGREES))
    for dtype in (np.int8, np.int16):
        delta = _snorm(wanted, dtype)
        morphed = base + delta / np.iinfo(dtype).max
        length = np.linalg.norm(morphed, axis=1)
        agree = np.einsum("ij,ij->i", morphed, normal) >= cosine * np.maximum(length, 1e-30)
        # (a zero normal, from a degenerate neighbourhood, is as wrong in any encoding)
        if np.all((agree & (length > 0)) | ~normal.any(axis=1)):
            return _padded(delta, dtype), True
    return (normal - base).astype(np.float32), False


def _animated(
    gltf, blob: _Blob, anim: AnimatedMesh, *, clock: TimeBase, interpolation, encoding
) -> None:
    from pygltflib import (
        Animation,
        AnimationChannel,
        AnimationChannelTarget,
        AnimationSampler,
        Attributes,
        Mesh,
        Node,
        Primitive,
    )

    count = anim.frame_count
    points_only = len(anim.faces) == 0
    faces, index, seams = anim.faces, slice(None), None
    if anim.uv is not None and not points_only:
        seams = split_seams(anim.faces, anim.uv, anim.vertex_count)
        faces, index = seams.faces, seams.vertex

    def normals(k: int) -> np.ndarray:  # one frame at a time: memory bounded by a frame
        return vertex_normals(anim.vertices[k], anim.faces)[index]

    quantized = encoding == "quantized" and count > 1
    centre, size = _dequantization(anim.vertices) if quantized else (np.zeros(3), 1.0)
    base = anim.vertices[0][index]
    attributes = Attributes(
        POSITION=blob.add(((base - centre) / size).astype(np.float32), "VEC3",
                          target=ARRAY_BUFFER, bounds=True)
    )
    base_normals = None
    if not points_only:
        base_normals = normals(0)
        attributes.NORMAL = blob.add(base_normals.astype(np.float32), "VEC3",
                                     target=ARRAY_BUFFER)
    if seams is not None:
        flipped = np.stack([seams.uv[:, 0], 1.0 - seams.uv[:, 1]], axis=1)  # glTF: v down
        attributes.TEXCOORD_0 = blob.add(flipped.astype(np.float32), "VEC2", target=ARRAY_BUFFER)
    if anim.colors is not None:
        colors = _mean_observed_colors(anim)[index]
        rgba = np.concatenate([colors, np.ones((len(colors), 1))], axis=1)
        attributes.COLOR_0 = blob.add(_unorm16(rgba), "VEC4", target=ARRAY_BUFFER,
                                      normalized=True)
    observed = anim.observed[0][index].astype(np.float32)
    attributes._OBSERVED = blob.add(observed, "SCALAR", target=ARRAY_BUFFER)
    targets = []
    for k in range(1, count):
        delta = anim.vertices[k][index] - base
        if quantized:
            position = blob.add(_padded(_snorm(delta / size, np.int16), np.int16), "VEC3",
                                target=ARRAY_BUFFER, bounds=True, normalized=True)
        else:
            position = blob.add(delta.astype(np.float32), "VEC3", target=ARRAY_BUFFER,
                                bounds=True)
        target = Attributes(POSITION=position)
        if base_normals is not None:
            if quantized:
                values, normalized = _normal_delta(base_normals, normals(k))
            else:
                values, normalized = (normals(k) - base_normals).astype(np.float32), False
            target.NORMAL = blob.add(values, "VEC3", target=ARRAY_BUFFER, normalized=normalized)
        targets.append(target)
    primitive = Primitive(
        attributes=attributes, mode=0 if points_only else 4, material=0, targets=targets or None
    )
    if not points_only:
        primitive.indices = _indices(blob, faces, len(base))
    mesh = Mesh(name="fourd", primitives=[primitive])
    if targets:
        mesh.weights = [0.0] * len(targets)
        mesh.extras = {"targetNames": [f"frame_{k}" for k in range(1, count)]}
    if seams is not None:  # which result vertex each seam copy repeats, to read it back whole
        mesh.extras = {**(mesh.extras or {}), SEAM_EXTRA: {
            "vertex_count": int(anim.vertex_count),
            "copies_of": [int(v) for v in seams.vertex[anim.vertex_count:]]}}
    gltf.meshes.append(mesh)
    node = Node(name="fourd", mesh=0)
    if quantized:  # undo the quantization: positions are size * stored + centre
        node.translation = [float(v) for v in centre]
        node.scale = [size] * 3
        gltf.extensionsUsed.append(QUANTIZATION)
        gltf.extensionsRequired.append(QUANTIZATION)
    if anim.colors is not None:  # white, so COLOR_0 shows as it is
        gltf.materials[0].pbrMetallicRoughness.baseColorFactor = [1.0, 1.0, 1.0, 1.0]
    gltf.nodes.append(node)
    gltf.scenes[0].nodes.append(0)
    if not targets:
        return
    weights = np.zeros((count, count - 1), dtype=np.float32)
    weights[np.arange(1, count), np.arange(count - 1)] = 1.0
    sampler = AnimationSampler(
        input=blob.add(_seconds(anim.times, clock), "SCALAR", bounds=True),
        output=blob.add(weights.ravel(), "SCALAR"),
        interpolation=interpolation,
    )
    gltf.animations.append(
        Animation(
            name="fourd",
            extras={TIMES_EXTRA: [float(t) for t in anim.times]},
            samplers=[sampler],
            channels=[
                AnimationChannel(sampler=0, target=AnimationChannelTarget(node=0, path="weights"))
            ],
        )
    )


def _unorm16(values: np.ndarray) -> np.ndarray:
    return np.round(np.clip(values, 0.0, 1.0) * 65535).astype(np.uint16)


def _mean_observed_colors(anim: AnimatedMesh) -> np.ndarray:
    """Linear vertex colours [N, 3] for ``COLOR_0``: each vertex's mean over the frames where
    it was observed (over all frames for a vertex never observed). glTF has no per-frame
    vertex colours (morph targets move positions, normals and tangents only)."""
    weights = anim.observed.astype(np.float64)
    never = weights.sum(axis=0) == 0
    weights[:, never] = 1.0
    linear = srgb_to_linear(anim.colors)
    return np.einsum("tn,tnc->nc", weights, linear) / weights.sum(axis=0)[:, None]


def _sequence(gltf, blob: _Blob, seq: MeshSequence, *, clock: TimeBase) -> None:
    from pygltflib import (
        Animation,
        AnimationChannel,
        AnimationChannelTarget,
        AnimationSampler,
        Attributes,
        Mesh,
        Node,
        Primitive,
    )

    count = len(seq.meshes)
    channels, samplers = [], []
    time_accessor = blob.add(_seconds(seq.times, clock), "SCALAR", bounds=True) if count > 1 else None
    for k, (vertices, faces) in enumerate(seq.meshes):
        node = Node(name=f"frame_{k}", scale=[1.0, 1.0, 1.0] if k == 0 else [0.0, 0.0, 0.0])
        if len(vertices):
            attributes = Attributes(
                POSITION=blob.add(
                    vertices.astype(np.float32), "VEC3", target=ARRAY_BUFFER, bounds=True
                )
            )
            if len(faces):
                attributes.NORMAL = blob.add(
                    vertex_normals(vertices, faces).astype(np.float32), "VEC3", target=ARRAY_BUFFER
                )
            primitive = Primitive(attributes=attributes, mode=4 if len(faces) else 0, material=0)
            if len(faces):
                primitive.indices = _indices(blob, faces, len(vertices))
            gltf.meshes.append(Mesh(name=f"frame_{k}", primitives=[primitive]))
            node.mesh = len(gltf.meshes) - 1
        gltf.nodes.append(node)
        gltf.scenes[0].nodes.append(len(gltf.nodes) - 1)
        if time_accessor is not None:
            scale = np.zeros((count, 3), dtype=np.float32)
            scale[k] = 1.0
            samplers.append(
                AnimationSampler(
                    input=time_accessor, output=blob.add(scale, "VEC3"), interpolation="STEP"
                )
            )
            channels.append(
                AnimationChannel(
                    sampler=len(samplers) - 1,
                    target=AnimationChannelTarget(node=len(gltf.nodes) - 1, path="scale"),
                )
            )
    if samplers:
        gltf.animations.append(Animation(name="fourd", samplers=samplers, channels=channels,
                                         extras={TIMES_EXTRA: [float(t) for t in seq.times]}))


def write_glb(
    path: str | os.PathLike,
    result: AnimatedMesh | MeshSequence,
    *,
    fps: float | None = None,
    time_unit: str | None = None,
    interpolation: str = "LINEAR",
    up: str = "y",
    encoding: str = "quantized",
) -> None:
    """Write ``result`` as a glTF 2.0 binary file, atomically.

    Parameters
    ----------
    path : path-like
    result : AnimatedMesh or MeshSequence
    fps, time_unit : optional
        The time base of ``result.times`` (:func:`fourd.io.timebase.time_base`: whole numbers
        are frame numbers at ``fps``, default 30, anything else seconds); keyframe times are
        the times in seconds, shifted to start at 0 if negative.
    interpolation : {"LINEAR", "STEP"}
        Between frames of an AnimatedMesh: blend (LINEAR) or hold (STEP).
    up : {"y", "z"}
        The data's up axis; Z-up data is rotated to glTF's Y up.
    encoding : {"quantized", "float"}
        An AnimatedMesh's morph targets: ``"quantized"`` (``KHR_mesh_quantization``: int16
        position deltas, 8-bit normal deltas where they are accurate to
        :data:`NORMAL_TOLERANCE_DEGREES`, the node's scale and translation undoing the
        quantization; half the size) or ``"float"`` (float32 everywhere, an identity node:
        for readers without the extension). A MeshSequence is always float32.
    """
    try:
        import pygltflib  # noqa: F401
    except ImportError:  # pragma: no cover - a core dependency
        raise InputError("writing .glb needs pygltflib: pip install pygltflib", path) from None
    interpolation = interpolation.upper()
    if interpolation not in ("LINEAR", "STEP"):
        raise InputError(f"interpolation must be LINEAR or STEP, got {interpolation!r}", path)
    encoding = str(encoding).lower()
    if encoding not in ENCODINGS:
        raise InputError(f"the .glb encoding must be 'quantized' or 'float', got {encoding!r}",
                         path)
    if not isinstance(result, AnimatedMesh | MeshSequence):
        raise InputError(f"cannot write a {type(result).__name__} as .glb", path)
    clock = time_base(result.times, fps=fps, unit=time_unit)
    if check_up(up) == "z":
        result = transformed(result, Z_UP_TO_Y_UP)
    gltf = _new_gltf()
    blob = _Blob(gltf)
    if isinstance(result, AnimatedMesh):
        _animated(gltf, blob, result, clock=clock, interpolation=interpolation,
                  encoding=encoding)
    else:
        _sequence(gltf, blob, result, clock=clock)
    gltf.set_binary_blob(blob.finish())
    with atomic_path(path, suffix=".glb") as tmp:
        gltf.save_binary(str(tmp))


# ------------------------------------------------------------------------------------ reading

_READ_TYPES = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_READ_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _accessor(gltf, blob: bytes, index: int, path) -> np.ndarray:
    """The values of accessor ``index``: an array [count, width] (``[count]`` for SCALAR)."""
    accessor = gltf.accessors[index]
    if accessor.sparse is not None or accessor.bufferView is None:
        raise InputError(f"accessor {index} is sparse or has no buffer view: not a fourd .glb", path)
    view = gltf.bufferViews[accessor.bufferView]
    dtype = np.dtype(_READ_TYPES[accessor.componentType]).newbyteorder("<")
    width = _READ_WIDTHS[accessor.type]
    start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
    stride = view.byteStride or dtype.itemsize * width
    count = accessor.count
    end = start + (stride * (count - 1) + dtype.itemsize * width if count else 0)
    if end > len(blob):
        raise InputError(f"accessor {index} reaches past the end of the binary chunk", path)
    rows = np.ndarray(
        (count, width), dtype=dtype, buffer=blob, offset=start, strides=(stride, dtype.itemsize)
    )
    rows = np.array(rows)
    if accessor.normalized and dtype.kind in "iu":  # glTF 2.0 section 3.11: normalized integers
        top = float(np.iinfo(dtype).max)
        rows = np.maximum(rows.astype(np.float64) / top, -1.0)
    return rows[:, 0] if accessor.type == "SCALAR" else rows


def _node_matrix(node) -> np.ndarray:
    """The 4x4 local transform of a glTF node (its ``matrix``, or translation, rotation, scale)."""
    if node.matrix is not None and len(node.matrix) == 16:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T  # column-major
    matrix = np.eye(4)
    if node.scale is not None:
        matrix[:3, :3] = np.diag(np.asarray(node.scale, dtype=np.float64))
    if node.rotation is not None:
        from scipy.spatial.transform import Rotation

        matrix[:3, :3] = Rotation.from_quat(np.asarray(node.rotation, dtype=np.float64)).as_matrix() @ matrix[:3, :3]
    if node.translation is not None:
        matrix[:3, 3] = np.asarray(node.translation, dtype=np.float64)
    return matrix


def _primitive(gltf, blob: bytes, mesh_index: int, path):
    """``(vertices [N, 3], faces [F, 3], targets [K, N, 3])`` of a mesh's first primitive."""
    primitive = gltf.meshes[mesh_index].primitives[0]
    if primitive.attributes.POSITION is None:
        raise InputError(f"mesh {mesh_index} has no POSITION attribute", path)
    vertices = _accessor(gltf, blob, primitive.attributes.POSITION, path).astype(np.float64)
    if primitive.indices is not None and primitive.mode in (None, 4):
        faces = _accessor(gltf, blob, primitive.indices, path).astype(np.int64).reshape(-1, 3)
    elif primitive.mode in (None, 4):  # non-indexed triangles
        faces = np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)
    else:
        faces = np.zeros((0, 3), dtype=np.int64)
    targets = [
        _accessor(gltf, blob, target["POSITION"] if isinstance(target, dict) else target.POSITION, path)
        for target in (primitive.targets or [])
    ]
    targets = np.stack(targets).astype(np.float64) if targets else np.zeros((0, len(vertices), 3))
    return vertices, faces, targets


def _weights_track(gltf, blob: bytes, node: int, path):
    """``(key times, weights [keys, targets])`` of the animation of ``node``'s morph weights,
    or None."""
    for animation in gltf.animations:
        for channel in animation.channels:
            if channel.target.node == node and channel.target.path == "weights":
                sampler = animation.samplers[channel.sampler]
                return (
                    _accessor(gltf, blob, sampler.input, path).astype(np.float64),
                    _accessor(gltf, blob, sampler.output, path).astype(np.float64),
                )
    return None


def _node_key_times(gltf, blob: bytes, nodes: list[int], path) -> np.ndarray | None:
    """The key times of the first animation channel that targets one of ``nodes``."""
    for animation in gltf.animations:
        for channel in animation.channels:
            if channel.target.node in nodes:
                sampler = animation.samplers[channel.sampler]
                return _accessor(gltf, blob, sampler.input, path).astype(np.float64)
    return None


def read_glb(path: str | os.PathLike) -> AnimatedMesh | MeshSequence:
    """Read a ``.glb`` written by :func:`write_glb` (see the module docstring).

    Raises
    ------
    InputError
        Not a glTF binary, no mesh, or a layout :func:`write_glb` does not write (several
        primitives per mesh, sparse accessors, a weights animation that does not match the
        morph targets).
    """
    try:
        from pygltflib import GLTF2
    except ImportError:  # pragma: no cover - a core dependency
        raise InputError("reading .glb needs pygltflib: pip install pygltflib", path) from None
    try:
        with open(path, "rb") as stream:
            if stream.read(4) != b"glTF":
                raise InputError("not a glTF binary (.glb) file", path)
        with warnings.catch_warnings():  # pygltflib warns before it fails on a bad header
            warnings.simplefilter("ignore")
            gltf = GLTF2().load_binary(os.fspath(path))
        blob = gltf.binary_blob() or b""
    except InputError:
        raise
    except OSError as error:
        raise InputError(f"cannot be read ({error.strerror or error})", path) from None
    except Exception as error:  # a damaged file: one clear line
        raise InputError(f"is not a readable .glb ({type(error).__name__}: {error})", path) from None
    scene = gltf.scenes[gltf.scene or 0] if gltf.scenes else None
    nodes = list(scene.nodes) if scene is not None and scene.nodes else list(range(len(gltf.nodes)))
    if not any(gltf.nodes[k].mesh is not None for k in nodes):
        raise InputError("holds no mesh", path)
    try:
        result = _read_animated(gltf, blob, nodes[0], path) if len(nodes) == 1 else _read_sequence(gltf, blob, nodes, path)
        written = next((a.extras.get(TIMES_EXTRA) for a in gltf.animations
                        if isinstance(a.extras, dict) and TIMES_EXTRA in a.extras), None)
        if written is not None and len(written) == len(result.times):
            result = dataclasses.replace(result, times=np.asarray(written, dtype=np.float64))
        return result
    except InputError as error:
        raise InputError(error.problem, error.path or path) from None
    except (IndexError, KeyError, ValueError, AttributeError, TypeError) as error:
        raise InputError(f"is not a .glb fourd can read ({type(error).__name__}: {error})", path) from None


def _read_animated(gltf, blob: bytes, node: int, path) -> AnimatedMesh:
    base, faces, targets = _primitive(gltf, blob, gltf.nodes[node].mesh, path)
    # a quantized file (KHR_mesh_quantization) keeps its dequantization in the node's transform
    transform = _node_matrix(gltf.nodes[node])
    base = base @ transform[:3, :3].T + transform[:3, 3]
    targets = targets @ transform[:3, :3].T
    track = _weights_track(gltf, blob, node, path)
    if track is None or not len(targets):
        return AnimatedMesh(faces, base[None])
    times, weights = track
    weights = weights.reshape(len(times), -1)
    if weights.shape[1] != len(targets):
        raise InputError(
            f"the weights animation drives {weights.shape[1]} morph targets but the mesh has "
            f"{len(targets)}",
            path,
        )
    vertices = base[None] + np.einsum("kt,tnd->knd", weights, targets)
    return _merged_seams(gltf, blob, gltf.nodes[node].mesh, AnimatedMesh(faces, vertices, times=times), path)


def _merged_seams(gltf, blob: bytes, mesh_index: int, anim: AnimatedMesh, path) -> AnimatedMesh:
    """``anim`` with the seam copies the writer made (:data:`SEAM_EXTRA`) merged back into
    their vertices, the UVs per face corner and the colours (sRGB) restored."""
    mesh = gltf.meshes[mesh_index]
    seam = (mesh.extras or {}).get(SEAM_EXTRA) if isinstance(mesh.extras, dict) else None
    attributes = mesh.primitives[0].attributes
    uv = colors = None
    corners = anim.faces
    if attributes.TEXCOORD_0 is not None and len(corners):
        stored = _accessor(gltf, blob, attributes.TEXCOORD_0, path)
        uv = np.stack([stored[:, 0], 1.0 - stored[:, 1]], axis=1)[corners]  # glTF's v is down
    if attributes.COLOR_0 is not None:
        from fourd.io.colorspace import linear_to_srgb

        colors = linear_to_srgb(np.clip(_accessor(gltf, blob, attributes.COLOR_0, path)[:, :3], 0, 1))
    count = anim.vertex_count
    faces = anim.faces
    if seam is not None:
        count = int(seam["vertex_count"])
        original = np.concatenate([np.arange(count), np.asarray(seam["copies_of"], dtype=np.int64)])
        if len(original) != anim.vertex_count:
            raise InputError("its seam table does not match the mesh's vertices", path)
        faces = original[faces]
    vertices = anim.vertices[:, :count]
    if colors is not None:
        colors = np.broadcast_to(colors[:count], (len(vertices), count, 3)).copy()
    return AnimatedMesh(faces, vertices, times=anim.times, uv=uv, colors=colors)


def _read_sequence(gltf, blob: bytes, nodes: list[int], path) -> MeshSequence:
    meshes = []
    for node in nodes:
        if gltf.nodes[node].mesh is None:  # an empty frame
            meshes.append((np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)))
        else:
            vertices, faces, _ = _primitive(gltf, blob, gltf.nodes[node].mesh, path)
            meshes.append((vertices, faces))
    times = _node_key_times(gltf, blob, nodes, path)
    if times is not None and len(times) != len(meshes):
        raise InputError(f"{len(meshes)} frame nodes but {len(times)} animation keys", path)
    return MeshSequence(tuple(meshes), times)
