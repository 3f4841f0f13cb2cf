"""The holes of a garment's closed surface re-triangulated and re-projected on the base mesh,
in turn with the parameterisation (Popa's thesis, section 3.6.2, after Kraevoy and Sheffer
2005).

:func:`~fourd.methods.garment.base_mesh.closed_surface` closes the holes the cameras left by
the C1 membrane of equation 3.1 with uniform weights: the membrane's shape and triangles owe
nothing to the map onto the base, and a large hole's membrane stretches the map. The thesis
iterates instead between re-triangulating the holes and re-parameterising the surface:

1. the surface parameterised onto the base (:func:`~.base_mesh.parameterize_onto_base`);
2. each hole's triangles re-triangulated on the base: its edges flipped to the Delaunay
   triangulation of its vertices' places on the base (:func:`delaunay_flips`; the vertices
   stay, and the holes' rims are not touched);
3. the hole's vertices placed in space by equation 3.1 with the normalised mean-value weights
   of the base embedding (:func:`base_mean_value_weights`) and the thesis' C1 terms at the rim
   (:func:`fourd.geometry.hole_filling.membrane_positions`): a hole laid out evenly on the
   base is filled evenly in space;

and again from 1, as long as the map's stretch falls (:func:`reparameterize_holes`).

Not as the thesis: no vertices are added or removed in step 2, and the openings' cones keep
their triangles (the thesis makes a small cone at the anchor and re-triangulates the gap between
it and the opening's loop with the holes).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from fourd.geometry.hole_filling import membrane_positions
from fourd.geometry.meshes import face_adjacency
from fourd.methods.garment.base_mesh import (
    BaseMesh,
    BaseParameterization,
    _facet_frame,
    _in_frame,
    _unfoldings,
    closed_surface,
    parameterize_onto_base,
)

__all__ = ["ClosedOnBase", "base_mean_value_weights", "delaunay_flips", "reparameterize_holes"]

#: Rounds of re-triangulation, re-projection and re-parameterisation at most (fewer once the
#: map's stretch no longer falls).
ROUNDS = 4
#: Passes of edge flips per re-triangulation at most.
FLIP_PASSES = 50


class ClosedOnBase(NamedTuple):
    """A garment's surface closed and parameterised onto the base with its holes re-triangulated
    and re-projected (:func:`reparameterize_holes`).

    vertices : float64 [N + K + M, 3]
        The surface's vertices, the anchors, then the holes' ``M`` vertices (re-projected).
    faces : int64 [G, 3]
        The closed surface's faces (the holes' re-triangulated).
    apex : int64 [K]
        The anchors' vertices.
    filled : bool [N + K + M]
        The holes' vertices.
    parameterization : BaseParameterization
        The map of the last round.
    stretches : list of float
        The map's L2 stretch (relative) after each round, the first before any re-projection.
    flips : list of int
        Edges flipped in each re-triangulation.
    """

    vertices: np.ndarray
    faces: np.ndarray
    apex: np.ndarray
    filled: np.ndarray
    parameterization: BaseParameterization
    stretches: list
    flips: list


def _base_places(parameterization: BaseParameterization, base: BaseMesh):
    """Each vertex's facet ``home [N]`` and place ``uv [N, 2]`` in that facet's plane, with the
    facets' frames and the unfoldings between them (:func:`~.base_mesh._unfoldings`)."""
    frames = np.array([_facet_frame(base.vertices[face]) for face in base.faces])
    home = np.maximum(parameterization.vertex_facet, 0)
    uv = np.einsum("nk,nkd->nd", parameterization.vertex_barycentric, frames[home])
    rotation, shift = _unfoldings(base, frames)
    return home, uv, rotation, shift


def base_mean_value_weights(faces: np.ndarray, home: np.ndarray, uv: np.ndarray, rotation: np.ndarray,
                            shift: np.ndarray, count: int) -> sp.csr_matrix:
    """Floater's mean-value weights of the base embedding, normalised per row, ``[N, N]``: each
    face laid out in the facet of the corner whose weights it gives (its other corners unfolded
    over the base edges between), ``w_ij = (tan(a/2) + tan(b/2)) / |u_i - u_j|`` from the angles
    ``a, b`` at ``u_i`` beside the edge. A corner whose face is degenerate on the base gives
    nothing."""
    faces = np.asarray(faces, dtype=np.int64)
    rows, cols, values = [], [], []
    for k in range(3):
        layout = _in_frame(faces, home, uv, home[faces[:, k]], rotation, shift)  # [F, 3, 2]
        to_j = layout[:, (k + 1) % 3] - layout[:, k]
        to_m = layout[:, (k + 2) % 3] - layout[:, k]
        len_j, len_m = np.linalg.norm(to_j, axis=1), np.linalg.norm(to_m, axis=1)
        cosine = np.einsum("fd,fd->f", to_j, to_m) / np.maximum(len_j * len_m, 1e-300)
        half = np.tan(0.5 * np.arccos(np.clip(cosine, -1.0, 1.0)))
        good = (len_j > 1e-12) & (len_m > 1e-12) & np.isfinite(half)
        rows += [faces[good, k], faces[good, k]]
        cols += [faces[good, (k + 1) % 3], faces[good, (k + 2) % 3]]
        values += [half[good] / len_j[good], half[good] / len_m[good]]
    weights = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                            shape=(count, count))
    total = np.asarray(weights.sum(axis=1)).ravel()
    return (sp.diags(1.0 / np.where(total > 0, total, 1.0)) @ weights).tocsr()


def _edges_of(faces: np.ndarray):
    """Every interior edge ``(a, b)`` with the face holding ``a -> b`` (left), the face holding
    ``b -> a`` (right) and the corners opposite it in each: ``(left, right, a, b, c, d)`` arrays
    (from :func:`fourd.geometry.meshes.face_adjacency`)."""
    pairs, edges = face_adjacency(faces)
    left, right = pairs[:, 0], pairs[:, 1]
    u, v = edges[:, 0], edges[:, 1]
    forward = ((faces[left] == u[:, None]) & (np.roll(faces, -1, axis=1)[left] == v[:, None])).any(axis=1)
    a, b = np.where(forward, u, v), np.where(forward, v, u)
    return left, right, a, b, faces[left].sum(axis=1) - u - v, faces[right].sum(axis=1) - u - v


def _angles(at: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The signed angles ``[Q]`` at ``at`` from ``p`` to ``q`` (points ``[Q, 2]``)."""
    u, v = p - at, q - at
    return np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], np.einsum("qd,qd->q", u, v))


def _turns(o: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Twice the signed areas ``[Q]`` of the triangles ``o, p, q`` (points ``[Q, 2]``)."""
    return (p[:, 0] - o[:, 0]) * (q[:, 1] - o[:, 1]) - (p[:, 1] - o[:, 1]) * (q[:, 0] - o[:, 0])


def delaunay_flips(faces: np.ndarray, flippable: np.ndarray, home: np.ndarray, uv: np.ndarray,
                   rotation: np.ndarray, shift: np.ndarray, fixed: set | None = None) -> tuple[np.ndarray, int]:
    """The ``flippable [F]`` faces re-triangulated towards the Delaunay triangulation of their
    vertices' places on the base: an edge between two flippable faces whose opposite angles on
    the base sum over pi is flipped, when the quadrilateral is convex there, the new edge is
    not an edge already and the old one is not in ``fixed`` (sorted vertex pairs: the charts'
    paths); passes of non-adjacent flips until none is left (at most :data:`FLIP_PASSES`).
    Returns the new faces (same count and order of rows) and the number of flips."""
    faces = np.array(faces, dtype=np.int64)
    fixed = set() if fixed is None else fixed
    flippable = np.asarray(flippable, dtype=bool)
    flips = 0
    for _ in range(FLIP_PASSES):
        left, right, a, b, c, d = _edges_of(faces)
        existing = {(int(p), int(q)) for p, q in zip(np.minimum(a, b), np.maximum(a, b), strict=True)}
        keep = flippable[left] & flippable[right] & (c != d)
        left, right, a, b, c, d = left[keep], right[keep], a[keep], b[keep], c[keep], d[keep]
        if not len(left):
            break
        # the four corners in the plane of a's facet
        quad = np.stack([a, b, c, d], axis=1)
        target = np.repeat(home[a][:, None], 4, axis=1)
        place = np.einsum("qcxy,qcy->qcx", rotation[home[quad], target], uv[quad]) + shift[home[quad], target]
        pa, pb, pc, pd = place[:, 0], place[:, 1], place[:, 2], place[:, 3]
        # left holds a -> b -> c, right holds b -> a -> d; the flip makes (a, d, c) and (b, c, d)
        sum_opposite = np.abs(_angles(pc, pa, pb)) + np.abs(_angles(pd, pb, pa))
        orientation = np.sign(_turns(pa, pb, pc))
        convex = (np.sign(_turns(pa, pd, pc)) == orientation) & (np.sign(_turns(pb, pc, pd)) == orientation) \
            & (orientation != 0)
        want = np.flatnonzero((sum_opposite > np.pi + 1e-9) & convex)
        if not len(want):
            break
        used = np.zeros(len(faces), dtype=bool)
        done = 0
        for q in want[np.argsort(-sum_opposite[want])]:
            f, g = left[q], right[q]
            if used[f] or used[g] or (min(a[q], b[q]), max(a[q], b[q])) in fixed:
                continue
            new_edge = (min(c[q], d[q]), max(c[q], d[q]))
            if new_edge in existing:
                continue
            faces[f] = (a[q], d[q], c[q])
            faces[g] = (b[q], c[q], d[q])
            used[f] = used[g] = True
            existing.add(new_edge)
            done += 1
        flips += done
        if not done:
            break
    return faces, flips


def reparameterize_holes(
    vertices: np.ndarray,
    faces: np.ndarray,
    openings: list,
    anchors: np.ndarray,
    base: BaseMesh,
    *,
    rounds: int = ROUNDS,
    smooth: float = 1.0,
    guides: list | None = None,
    reach: float = 0.0,
    slide: bool = True,
) -> ClosedOnBase:
    """A garment's surface closed (:func:`~.base_mesh.closed_surface`) and parameterised onto
    ``base``, its holes re-triangulated and re-projected on the base in turn with the
    parameterisation (module docstring), as long as the map's stretch falls; the round with the
    least stretch is returned.

    Parameters
    ----------
    vertices : array [N, 3]; faces : int array [F, 3]
    openings, anchors
        As for :func:`~.base_mesh.closed_surface`.
    base : BaseMesh
    rounds : int
        Re-triangulations and re-projections at most.
    smooth : float
        Weight of the C1 terms at the holes' rims (1: the thesis' C1 membrane; 0: C0).
    guides, reach, slide
        As for :func:`~.base_mesh.parameterize_onto_base` (the paths are guided in the first
        round and kept in the later ones).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    closed, closed_faces, apex = closed_surface(vertices, faces, openings, anchors)
    count = len(closed)
    filled = np.zeros(count, dtype=bool)
    filled[len(vertices) + len(apex):] = True
    first_membrane_face = len(faces) + sum(len(opening) for opening in openings)
    in_hole = np.zeros(len(closed_faces), dtype=bool)
    in_hole[first_membrane_face:] = True
    rims = [np.unique(closed_faces[in_hole][~filled[closed_faces[in_hole]]])] if in_hole.any() else []
    parameterization = parameterize_onto_base(closed, closed_faces, apex, base, guides=guides, reach=reach,
                                              slide=slide)
    best = ClosedOnBase(closed, closed_faces, apex, filled, parameterization, [parameterization.stretch], [])
    stretches, flips = [parameterization.stretch], []
    for _ in range(rounds if filled.any() or in_hole.any() else 0):
        home, uv, rotation, shift = _base_places(parameterization, base)
        on_paths = {(min(u, v), max(u, v)) for path in parameterization.charts.paths
                    for u, v in zip(path[:-1].tolist(), path[1:].tolist(), strict=True)}
        closed_faces, flipped = delaunay_flips(closed_faces, in_hole, home, uv, rotation, shift, on_paths)
        flips.append(flipped)
        if filled.any():
            weights = base_mean_value_weights(closed_faces, home, uv, rotation, shift, count)
            closed = membrane_positions(closed[None], closed_faces, filled, rims, smooth=smooth,
                                        weights=weights)[0]
        parameterization = parameterize_onto_base(closed, closed_faces, apex, base,
                                                  paths=parameterization.charts.paths, slide=slide)
        stretches.append(parameterization.stretch)
        if not parameterization.stretch < best.parameterization.stretch:
            break
        best = ClosedOnBase(closed, closed_faces.copy(), apex, filled, parameterization, [], [])
    return best._replace(stretches=stretches, flips=flips)
