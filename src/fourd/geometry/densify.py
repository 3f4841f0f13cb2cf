"""Densify a sparse scan: mesh the frame on its own and sample its surface more densely.

A tracker whose template is finer than its data has vertices that no point holds, and with
few points per limb the nearest-point pulls of a registration cannot bring a limb back that a
fast motion left behind (issue 56: the whole crane capture at 2,641 points per frame). The
frame's own surface (:func:`fourd.geometry.frame_surface.frame_surface`: an implicit
moving-least-squares surface of its points, clipped to where it has points) interpolates
between the points; sampling it at the template's density gives the tracker data at its own
resolution, and every scale it derives from the point spacing (the fit's error, the data ball,
the data term's bandwidth) follows. Nothing is added where the frame has no points: the
surface is clipped to them, so a hole stays a hole.
"""

from __future__ import annotations

import numpy as np

from fourd.geometry.frame_surface import SurfaceSettings, frame_surface
from fourd.geometry.meshes import face_areas
from fourd.geometry.normals import vertex_normals
from fourd.geometry.surface_samples import sample_surface


def densify_points(
    points: np.ndarray,
    normals: np.ndarray,
    *,
    density: float,
    surface: tuple[np.ndarray, np.ndarray] | None = None,
    sensors: np.ndarray | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Points ``[Q, 3]`` and unit normals ``[Q, 3]`` sampled on the surface of one frame's
    ``points`` ``[P, 3]`` (with their oriented ``normals`` ``[P, 3]``) at ``density`` samples
    per unit area, area-weighted uniform random samples with the mesh's interpolated vertex
    normals (seeded by ``seed``).

    ``surface`` ``(vertices, faces)``: the frame's surface when already made (default: made
    here by :func:`~fourd.geometry.frame_surface.frame_surface` with the frame's normals). The
    input comes back unchanged when the surface is empty (too few points) or would give fewer
    samples than there are points.

    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(800, 3)); p /= np.linalg.norm(p, axis=1, keepdims=True)
    >>> q, n = densify_points(p, p, density=4000 / (4 * np.pi))
    >>> bool(3000 < len(q) < 4200 and np.abs(np.linalg.norm(q, axis=1) - 1).max() < 0.05)
    True
    >>> bool(np.einsum("ij,ij->i", q, n).min() > 0.9)
    True
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if not (np.isfinite(density) and density > 0):
        raise ValueError(f"density must be positive, got {density}")
    if surface is None:
        surface = frame_surface(points, normals=normals, sensors=sensors, settings=SurfaceSettings(seed=seed))
    vertices, faces = surface
    count = int(round(density * float(face_areas(vertices, faces).sum())))
    if count <= len(points):
        return points, normals
    samples = sample_surface(vertices, faces, count, np.random.default_rng(seed))
    corner_normals = vertex_normals(vertices, faces)[faces[samples.faces]]  # [Q, 3, 3]
    sampled_normals = np.einsum("qk,qkd->qd", samples.barycentric, corner_normals)
    sampled_normals /= np.maximum(np.linalg.norm(sampled_normals, axis=1, keepdims=True), 1e-12)
    return samples.points, sampled_normals
