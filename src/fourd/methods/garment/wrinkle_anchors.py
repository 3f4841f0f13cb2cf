"""Where the video says the garment folds: anchor triangles and their rotations (Popa's thesis,
sections 4.4 "View Selection" and 4.5.1).

Per frame:

1. **Best views.** Each camera scores the garment by the area it sees facing it (visible face
   area times the cosine to the camera); the ``views`` best are searched (the thesis picks the
   most frontal front and back views from two tracked normals; this needs no user's clicks).
2. **Fold edges** in each chosen image (:func:`.fold_edges.fold_edges`), inside the garment's
   image less a band along its silhouette.
3. **Anchor triangles.** Each edge pixel's triangle is the visible face nearest it in the
   image (the faces' centres z-buffered in the camera). A pair is dropped when either edge
   leaves the garment or runs along its silhouette (a face seen at a grazing angle), as in the
   thesis.
4. **Rotation.** The anchor triangle turns about the edge (the image tangent carried onto the
   face's plane) so that the edge's darker side goes deeper, away from the camera ("dark equals
   deep", 4.3.1). The thesis' angle runs from 60 degrees for the frame's narrowest fold to 30
   for its widest, inversely to the pair's width. *Beyond the thesis*: the angle is measured
   from the garment's low-passed surface (:mod:`fourd.geometry.low_pass`), not from the face as
   it is, so a fold the capture already has is not folded again: the anchor's rotation is the
   one taking the face's normal to the low-passed normal turned by the angle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.ndimage import binary_erosion
from scipy.spatial.transform import Rotation

from fourd.appearance.cameras import Camera, project, rays
from fourd.appearance.depth import frame_view
from fourd.geometry.meshes import face_areas
from fourd.geometry.surface_walk import face_unit_normals
from fourd.methods.garment.fold_edges import FoldEdgeOptions, FoldPair, fold_edges

__all__ = ["AnchorOptions", "FrameAnchors", "frame_anchors", "rotation_between"]


@dataclass(frozen=True)
class AnchorOptions:
    """Where the fold anchors come from (thesis 4.4-4.5.1).

    Attributes
    ----------
    views : int
        Cameras searched per frame, the most frontal first (the thesis: a front and a back view
        of sixteen cameras; with the three of a small rig, every camera finds more).
    narrow_angle, wide_angle : float
        Anchor rotation, degrees, for the frame's narrowest and widest fold pair (the thesis: 60
        and 30), inversely proportional to the pair's width in between.
    grazing : float
        Smallest cosine between an anchor face's normal and its camera ray; a pair with an
        edge on faces seen more obliquely runs along the silhouette and is dropped.
    silhouette_band : int
        Pixels of the garment's image along its silhouette where edges are not searched.
    on_garment : float
        Smallest fraction of an edge's pixels that must land on the garment.
    edges : FoldEdgeOptions
        The fold-edge filter's parameters (Table 4.1).
    """

    views: int = 3
    narrow_angle: float = 60.0
    wide_angle: float = 30.0
    grazing: float = 0.3
    silhouette_band: int = 3
    on_garment: float = 0.8
    edges: FoldEdgeOptions = field(default_factory=FoldEdgeOptions)


class FrameAnchors(NamedTuple):
    """One frame's anchors: ``faces`` [A] (indices, each once), ``rotations`` [A, 3] (rotation
    vectors, radians), ``pairs`` (fold pairs found), ``used`` (pairs that gave anchors),
    ``views`` (camera indices searched)."""

    faces: np.ndarray
    rotations: np.ndarray
    pairs: int
    used: int
    views: tuple[int, ...]


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation vectors [K, 3] of the smallest rotations taking unit vectors ``a`` [K, 3] to
    ``b`` [K, 3] (axis ``a x b``, angle ``arccos(a . b)``; the thesis' 4.5.5)."""
    axis = np.cross(a, b)
    sine = np.linalg.norm(axis, axis=1)
    cosine = np.einsum("ij,ij->i", a, b)
    angle = np.arctan2(sine, cosine)
    with np.errstate(invalid="ignore", divide="ignore"):
        vectors = axis * np.where(sine > 1e-12, angle / sine, 0.0)[:, None]
    return vectors


def _view_scores(cameras, centres, normals, areas, views) -> list[float]:
    scores = []
    for camera, view in zip(cameras, views, strict=True):
        toward = camera.center - centres[view.index]
        toward /= np.linalg.norm(toward, axis=1, keepdims=True)
        scores.append(float((areas[view.index] * np.abs(np.einsum("ij,ij->i", toward, normals[view.index]))).sum()))
    return scores


def _on_plane(camera: Camera, uv: np.ndarray, origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Where the rays through pixels ``uv`` [K, 2] cut the planes through ``origin`` [K, 3]
    with ``normal`` [K, 3]; [K, 3] (NaN where a ray runs along its plane)."""
    direction = rays(camera, uv)
    centre = camera.center
    denominator = np.einsum("ij,ij->i", direction, normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = np.einsum("ij,ij->i", origin - centre, normal) / denominator
    return centre + distance[:, None] * direction


def _edge_anchors(edge, camera, view, centres, normals, reach, options):
    """(faces [K], axes [K, 3], dark sides [K, 3], towards the camera [K, 3]) of one fold
    edge's pixels, or None when it leaves the garment or runs along the silhouette."""
    points = edge.points
    distance, nearest = view.tree.query(points, distance_upper_bound=reach)
    hit = np.isfinite(distance)
    if hit.mean() < options.on_garment:
        return None
    faces = view.index[nearest[hit]]
    ray = rays(camera, points[hit])
    if np.median(np.abs(np.einsum("ij,ij->i", ray, normals[faces]))) < options.grazing:
        return None
    tangent = np.gradient(points, axis=0)[hit]
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    left = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)  # image y points down
    origin = _on_plane(camera, points[hit], centres[faces], normals[faces])
    axis = _on_plane(camera, points[hit] + tangent, centres[faces], normals[faces]) - origin
    dark = _on_plane(camera, points[hit] + left, centres[faces], normals[faces]) - origin
    good = np.isfinite(axis).all(axis=1) & np.isfinite(dark).all(axis=1)
    if not good.any():
        return None
    axis = axis[good] / np.maximum(np.linalg.norm(axis[good], axis=1, keepdims=True), 1e-300)
    return faces[good], axis, dark[good], camera.center - origin[good]


def frame_anchors(
    vertices: np.ndarray,
    faces: np.ndarray,
    base_vertices: np.ndarray,
    cameras,
    images,
    options: AnchorOptions | None = None,
) -> FrameAnchors:
    """The anchors of one frame (module docstring).

    Parameters
    ----------
    vertices : array [N, 3]
        The garment in this frame.
    faces : array [F, 3]
    base_vertices : array [N, 3]
        The same garment low-passed (the folds' reference for the rotation angles).
    cameras : sequence of Camera
    images : sequence of array [H, W] or [H, W, 3]
        This frame's image from each camera.
    options : AnchorOptions
    """
    options = options or AnchorOptions()
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    centres = vertices[faces].mean(axis=1)
    normals = face_unit_normals(vertices, faces)
    base_normals = face_unit_normals(np.asarray(base_vertices, dtype=np.float64), faces)
    areas = face_areas(vertices, faces)
    edge = float(np.sqrt(np.median(areas) * 4 / np.sqrt(3)))
    views, reaches = [], []
    for camera in cameras:
        _, depth = project(camera, centres)
        pixels = camera.K[0, 0] * edge / max(float(np.median(depth[depth > 0])) if (depth > 0).any() else 1.0, 1e-12)
        reaches.append(max(1.5, pixels))
        views.append(frame_view(camera, centres, tolerance=edge, radius=max(1.0, 0.75 * pixels)))
    scores = _view_scores(cameras, centres, normals, areas, views)
    order = [int(c) for c in np.argsort(scores)[::-1][: options.views] if scores[c] > 0]
    found, used = [], 0
    pair_count = 0
    for c in order:
        camera, view = cameras[c], views[c]
        garment = view.depth.index >= 0
        mask = binary_erosion(garment, iterations=options.silhouette_band) if options.silhouette_band else garment
        pairs: list[FoldPair] = fold_edges(images[c], options.edges, mask=mask)
        pair_count += len(pairs)
        kept = []
        for pair in pairs:
            sides = [_edge_anchors(e, camera, view, centres, normals, reaches[c], options)
                     for e in (pair.first, pair.second)]
            if any(side is None for side in sides):
                continue
            kept.append((pair, sides))
        if not kept:
            continue
        widths = np.array([pair.distance for pair, _ in kept])
        narrow = widths.min()
        for (_, sides), width in zip(kept, widths, strict=True):
            angle = np.radians(np.clip(options.narrow_angle * narrow / width, options.wide_angle, options.narrow_angle))
            for anchor_faces, axis, dark, toward in sides:
                # the turn about the edge that moves the darker side away from the camera
                sign = -np.sign(np.einsum("ij,ij->i", np.cross(axis, dark), toward))
                turned = Rotation.from_rotvec((sign * angle)[:, None] * axis).apply(base_normals[anchor_faces])
                found.append((anchor_faces, rotation_between(normals[anchor_faces], turned)))
            used += 1
    if not found:
        return FrameAnchors(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), pair_count, 0, tuple(order))
    anchor_faces = np.concatenate([f for f, _ in found])
    rotations = np.concatenate([r for _, r in found])
    unique, inverse = np.unique(anchor_faces, return_inverse=True)
    summed = np.zeros((len(unique), 3))
    np.add.at(summed, inverse, rotations)
    counts = np.bincount(inverse, minlength=len(unique))
    return FrameAnchors(unique, summed / counts[:, None], pair_count, used, tuple(order))
