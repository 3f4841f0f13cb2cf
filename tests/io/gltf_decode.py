"""Decoding of the .glb files fourd writes, independent of fourd's writer: accessors of any
component type (normalized or not, strided) and the morph animation applied through the
node's transform. Used by the glb tests in this folder."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
          5126: np.float32}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def accessor(gltf, blob: bytes, index: int) -> np.ndarray:
    """The accessor's values as float64 (normalized integers mapped to [-1, 1] or [0, 1] as
    glTF 2.0 section 3.11 says), ``[count, width]`` or ``[count]``; integers unnormalized
    stay integers."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = np.dtype(DTYPES[acc.componentType])
    width = WIDTHS[acc.type]
    stride = view.byteStride or dtype.itemsize * width
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    raw = np.frombuffer(blob, np.uint8, stride * (acc.count - 1) + dtype.itemsize * width, start)
    rows = np.lib.stride_tricks.as_strided(
        raw, shape=(acc.count, dtype.itemsize * width), strides=(stride, 1)
    )
    values = np.ascontiguousarray(rows).view(dtype).reshape(acc.count, width)
    if acc.normalized:
        limit = np.iinfo(dtype).max
        values = np.maximum(values / limit, -1.0) if dtype.kind == "i" else values / limit
    elif dtype.kind == "f":
        values = values.astype(np.float64)
    return values if width > 1 else values[:, 0]


class Decoded(NamedTuple):
    positions: np.ndarray  # [T, M, 3] in the scene (node transform applied)
    normals: np.ndarray | None  # [T, M, 3] unit
    faces: np.ndarray | None
    attributes: dict  # base attributes by name (decoded)
    node: object


def decode_animation(gltf, blob: bytes) -> Decoded:
    """Frame k of fourd's morph animation: base + target k-1 (weights are one-hot)."""
    node = gltf.nodes[0]
    primitive = gltf.meshes[node.mesh].primitives[0]
    names = [n for n in vars(primitive.attributes) if getattr(primitive.attributes, n) is not None]
    attributes = {n: accessor(gltf, blob, getattr(primitive.attributes, n)) for n in names}
    base = attributes["POSITION"]
    targets = primitive.targets or []
    positions = [base] + [base + accessor(gltf, blob, t["POSITION"]) for t in targets]
    scale = np.asarray(node.scale if node.scale else [1.0, 1.0, 1.0])
    translation = np.asarray(node.translation if node.translation else [0.0, 0.0, 0.0])
    assert not node.rotation and not node.matrix
    positions = np.stack(positions) * scale + translation
    normals = None
    if "NORMAL" in attributes:
        n0 = attributes["NORMAL"]
        normals = np.stack([n0] + [n0 + accessor(gltf, blob, t["NORMAL"]) for t in targets])
        normals = normals / np.linalg.norm(normals, axis=2, keepdims=True)
    faces = None
    if primitive.indices is not None:
        faces = accessor(gltf, blob, primitive.indices).reshape(-1, 3).astype(np.int64)
    return Decoded(positions, normals, faces, attributes, node)


# what KHR_mesh_quantization allows (component type, normalized) per attribute; core glTF
# allows only the float rows of POSITION and NORMAL
FLOAT = (5126, False)
ALLOWED = {
    "POSITION": {FLOAT, (5120, True), (5120, False), (5121, True), (5121, False),
                 (5122, True), (5122, False), (5123, True), (5123, False)},
    "NORMAL": {FLOAT, (5120, True), (5122, True)},
    "TEXCOORD_0": {FLOAT, (5120, True), (5120, False), (5121, True), (5121, False),
                   (5122, True), (5122, False), (5123, True), (5123, False)},
    "COLOR_0": {FLOAT, (5121, True), (5123, True)},
    "target POSITION": {FLOAT, (5120, True), (5120, False), (5122, True), (5122, False)},
    "target NORMAL": {FLOAT, (5120, True), (5122, True)},
}


def check_structure(gltf, blob: bytes) -> None:
    """The rules of glTF 2.0 (sections 3.6.2.4 data alignment, 3.6.2.5 bounds, 3.7.2.1
    POSITION bounds) and of KHR_mesh_quantization that fourd's writer could break: accessors
    inside their views and views inside the buffer, every vertex attribute element 4-byte
    aligned, POSITION bounds equal to the stored values, component types the attribute
    allows, the extension declared (used and required) whenever it is needed."""
    assert gltf.buffers[0].byteLength == len(blob)
    for view in gltf.bufferViews:
        assert (view.byteOffset or 0) + view.byteLength <= len(blob)
        assert view.byteStride is None or (4 <= view.byteStride <= 252 and view.byteStride % 4 == 0)
    needs_extension = False
    for mesh in gltf.meshes:
        for primitive in mesh.primitives:
            used = [(name, index) for name, index in vars(primitive.attributes).items()
                    if index is not None]
            for target in primitive.targets or []:
                used += [(f"target {name}", index) for name, index in target.items()]
            for name, index in used:
                acc = gltf.accessors[index]
                view = gltf.bufferViews[acc.bufferView]
                size = np.dtype(DTYPES[acc.componentType]).itemsize * WIDTHS[acc.type]
                stride = view.byteStride or size
                assert ((view.byteOffset or 0) + (acc.byteOffset or 0)) % 4 == 0, name
                assert stride % 4 == 0 and stride >= size, name
                assert (acc.byteOffset or 0) + stride * (acc.count - 1) + size <= view.byteLength
                kind = (acc.componentType, bool(acc.normalized))
                if not name.startswith("_"):
                    assert kind in ALLOWED[name], (name, kind)
                    needs_extension |= kind != FLOAT and name != "COLOR_0" and (
                        name != "TEXCOORD_0" or kind not in {(5121, True), (5123, True)})
                if name.endswith("POSITION"):
                    acc_normalized, acc.normalized = acc.normalized, False
                    try:
                        raw = accessor(gltf, blob, index)
                    finally:
                        acc.normalized = acc_normalized
                    assert np.allclose(acc.min, raw.min(axis=0)) and np.allclose(acc.max, raw.max(axis=0))
    extension = "KHR_mesh_quantization"
    if needs_extension:
        assert extension in (gltf.extensionsUsed or []) and extension in (gltf.extensionsRequired or [])
    else:
        assert extension not in (gltf.extensionsRequired or [])
