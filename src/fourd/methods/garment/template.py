"""A garment's template mesh from a photo of it laid out flat (Popa's thesis, section 3.7).

The silhouette is taken from the photo (its largest white region), its outline resampled at
the template's edge length and its interior triangulated
(:func:`fourd.geometry.polygon_triangulation.triangulate_polygon`; the thesis uses Shewchuk's
Triangle). The 2D mesh
is duplicated for the back; front and back share the outline's vertices except along the
openings (the garment's boundaries, the user's brush strokes), so a T-shirt comes out with
four boundary loops. The flat double layer is then inflated by the thesis' variant of Mori and
Igarashi's iteration (2007): every face moves a little along its normal (the pressure), then
every vertex moves by the area-weighted mean of its edges' length corrections, which oppose
stretch and, unlike Mori and Igarashi's, compression too (equations 3.2 and 3.3).

The template keeps its pattern coordinates (``uv``: where each vertex lies on the flat
garment), a texture layout for free.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.errors import InputError
from fourd.geometry.polygon_triangulation import resample_polyline, signed_area, triangulate_polygon

__all__ = [
    "Template",
    "TemplateOptions",
    "edge_strain",
    "inflate",
    "outline_from_photo",
    "sew_front_and_back",
    "template_from_photo",
    "template_from_pattern",
    "triangulate_outline",
]


@dataclass(frozen=True)
class TemplateOptions:
    """How the template is built from the photo.

    Attributes
    ----------
    edge : float
        Edge length of the 2D triangulation, garment units.
    iterations : int
        Most inflation iterations (pressure step plus length corrections).
    pressure : float
        How far each face moves along its normal per iteration, in edge lengths.
    corrections : int
        Length-correction passes (equations 3.2-3.3) per iteration.
    tolerance : float
        Inflation stops when an iteration changes the enclosed volume by less than this
        fraction.
    """

    edge: float = 0.04
    iterations: int = 5000
    pressure: float = 0.005
    corrections: int = 10
    tolerance: float = 1e-4


class Template(NamedTuple):
    """A garment template.

    vertices : float64 [N, 3]
    faces : int64 [F, 3]
        Outward-facing (front faces look along +z before inflation, back faces along -z).
    uv : float64 [N, 2]
        Where each vertex lies on the flat pattern (garment units).
    back : bool [N]
        True for the vertices of the back layer (the outline's seam vertices are front).
    rest_lengths : float64 [E]
        Edge lengths of the flat pattern, ``edges [E, 2]`` in the same order.
    edges : int64 [E, 2]
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    back: np.ndarray
    rest_lengths: np.ndarray
    edges: np.ndarray


def outline_from_photo(image: np.ndarray, calibration: dict) -> np.ndarray:
    """The outline ``[K, 2]`` (garment units, counter-clockwise) of the largest bright region of
    a photo ``image [H, W]`` or ``[H, W, C]``, with ``calibration`` as written by
    :func:`fourd.synth.garments.pattern_photo` (``pixels_per_unit``, ``origin``)."""
    import cv2

    image = np.asarray(image)
    if image.ndim == 3:
        image = image[..., :3].mean(axis=2)
    if image.ndim != 2 or not image.size:
        raise InputError(f"the garment photo must be a grey or colour image, got shape {list(image.shape)}")
    mask = (image > 0.5 * float(image.max())).astype(np.uint8) if image.max() > 0 else None
    if mask is None or not mask.any():
        raise InputError("the garment photo has no bright region (the garment, white on black)")
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    # the pixel staircase straightened: within a pixel of the traced outline
    contour = cv2.approxPolyDP(max(contours, key=cv2.contourArea), 1.0, True)[:, 0, :].astype(np.float64)
    scale = float(calibration["pixels_per_unit"])
    origin = np.asarray(calibration["origin"], dtype=np.float64)
    outline = np.column_stack([origin[0] + contour[:, 0] / scale, origin[1] - contour[:, 1] / scale])
    if signed_area(outline) < 0:
        outline = outline[::-1]
    return outline


def _resample(polygon: np.ndarray, edge: float) -> np.ndarray:
    """Points along the closed ``polygon`` about ``edge`` apart, its corners (turns of more
    than 20 degrees) kept."""
    polygon = np.asarray(polygon, dtype=np.float64)
    ahead = np.roll(polygon, -1, axis=0) - polygon
    behind = polygon - np.roll(polygon, 1, axis=0)
    cosine = np.einsum("ij,ij->i", ahead, behind) / np.maximum(
        np.linalg.norm(ahead, axis=1) * np.linalg.norm(behind, axis=1), 1e-300
    )
    corners = np.flatnonzero(cosine < np.cos(np.radians(20)))
    if not len(corners):
        corners = np.array([0])
    # corners closer than half an edge along the outline are one corner
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(ahead, axis=1))])
    kept = [corners[0]]
    for corner in corners[1:]:
        if along[corner] - along[kept[-1]] >= 0.5 * edge:
            kept.append(corner)
    if len(kept) > 1 and along[-1] - along[kept[-1]] + along[kept[0]] < 0.5 * edge:
        kept.pop()
    corners = np.array(kept)
    points = []
    for a, b in zip(corners, np.roll(corners, -1), strict=True):
        piece = polygon[a : b + 1] if b > a else np.concatenate([polygon[a:], polygon[: b + 1]])
        length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(piece, axis=0), axis=1))])
        count = max(1, int(round(length[-1] / edge)))
        at = np.linspace(0.0, length[-1], count + 1)[:-1]
        points.append(np.column_stack([np.interp(at, length, piece[:, k]) for k in range(2)]))
    return np.concatenate(points)


def triangulate_outline(outline: np.ndarray, edge: float):
    """A 2D mesh of the polygon ``outline [K, 2]``: ``(points [P, 2], faces [F, 3]
    counter-clockwise, boundary_count)``; the first ``boundary_count`` points are the outline
    resampled at ``edge``, in order."""
    outline = np.asarray(outline, dtype=np.float64)
    if len(outline) < 3 or abs(signed_area(outline)) < edge**2:
        raise InputError("the garment's outline encloses no area")
    if signed_area(outline) < 0:
        outline = outline[::-1]
    boundary = _resample(outline, edge)
    points, faces = triangulate_polygon(boundary, edge)
    return points, faces, len(boundary)


def sew_front_and_back(points: np.ndarray, faces: np.ndarray, boundary_count: int, openings, edge: float):
    """The flat double layer: ``(vertices [N, 3], faces [F, 3], uv [N, 2], back [N] bool)``.
    The back is a mirrored copy of the 2D mesh; the outline's first ``boundary_count`` points
    are shared by both, except those strictly inside an opening polyline (within a quarter
    ``edge`` of it and farther than that from its ends)."""
    count = len(points)
    boundary = np.arange(boundary_count)
    opening = np.zeros(count, dtype=bool)
    for polyline in openings or []:
        polyline = np.asarray(polyline, dtype=np.float64)
        dense = resample_polyline(polyline, edge / 16)
        on = cKDTree(dense).query(points[boundary])[0] < 0.25 * edge
        ends = np.linalg.norm(points[boundary, None, :] - polyline[[0, -1]][None], axis=2).min(axis=1) > 0.25 * edge
        opening[boundary[on & ends]] = True
    shared = np.zeros(count, dtype=bool)
    shared[boundary] = ~opening[boundary]
    back_index = np.where(shared, np.arange(count), count + np.arange(count))
    keep_back = ~shared
    back_of = back_index[faces][:, [0, 2, 1]]  # mirrored: the back looks the other way
    index = np.full(2 * count, -1, dtype=np.int64)
    used = np.concatenate([np.ones(count, dtype=bool), keep_back])
    index[used] = np.arange(used.sum())
    all_faces = index[np.concatenate([faces, back_of])]
    uv = np.concatenate([points, points[keep_back]])
    vertices = np.column_stack([uv, np.zeros(len(uv))])
    back = np.concatenate([np.zeros(count, dtype=bool), np.ones(keep_back.sum(), dtype=bool)])
    return vertices, all_faces, uv, back


def _unique_edges(faces: np.ndarray) -> np.ndarray:
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(edges, axis=0)


def inflate(vertices: np.ndarray, faces: np.ndarray, edges: np.ndarray, rest_lengths: np.ndarray,
            options: TemplateOptions | None = None) -> tuple[np.ndarray, int]:
    """The double layer inflated (see the module docstring): ``(vertices [N, 3], iterations
    run)``."""
    import scipy.sparse as sp

    options = options or TemplateOptions()
    vertices = np.array(vertices, dtype=np.float64)
    count, edge_count = len(vertices), len(edges)
    i, j = edges[:, 0], edges[:, 1]
    # face -> its corners, averaging the faces' normals at each vertex
    corners = sp.csr_matrix((np.ones(3 * len(faces)), (faces.ravel(), np.repeat(np.arange(len(faces)), 3))),
                            shape=(count, len(faces)))
    corners = sp.diags(1.0 / np.maximum(np.asarray(corners.sum(axis=1)).ravel(), 1)) @ corners
    # face sides -> edges, for the areas of the faces beside each edge
    keys = i * count + j
    sides = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    side_edge = np.searchsorted(keys, sides[:, 0] * count + sides[:, 1])
    beside = sp.csr_matrix((np.ones(len(side_edge)), (side_edge, np.repeat(np.arange(len(faces)), 3))),
                           shape=(edge_count, len(faces)))
    # edge forces -> vertices: +t on i, -t on j
    spread = sp.csr_matrix((np.r_[np.ones(edge_count), -np.ones(edge_count)],
                            (np.r_[i, j], np.r_[np.arange(edge_count), np.arange(edge_count)])),
                           shape=(count, edge_count))
    ends = abs(spread)
    step = options.pressure * options.edge
    volume = 0.0
    for iteration in range(1, options.iterations + 1):
        cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
        vertices += step * (corners @ (cross / np.maximum(np.linalg.norm(cross, axis=1, keepdims=True), 1e-300)))
        for _ in range(options.corrections):
            tri = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
            weight = beside @ (0.5 * np.linalg.norm(tri, axis=1))  # A(left face) + A(right face)
            d = vertices[j] - vertices[i]
            length = np.linalg.norm(d, axis=1)
            # equation 3.3: a stretched edge pulls its ends together, a compressed one pushes them
            # apart (the thesis' addition to Mori and Igarashi)
            factor = np.where(length >= rest_lengths, (length - rest_lengths) / np.maximum(length, 1e-300),
                              (length - rest_lengths) / np.maximum(rest_lengths, 1e-300))
            force = (0.5 * weight * factor)[:, None] * d  # on i; -force on j
            vertices += (spread @ force) / np.maximum(ends @ weight, 1e-300)[:, None]  # equation 3.2
        now = float(np.einsum("ij,ij->i", vertices[faces[:, 0]], cross).sum() / 6.0)
        if iteration > 10 and abs(now - volume) <= options.tolerance * abs(now):
            return vertices, iteration
        volume = now
    return vertices, options.iterations


def edge_strain(template: Template) -> np.ndarray:
    """Per edge ``length / rest length - 1`` [E] (0: neither stretched nor compressed)."""
    d = template.vertices[template.edges[:, 1]] - template.vertices[template.edges[:, 0]]
    return np.linalg.norm(d, axis=1) / template.rest_lengths - 1.0


def template_from_pattern(outline: np.ndarray, openings, options: TemplateOptions | None = None) -> Template:
    """The template of the garment whose flat ``outline [K, 2]`` and ``openings`` (polylines
    along it) are given (see the module docstring)."""
    options = options or TemplateOptions()
    points, faces2d, boundary_count = triangulate_outline(outline, options.edge)
    vertices, faces, uv, back = sew_front_and_back(points, faces2d, boundary_count, openings, options.edge)
    edges = _unique_edges(faces)
    rest = np.linalg.norm(uv[edges[:, 1]] - uv[edges[:, 0]], axis=1)
    inflated, _ = inflate(vertices, faces, edges, rest, options)
    return Template(inflated, faces, uv, back, rest, edges)


def template_from_photo(image: np.ndarray, calibration: dict, options: TemplateOptions | None = None) -> Template:
    """The template from a photo of the garment laid out flat and its calibration
    (``pixels_per_unit``, ``origin``, ``openings``: the format of ``pattern.json``)."""
    outline = outline_from_photo(image, calibration)
    openings = calibration.get("openings")
    if not openings:
        raise InputError("the garment photo's calibration names no openings (the garment's boundaries)")
    return template_from_pattern(outline, openings, options)
