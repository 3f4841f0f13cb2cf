"""Per-frame mass levels: the closed meshes moved along their normals so that the volume
each encloses follows the flow's conserved mass (:func:`mass_meshes`).
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from fourd.geometry.laplacian import laplacian_smooth
from fourd.geometry.meshes import face_areas, face_volumes
from fourd.geometry.normals import vertex_normals

log = logging.getLogger("fourd.methods.flow")


def _mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume enclosed by a closed mesh (:func:`fourd.geometry.meshes.face_volumes` summed)."""
    return float(face_volumes(vertices, faces).sum())


def _mesh_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Surface area of a triangle mesh."""
    return float(face_areas(vertices, faces).sum())


def _volume_gradient(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``d volume / d vertex`` [N, 3] of a closed mesh (``a . (b x c) / 6`` per face)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    gradient = np.zeros_like(vertices)
    for k, term in enumerate((np.cross(b, c), np.cross(c, a), np.cross(a, b))):
        for axis in range(3):
            gradient[:, axis] += np.bincount(faces[:, k], term[:, axis], len(vertices))
    return gradient / 6.0


def mass_meshes(
    meshes: list[tuple[np.ndarray, np.ndarray]],
    points: list[np.ndarray | None],
    mass: np.ndarray,
    *,
    h: float,
    reach: float = 0.5,
    limit: float = 4.0,
    smoothing: int = 100,
    steps: int = 3,
    all_or_nothing: bool = False,
    observed_cell: float | None = None,
    target: float | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The frames' closed meshes with their unobserved parts moved so that each frame's
    enclosed volume follows the flow's (conserved) mass.

    Every frame's target is ``V0``, the mean enclosed volume of ``meshes``: the overall size
    stays the Laplace solve's, and the flow, which conserves mass, says it does not change
    (its per-frame ``mass`` [T] only marks the frames to move, those with mass; until
    a66da0d the targets followed it, ``mass[i] * V0 / mean(mass)``, and with it the solver's
    error: ``squash-ball`` volume change 3.0%, at ``V0`` 0.9%, ``exp``). Each vertex has a weight ``u = clip(d / c - reach, 0,
    1)`` (``c``: ``observed_cell``) from its distance ``d`` to the frame's nearest data point: what lies on the data
    stays, what no scanner saw moves. The unobserved parts are first smoothed (``smoothing``
    umbrella steps, each vertex's step scaled by ``u`` and by the frame's strength ``b``: the
    flow leaves dents and bumps where it cannot follow the motion, and then the frame's volume
    is off; ``b`` is the first (linear) offset that would reach the target, in flow cells, at
    most 1, so a frame whose volume the flow got right keeps the shape it carried into its
    unseen parts), then every vertex moves along its normal by ``s_i u``, one
    offset per frame (``steps`` Newton steps on the exact mesh volume, at most ``limit``
    flow cells either way) that sets the volume. A frame without points moves as a whole.
    With ``all_or_nothing``, ``meshes`` come back unchanged when some frame's first (linear)
    offset exceeds its mean radius ``3 V / A``: the unobserved parts cannot account for the
    volume differences, so the object is not incompressible (or more than its unseen parts
    is off).

    Parameters
    ----------
    meshes : T closed (vertices [N, 3], faces [F, 3]) pairs.
    points : T data point arrays [P, 3] (or None), input units.
    mass : float [T], the flow mass per frame (input units^3).
    h : float, the flow cell (input units).
    observed_cell : float, optional
        The length unit of ``reach`` and of the weight's ramp (input units; default ``h``).
    target : float, optional
        The volume every frame is moved to (input units^3; default ``V0``, the mean
        contoured volume of ``meshes``): a windowed flow carries it from window to window.
    """
    cell = h if observed_cell is None else observed_cell
    volumes = np.array([_mesh_volume(v, f) for v, f in meshes])
    mass = np.asarray(mass, float)
    good = (volumes > 0) & (mass > 0)
    if not good.any():
        return list(meshes)
    # one target for every frame, the mean contoured volume: the flow conserves mass, and its
    # per-frame mass deviates from the mean only by the capped solves' error (squash-ball:
    # 1.2%; volumes that followed it changed by 3.0%, at the mean by 0.9%)
    target = volumes[good].mean() if target is None else float(target)
    out = list(meshes)
    for i in np.flatnonzero(good):
        vertices, faces = meshes[i]
        if points[i] is None or len(points[i]) == 0:
            free = np.ones(len(vertices))
        else:
            distance, _ = cKDTree(points[i]).query(
                vertices, distance_upper_bound=(reach + 1.0) * cell, workers=-1
            )
            free = np.clip(np.minimum(distance, (reach + 1.0) * cell) / cell - reach, 0.0, 1.0)
        if smoothing:
            strength = _smoothing_strength(vertices, faces, free, target - volumes[i], h=h)
            if strength > 0:
                vertices = laplacian_smooth(
                    vertices, faces, iterations=smoothing, weights=strength * free
                )
        direction = free[:, None] * vertex_normals(vertices, faces)
        shift, moved = 0.0, vertices
        for step in range(steps):
            volume = _mesh_volume(moved, faces)
            slope = _volume_slope(moved, faces, direction)
            if slope <= 0 or abs(volume - target) <= 1e-4 * target:
                break
            proposal = shift + (target - volume) / slope
            if step == 0 and all_or_nothing:
                radius = 3.0 * volume / _mesh_area(vertices, faces)
                if abs(proposal) > radius:
                    log.info(
                        "flow: frame %d asks its unobserved parts to move by %.1f flow cells, "
                        "more than its mean radius (%.1f): volumes left as contoured "
                        "(mass_levels=auto)", i, proposal / h, radius / h,
                    )
                    return list(meshes)
            shift = float(np.clip(proposal, -limit * h, limit * h))
            moved = vertices + shift * direction
        out[i] = (moved, faces)
    return out


def _volume_slope(vertices: np.ndarray, faces: np.ndarray, direction: np.ndarray) -> float:
    """Rate of change of the enclosed volume as ``vertices`` move along ``direction`` [N, 3]
    (input units^2 per unit of offset)."""
    return float(np.einsum("ij,ij->", _volume_gradient(vertices, faces), direction))


def _smoothing_strength(
    vertices: np.ndarray,
    faces: np.ndarray,
    free: np.ndarray,
    deficit: float,
    *,
    h: float,
) -> float:
    """How strongly to smooth a frame's unobserved parts, in [0, 1]: their first (linear)
    offset towards the volume target ``deficit`` away, in flow cells ``h``, at most 1."""
    slope = _volume_slope(vertices, faces, free[:, None] * vertex_normals(vertices, faces))
    if slope <= 0:
        return 1.0
    return float(min(abs(deficit) / slope / h, 1.0))
