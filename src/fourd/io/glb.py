"""glTF 2.0 binary (``.glb``) export of animations.

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

References
----------
Khronos Group, "glTF 2.0 Specification", sections 3.7.2.2 (morph targets) and 3.11 (animations).
"""

from __future__ import annotations

import os

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
        gltf.animations.append(Animation(name="fourd", samplers=samplers, channels=channels))


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
