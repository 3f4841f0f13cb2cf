"""The colour of a truth's surface where a camera ray hits it: albedo x shading.

A :class:`Paint` ties an albedo kind and seed to a ground truth: the albedo of a hit is
:func:`fourd.synth.albedo.albedo` at the hit's rest-surface position (the barycentric
combination of its triangle's rest vertices; the truth's ``rest``, else its first frame), so the
colour moves with the material. Shading uses the hit's smooth normal (vertex normals of the
frame, interpolated) turned towards the viewer (a sheet is coloured on both sides; a closed
surface is only seen from outside), lit by :class:`fourd.synth.shading.Lamps`.

A :class:`~fourd.MeshSequence` truth has no correspondence and no rest surface: its albedo is
evaluated at the hit's own position in space (a texture that does not follow the material).
A point truth (an AnimatedMesh without faces) colours point ``i`` by the albedo of its
first-frame position.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.synth.albedo import albedo, check_appearance
from fourd.synth.shading import Lamps, shaded_colors


@dataclass(frozen=True, eq=False)
class Paint:
    """The appearance of one truth.

    Attributes
    ----------
    kind : {"skin", "cloth", "uniform"}
    seed : int
    rest : ndarray [N, 3] or None
        Rest-surface vertex positions (None: a MeshSequence, coloured where it is).
    bounds : ndarray [2, 3]
        Bounds the pattern is laid out in (the rest surface's, or the truth's over all frames).
    lamps : Lamps
    """

    kind: str
    seed: int
    rest: np.ndarray | None
    bounds: np.ndarray
    lamps: Lamps = field(default_factory=Lamps)


def truth_paint(truth, kind: str, seed: int = 0, *, lamps: Lamps | None = None) -> Paint:
    """The :class:`Paint` of ``truth`` (AnimatedMesh or MeshSequence) with albedo ``kind``."""
    kind = check_appearance(kind)
    if kind is None:
        raise InputError("a paint needs an appearance: skin or cloth")
    lamps = Lamps() if lamps is None else lamps
    if isinstance(truth, AnimatedMesh):
        rest = truth.rest if truth.rest is not None else truth.vertices[0]
        bounds = np.stack([rest.min(axis=0), rest.max(axis=0)])
        return Paint(kind, int(seed), np.asarray(rest, dtype=np.float64), bounds, lamps)
    if isinstance(truth, MeshSequence):
        return Paint(kind, int(seed), None, truth.bounds(), lamps)
    raise InputError(f"the truth must be an AnimatedMesh or a MeshSequence, got {type(truth).__name__}")


def barycentric(points, corners) -> np.ndarray:
    """Barycentric coordinates ``[P, 3]`` of ``points [P, 3]`` in triangles ``corners [P, 3, 3]``
    (of the point's projection onto the triangle's plane; degenerate triangles give thirds)."""
    points = np.asarray(points, dtype=np.float64)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e0, e1, d = b - a, c - a, points - a
    d00 = np.einsum("ij,ij->i", e0, e0)
    d01 = np.einsum("ij,ij->i", e0, e1)
    d11 = np.einsum("ij,ij->i", e1, e1)
    d20 = np.einsum("ij,ij->i", d, e0)
    d21 = np.einsum("ij,ij->i", d, e1)
    denominator = d00 * d11 - d01 * d01
    safe = np.where(np.abs(denominator) > 1e-300, denominator, 1.0)
    v = np.where(denominator != 0, (d11 * d20 - d01 * d21) / safe, 1.0 / 3.0)
    w = np.where(denominator != 0, (d00 * d21 - d01 * d20) / safe, 1.0 / 3.0)
    return np.stack([1.0 - v - w, v, w], axis=1)


def hit_albedo(paint: Paint, vertices, faces, triangle, points) -> np.ndarray:
    """Albedo ``[P, 3]`` of hits ``points [P, 3]`` on triangles ``triangle [P]`` of the frame
    ``(vertices, faces)``."""
    triangle = np.asarray(triangle, dtype=np.int64)
    if paint.rest is None:
        where = np.asarray(points, dtype=np.float64)
    else:
        corners = faces[triangle]
        weights = barycentric(points, vertices[corners])
        where = np.einsum("pk,pkj->pj", weights, paint.rest[corners])
    return albedo(where, paint.kind, bounds=paint.bounds, seed=paint.seed)


def hit_normals(vertex_normals, vertices, faces, triangle, points, directions) -> np.ndarray:
    """Smooth unit normals ``[P, 3]`` at hits (interpolated ``vertex_normals [N, 3]``) turned
    against the ray ``directions [P, 3]`` (facing the viewer)."""
    corners = faces[np.asarray(triangle, dtype=np.int64)]
    weights = barycentric(points, vertices[corners])
    normals = np.einsum("pk,pkj->pj", weights, vertex_normals[corners])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    facing = np.einsum("ij,ij->i", normals, directions) > 0
    normals[facing] *= -1.0
    return normals


def hit_colors(
    paint: Paint, vertices, faces, vertex_normals, triangle, points, directions, *, noise=0.0, rng=None
) -> np.ndarray:
    """Recorded colours ``[P, 3]`` in [0, 1] of hits: albedo x shading + noise (see module)."""
    base = hit_albedo(paint, vertices, faces, triangle, points)
    normals = hit_normals(vertex_normals, vertices, faces, triangle, points, directions)
    sky = hit_sky(paint, vertices, faces, vertex_normals, triangle, points, directions) if paint.lamps.diffuse else None
    return shaded_colors(base, normals, noise=noise, rng=rng, lamps=paint.lamps, sky=sky)


def hit_sky(paint: Paint, vertices, faces, vertex_normals, triangle, points, directions) -> np.ndarray:
    """The diffuse sky's share ``[P]`` at hits (:func:`fourd.synth.shading.accessibility` of
    the side facing the viewer, interpolated over the hit triangle)."""
    from fourd.synth.shading import DIFFUSE_REACH, accessibility

    vertices = np.asarray(vertices, dtype=np.float64)
    reach = DIFFUSE_REACH * float(np.linalg.norm(paint.bounds[1] - paint.bounds[0]))
    outside = accessibility(vertices, faces, vertex_normals, reach=reach)
    inside = accessibility(vertices, faces, -np.asarray(vertex_normals), reach=reach)
    corners = faces[np.asarray(triangle, dtype=np.int64)]
    weights = barycentric(points, vertices[corners])
    normals = np.einsum("pk,pkj->pj", weights, vertex_normals[corners])
    facing_out = np.einsum("ij,ij->i", normals, directions) < 0
    return np.where(facing_out, np.einsum("pk,pk->p", weights, outside[corners]),
                    np.einsum("pk,pk->p", weights, inside[corners]))
