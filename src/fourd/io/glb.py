"""glTF 2.0 binary (``.glb``) export of animations, and :func:`read_glb` to read them back.

An :class:`~fourd.animation.AnimatedMesh` becomes one mesh whose base is frame 0 (POSITION and
NORMAL) and whose morph targets are the other frames (POSITION and NORMAL deltas from frame
0); one animation drives the morph ``weights`` over ``times`` with one-hot keys (frame ``k``
has weight 1 on target ``k - 1``), so LINEAR interpolation blends consecutive frames and STEP
shows them as they are. Blender's glTF importer turns the targets into shape keys; three.js
plays the clip with an ``AnimationMixer``.

A :class:`~fourd.animation.MeshSequence` becomes one node per frame, each with its own mesh,
and an animation of the nodes' ``scale`` (1 while the frame is current, 0 otherwise, STEP).

Keyframe times are the frame times in seconds (:mod:`fourd.io.timebase`). glTF is Y up by
specification: Z-up data (``up="z"``) is rotated on writing, ``(x, y, z) -> (x, z, -y)``.

:func:`read_glb` reads both layouts back: one mesh node is an AnimatedMesh (frame ``k`` is the
base plus the morph targets weighted by the ``k``-th key of the weights animation), several
are a MeshSequence (one node per frame). Times are the animation's key times (seconds); a
``.glb`` does not hold ``observed`` (read back as all True) nor the rest pose.

References
----------
Khronos Group, "glTF 2.0 Specification", sections 3.7.2.2 (morph targets) and 3.11 (animations).
"""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.io.atomic import atomic_path
from fourd.io.axes import Z_UP_TO_Y_UP, check_up, transformed
from fourd.io.timebase import TimeBase, time_base

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
FLOAT = 5126
UNSIGNED_SHORT = 5123
UNSIGNED_INT = 5125


class _Blob:
    """Accumulates accessors over one binary buffer (4-byte aligned views)."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.parts: list[bytes] = []
        self.length = 0

    def add(
        self, array: np.ndarray, kind: str, *, target: int | None = None, bounds: bool = False
    ) -> int:
        from pygltflib import Accessor, BufferView

        array = np.ascontiguousarray(array)
        component = {
            np.dtype("float32"): FLOAT,
            np.dtype("uint16"): UNSIGNED_SHORT,
            np.dtype("uint32"): UNSIGNED_INT,
        }[array.dtype]
        data = array.tobytes()
        self.gltf.bufferViews.append(
            BufferView(buffer=0, byteOffset=self.length, byteLength=len(data), target=target)
        )
        self.parts.append(data)
        self.length += len(data)
        padding = (-self.length) % 4
        if padding:
            self.parts.append(b"\0" * padding)
            self.length += padding
        width = {"SCALAR": 1, "VEC3": 3}[kind]
        flat = array.reshape(-1, width)
        accessor = Accessor(
            bufferView=len(self.gltf.bufferViews) - 1,
            byteOffset=0,
            componentType=component,
            count=len(flat),
            type=kind,
        )
        if bounds:
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def finish(self) -> bytes:
        from pygltflib import Buffer

        blob = b"".join(self.parts)
        self.gltf.buffers.append(Buffer(byteLength=len(blob)))
        return blob


#: The animation's ``extras`` key holding the result's own times (the keys are seconds).
TIMES_EXTRA = "fourd_times"

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


def _animated(gltf, blob: _Blob, anim: AnimatedMesh, *, clock: TimeBase, interpolation) -> None:
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

    vertices = anim.vertices
    count = len(vertices)
    points_only = len(anim.faces) == 0
    base = vertices[0].astype(np.float32)
    attributes = Attributes(POSITION=blob.add(base, "VEC3", target=ARRAY_BUFFER, bounds=True))
    normals = None
    if not points_only:
        normals = vertex_normals(vertices, anim.faces).astype(np.float32)
        attributes.NORMAL = blob.add(normals[0], "VEC3", target=ARRAY_BUFFER)
    targets = []
    for k in range(1, count):
        target = Attributes(
            POSITION=blob.add(
                vertices[k].astype(np.float32) - base, "VEC3", target=ARRAY_BUFFER, bounds=True
            )
        )
        if normals is not None:
            target.NORMAL = blob.add(normals[k] - normals[0], "VEC3", target=ARRAY_BUFFER)
        targets.append(target)
    primitive = Primitive(
        attributes=attributes, mode=0 if points_only else 4, material=0, targets=targets or None
    )
    if not points_only:
        primitive.indices = _indices(blob, anim.faces, vertices.shape[1])
    mesh = Mesh(name="fourd", primitives=[primitive])
    if targets:
        mesh.weights = [0.0] * len(targets)
        mesh.extras = {"targetNames": [f"frame_{k}" for k in range(1, count)]}
    gltf.meshes.append(mesh)
    gltf.nodes.append(Node(name="fourd", mesh=0))
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
    """
    try:
        import pygltflib  # noqa: F401
    except ImportError:  # pragma: no cover - a core dependency
        raise InputError("writing .glb needs pygltflib: pip install pygltflib", path) from None
    interpolation = interpolation.upper()
    if interpolation not in ("LINEAR", "STEP"):
        raise InputError(f"interpolation must be LINEAR or STEP, got {interpolation!r}", path)
    if not isinstance(result, AnimatedMesh | MeshSequence):
        raise InputError(f"cannot write a {type(result).__name__} as .glb", path)
    clock = time_base(result.times, fps=fps, unit=time_unit)
    if check_up(up) == "z":
        result = transformed(result, Z_UP_TO_Y_UP)
    gltf = _new_gltf()
    blob = _Blob(gltf)
    if isinstance(result, AnimatedMesh):
        _animated(gltf, blob, result, clock=clock, interpolation=interpolation)
    else:
        _sequence(gltf, blob, result, clock=clock)
    gltf.set_binary_blob(blob.finish())
    with atomic_path(path, suffix=".glb") as tmp:
        gltf.save_binary(str(tmp))


# ------------------------------------------------------------------------------------ reading

_COMPONENTS = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _accessor(gltf, blob: bytes, index: int, path) -> np.ndarray:
    """The values of accessor ``index``: an array [count, width] (``[count]`` for SCALAR)."""
    accessor = gltf.accessors[index]
    if accessor.sparse is not None or accessor.bufferView is None:
        raise InputError(f"accessor {index} is sparse or has no buffer view: not a fourd .glb", path)
    view = gltf.bufferViews[accessor.bufferView]
    dtype = np.dtype(_COMPONENTS[accessor.componentType]).newbyteorder("<")
    width = _WIDTHS[accessor.type]
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
    return rows[:, 0] if accessor.type == "SCALAR" else rows


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
    return AnimatedMesh(faces, vertices, times=times)


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
