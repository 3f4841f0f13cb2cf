"""The garment template fitted onto one frame's surface.

The thesis maps its template into every frame through a common base-mesh parameterisation
(sections 3.6.2 and 3.7). Here the template is carried from frame to frame by an
as-rigid-as-possible fit to each frame's mesh instead (Sorkine and Alexa 2007's local and
global steps; the data in both directions: each template vertex to its closest frame vertex
whose normal agrees, each frame vertex to its closest template vertex), with the thesis'
boundary anchors as its strongest data: each of the garment's openings on the template is
pulled onto the same opening in the frame (the boundary points of the ellipse tracked there,
:mod:`.boundary_tracking`). Where the frame has no data (the underarms the cameras miss), the
template keeps its own shape, carried as rigidly as possible: the template's completion of 3.7.

The data hold a vertex only across the frame's surface (point to plane: the distance along the
closest point's normal) and an opening's vertex only across the opening (point to line): the
fabric slides along both to where the fit's rigidity puts it. Closest points held as points
stop the template where it entered the frame, on the surface but slid (an untextured
garment's twist followed by a quarter; ``experiments/garment_plain_drift.py``).

:func:`align_template` places a template (say one inflated from a photo) on the first frame by
the similarity that best maps its openings' ellipses onto the frame's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from fourd.geometry.laplacian import cotangent_weights, weights_laplacian
from fourd.geometry.normals import vertex_normals
from fourd.geometry.projector_sums import projector_sums
from fourd.geometry.rotations import arap_right_hand_side, one_ring_rotations, procrustes

__all__ = ["FitOptions", "align_template", "fit_template"]


@dataclass(frozen=True)
class FitOptions:
    """The as-rigid-as-possible fit of the template to a frame.

    Attributes
    ----------
    iterations : int
        Local/global iterations per frame.
    data_weight : float
        Weight of the closest-point data, in units of a vertex's stiffness (its Laplacian
        diagonal).
    boundary_weight : float
        Weight of an opening's vertices pulled onto the frame's same opening, same units.
    anchor_weight : float
        Weight of the video anchors' guide, same units (times each guided vertex's weight).
    project : bool
        Finally move each vertex with agreeing data onto the frame's surface along the
        surface's normal (to the plane of its closest frame vertex).
    reject : float
        Closest pairs farther apart than this many median template edges are ignored.
    normal_angle : float
        Closest pairs whose normals differ by more than this (degrees) are ignored.
    slide : bool
        Hold each vertex only across the frame's surface and each opening's vertex only across
        the opening, so they slide along them (module docstring); False: pull them to the
        closest points themselves.
    """

    iterations: int = 10
    data_weight: float = 0.5
    boundary_weight: float = 4.0
    anchor_weight: float = 2.0
    project: bool = True
    reject: float = 4.0
    normal_angle: float = 60.0
    slide: bool = True


def fit_template(
    rest: np.ndarray,
    faces: np.ndarray,
    start: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    *,
    openings: list | None = None,
    guide=None,
    options: FitOptions | None = None,
) -> np.ndarray:
    """The template ``(rest [N, 3], faces)`` fitted onto a frame's mesh from ``start [N, 3]``.

    Parameters
    ----------
    openings : list of (template vertex indices, frame points [M, 3]), optional
        Per garment opening: the template's loop and the frame's boundary points of the same
        opening (an empty array when the frame lost it); each template vertex is pulled onto
        the closest of those points (across the opening only, with ``options.slide``).
    guide : fourd.appearance.guide.Guide, optional
        Where the video's anchors say vertices went, pulled with ``options.anchor_weight``
        times the guide's weight.

    Returns
    -------
    ndarray float64 [N, 3]
    """
    options = options or FitOptions()
    rest = np.asarray(rest, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    weights = cotangent_weights(rest, faces, clamp_negative=True)
    laplacian = weights_laplacian(weights).tocsr()
    stiffness = laplacian.diagonal()
    stiffness = np.where(stiffness > 0, stiffness, max(float(stiffness.mean()), 1e-12))
    edges = sp.triu(weights, k=1).tocoo()
    edge = float(np.median(np.linalg.norm(rest[edges.row] - rest[edges.col], axis=1)))
    target_vertices = np.asarray(target_vertices, dtype=np.float64)
    target_normals = vertex_normals(target_vertices, np.asarray(target_faces, dtype=np.int64))
    tree = cKDTree(target_vertices)
    cosine = np.cos(np.radians(options.normal_angle))
    count = len(rest)
    x = np.array(start, dtype=np.float64)
    coupled = sp.kron(laplacian, sp.identity(3), format="csr")
    for _ in range(options.iterations):
        normals = vertex_normals(x, faces)
        pulls = _Pulls(count)
        # template -> frame
        distance, nearest = tree.query(x, workers=-1)
        ok = np.flatnonzero((distance <= options.reject * edge)
                            & (np.einsum("ij,ij->i", normals, target_normals[nearest]) >= cosine))
        pulls.add(ok, target_vertices[nearest[ok]], options.data_weight * stiffness[ok],
                  across=target_normals[nearest[ok]] if options.slide else None)
        # frame -> template: every frame vertex pulls its closest template vertex (their mean)
        back_distance, back = cKDTree(x).query(target_vertices, workers=-1)
        agree = np.flatnonzero((back_distance <= options.reject * edge)
                               & (np.einsum("ij,ij->i", target_normals, normals[back]) >= cosine))
        share = np.bincount(back[agree], minlength=count).astype(np.float64)
        pulled = back[agree]
        pulls.add(pulled, target_vertices[agree], options.data_weight * stiffness[pulled] / share[pulled],
                  across=target_normals[agree] if options.slide else None)
        for loop, points in openings or []:
            points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
            if not len(points):
                continue
            loop = np.asarray(loop, dtype=np.int64)
            _, closest = cKDTree(points).query(x[loop])
            pulls.add(loop, points[closest], options.boundary_weight * stiffness[loop],
                      along=_loop_tangents(x[loop]) if options.slide else None)
        if guide is not None and len(guide.vertices):
            vertices = np.asarray(guide.vertices, dtype=np.int64)
            pulls.add(vertices, np.asarray(guide.positions, dtype=np.float64),
                      options.anchor_weight * np.asarray(guide.weight, dtype=np.float64) * stiffness[vertices])
        if not pulls.any():  # nothing holds it: keep the position (the rotations alone are free)
            break
        rhs = arap_right_hand_side(weights, rest, one_ring_rotations(weights, rest, x))
        system = (coupled + pulls.matrix()).tocsr()
        right = (rhs + pulls.right).ravel()
        # symmetric positive definite and started from the last iterate: a few preconditioned
        # conjugate-gradient steps reach it faster than a factorisation per iteration
        jacobi = sp.diags(1.0 / system.diagonal())
        x = spla.cg(system, right, x0=x.ravel(), rtol=1e-6, maxiter=600, M=jacobi)[0].reshape(count, 3)
    if options.project:
        # onto the frame's surface along its normal where the data agrees: no sliding
        distance, nearest = tree.query(x, workers=-1)
        normals = vertex_normals(x, faces)
        ok = (distance <= options.reject * edge) & (np.einsum("ij,ij->i", normals, target_normals[nearest]) >= cosine)
        offset = np.einsum("ij,ij->i", target_vertices[nearest[ok]] - x[ok], target_normals[nearest[ok]])
        x[ok] += offset[:, None] * target_normals[nearest[ok]]
    return x


class _Pulls:
    """The fit's pulls ``sum w |P (x_v - p)|^2`` gathered per vertex: ``blocks [N, 3, 3]`` (the
    sum of ``w P``) and ``right [N, 3]`` (of ``w P p``), ``P`` the identity, a plane's normal
    projector or a line's normal-plane projector."""

    def __init__(self, count: int):
        self.blocks = np.zeros((count, 3, 3))
        self.right = np.zeros((count, 3))

    def add(self, vertices, points, weights, *, across=None, along=None) -> None:
        """Pull ``vertices [K]`` to ``points [K, 3]`` with ``weights [K]``; with ``across``
        (unit normals [K, 3]) only along the normal, with ``along`` (unit tangents [K, 3]) only
        across the tangent."""
        if across is not None:
            sums = projector_sums(vertices, points, weights, len(self.blocks), directions=across, identity=0.0,
                                  outer=1.0)
        elif along is not None:
            sums = projector_sums(vertices, points, weights, len(self.blocks), directions=along, outer=-1.0)
        else:
            sums = projector_sums(vertices, points, weights, len(self.blocks))
        self.blocks += sums.blocks
        self.right += sums.right

    def any(self) -> bool:
        return bool(self.blocks.any())

    def matrix(self) -> sp.csr_matrix:
        """The blocks as a sparse ``[3N, 3N]`` matrix (row ``3 v + i``)."""
        count = len(self.blocks)
        index = np.arange(3 * count).reshape(count, 1, 3)
        rows = np.broadcast_to(np.swapaxes(index, 1, 2), (count, 3, 3))
        cols = np.broadcast_to(index, (count, 3, 3))
        return sp.csr_matrix((self.blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * count,) * 2)


def _loop_tangents(points: np.ndarray) -> np.ndarray:
    """Unit tangents [L, 3] of an ordered loop (or arc) of ``points [L, 3]``: central
    differences, wrapped."""
    tangents = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    return tangents / np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-300)


def align_template(template_ellipses: list, frame_ellipses: list) -> tuple[np.ndarray, float, np.ndarray]:
    """The similarity ``(R [3, 3], scale, t [3])`` mapping the template's opening ellipses onto
    the frame's (same order): their centres, the points one radius along each axis and along
    each normal, matched in least squares; each axis's sign ambiguity (a fitted ellipse's axes
    have none) is resolved by trying both and keeping the better fit."""
    best = None
    for flip in (1.0, -1.0):
        source, target = [], []
        for a, b in zip(template_ellipses, frame_ellipses, strict=True):
            radius_a, radius_b = a.radii.mean(), b.radii.mean()
            source += [a.center, a.center + radius_a * a.normal,
                       a.center + a.radii[0] * a.axes[0], a.center + a.radii[1] * a.axes[1]]
            target += [b.center, b.center + radius_b * b.normal,
                       b.center + flip * b.radii[0] * b.axes[0], b.center + flip * b.radii[1] * b.axes[1]]
        transform = procrustes(np.array(source), np.array(target), with_scale=True)
        if best is None or transform.rms < best.rms:
            best = transform
    return best.rotation, best.scale, best.translation
