"""Geometry only the target has, pasted into the union mesh (thesis section 5.6, second half).

After a pair map the union mesh (the source's connectivity) has a position in the target frame
for every vertex. A target triangle whose three corners lie farther than ``gap`` from that
placed union mesh is geometry the source lacks (a hole of the source's scan that the target
saw); connected such triangles form a patch. A patch boundary that runs beside a boundary loop
of the union (a hole's rim) all the way round is glued to the whole rim; otherwise each run of
its vertices beside one rim is glued to the stretch of the rim beside it, so a hole the target
fills only in part keeps the rest open (:func:`zip_strip`). The thesis maps the union's rim
onto the target, cuts the target's triangles along it and remeshes the seam in the plane; here
the seam band is the triangles of ``gap`` width that the patch leaves out, triangulated by the
shortest-diagonal zipper (the strip triangulation of Fuchs, Kedem and Uselton 1977) between the
two runs: the same union of connectivities, with a band one triangle wide. A patch with no run
beside any rim is left out and counted (it would float).

The patch's positions in the target's frames are the target's own; in the source's frames they
are placed frame by frame, from the one next to the target back to the first, each by the
Laplacian coordinates of the union mesh in the frame after it with the union's vertices held
(:func:`fourd.methods.assembly.registration.register_by_laplacian`, [LSA+05]), over the patch
and a few rings of the union around it (rows farther away hold no unknown).

References
----------
T. Popa, PhD thesis (004_f87f5acf96d50b57.txt) section 5.6 and figure 5.9; H. Fuchs, Z. M.
Kedem, S. P. Uselton, "Optimal surface reconstruction from planar contours", CACM 1977.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.meshes import median_edge_length, vertex_adjacency, vertex_components
from fourd.methods.assembly.registration import register_by_laplacian

__all__ = ["Paste", "paste_target_only", "place_pasted", "zip_strip"]

#: A patch boundary vertex is beside a rim when it lies within the gap plus this many edges
#: of it.
RIM_SLACK = 3.0
#: Fewest vertices of a patch boundary's run beside a rim that are glued to it.
MIN_RUN = 4
#: The rings of union vertices around a patch that its Laplacian placement reads.
PLACEMENT_RINGS = 3


class Paste(NamedTuple):
    """The union mesh with the target-only patches glued in.

    faces : int64 [F', 3]
        The union's faces first, then the patches' and the seams'.
    target : int64 [M]
        The target vertex each new vertex is (new vertex ``N + k`` is ``target[k]``).
    patch : int64 [M]
        The patch each new vertex belongs to (0 to ``patches - 1``).
    patches : int
        Patches glued in.
    skipped : int
        Patches left out (no run of their boundary beside a rim not glued already).
    """

    faces: np.ndarray
    target: np.ndarray
    patch: np.ndarray
    patches: int
    skipped: int


def _surface_samples(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Vertices, edge midpoints and face centres: a dense enough sampling of the mesh for
    distances of about an edge."""
    corners = vertices[faces]
    midpoints = 0.5 * (corners + np.roll(corners, -1, axis=1))
    return np.vstack([vertices, midpoints.reshape(-1, 3), corners.mean(axis=1)])


def zip_strip(rim: np.ndarray, along: np.ndarray, positions: np.ndarray, *, closed: bool) -> np.ndarray:
    """Triangles ``[K, 3]`` of the band between two runs of vertex ids that go side by side in
    the same direction: ``rim`` as the union's faces run along it, ``along`` the patch's
    boundary against its faces' direction. ``closed``: both are whole loops (wrapping round);
    else open runs whose first and last vertices face each other. Each step adds the triangle
    whose new diagonal is shorter (``positions [V, 3]``); every rim and patch edge of the runs
    is used once, against its own face's direction, so the glued mesh stays consistently
    oriented."""
    m, n = (len(rim), len(along)) if closed else (len(rim) - 1, len(along) - 1)
    faces = []
    i = j = 0
    while i < m or j < n:
        u0, u1 = rim[i % len(rim)], rim[(i + 1) % len(rim)]
        t0, t1 = along[j % len(along)], along[(j + 1) % len(along)]
        advance_rim = j >= n or (
            i < m
            and np.linalg.norm(positions[u1] - positions[t0]) <= np.linalg.norm(positions[u0] - positions[t1])
        )
        if advance_rim:
            faces.append((u1, u0, t0))
            i += 1
        else:
            faces.append((u0, t0, t1))
            j += 1
    return np.asarray(faces, dtype=np.int64)


def _parallel(p_rim: np.ndarray, p_along: np.ndarray) -> bool:
    """Whether two runs of points go the same way: their tangents at nearest points agree."""
    t_rim = np.diff(p_rim, axis=0)
    t_along = np.diff(p_along, axis=0)
    if not len(t_rim) or not len(t_along):
        return False
    nearest = np.minimum(cKDTree(p_along).query(p_rim[:-1])[1], len(t_along) - 1)
    return bool(np.sum(t_rim * t_along[nearest]) > 0.0)


def _runs(flags: np.ndarray) -> list[np.ndarray]:
    """The maximal runs of True in a cyclic sequence, as index arrays in order (one run
    covering everything when all are True)."""
    count = len(flags)
    if flags.all():
        return [np.arange(count)]
    if not flags.any():
        return []
    start = int(np.flatnonzero(~flags)[0]) + 1  # begin just after a False
    order = (start + np.arange(count)) % count
    runs, current = [], []
    for k in order:
        if flags[k]:
            current.append(k)
        elif current:
            runs.append(np.array(current))
            current = []
    if current:
        runs.append(np.array(current))
    return runs


def _seams(along, rims, rim_of, place, tree, positions, used, limit, min_run):
    """The seams ``(rim run, along run, closed)`` that glue one patch boundary ``along`` (ids,
    against the patch's face direction) to the union's rims: the whole loop to a whole rim
    that runs beside it, else each run of at least ``min_run`` of its vertices within
    ``limit`` of one rim to the stretch of that rim beside it. Rim vertices in ``used`` are
    not glued twice."""
    distance, nearest = tree.query(positions[along])
    near = distance <= limit
    rim_id = rim_of[nearest]
    if near.all() and (rim_id == rim_id[0]).all():
        rim = rims[rim_id[0]]
        if not used[rim].any():
            back, facing = cKDTree(positions[along]).query(positions[rim])
            if back.max() <= limit:
                start = int(facing[0])
                rolled = np.roll(along, -start)
                if _parallel(positions[np.r_[rim, rim[:1]]], positions[np.r_[rolled, rolled[:1]]]):
                    return [(rim, rolled, True)]
                return []
    seams = []
    for run in _runs(near):
        # split where the nearest rim changes
        cuts = np.flatnonzero(np.diff(rim_id[run])) + 1
        for piece in np.split(run, cuts):
            if len(piece) < min_run:
                continue
            rim = rims[rim_id[piece[0]]]
            first, last = place[nearest[piece[0]]], place[nearest[piece[-1]]]
            span = (last - first) % len(rim)
            if span < 1 or span > 2 * len(piece) + 4:  # not side by side, or going the other way
                continue
            segment = rim[(first + np.arange(span + 1)) % len(rim)]
            if used[segment].any() or not _parallel(positions[segment], positions[along[piece]]):
                continue
            seams.append((segment, along[piece], False))
            used[segment] = True
    return seams


def paste_target_only(
    union: np.ndarray,
    faces: np.ndarray,
    target: np.ndarray,
    target_faces: np.ndarray,
    *,
    gap: float = 2.0,
    min_faces: int = 8,
) -> Paste:
    """Glue the target-only patches into the union mesh (module docstring).

    Parameters
    ----------
    union : float64 [N, 3]
        The union mesh's vertices placed in the target frame.
    faces : int [F, 3]
        Its faces (the source's connectivity).
    target : float64 [Nt, 3], target_faces : int [Ft, 3]
        The target frame's mesh.
    gap : float
        Target triangles farther than this many target edges from the union are target-only.
    min_faces : int
        Smaller patches are left out (scan debris).
    """
    faces = np.asarray(faces, dtype=np.int64)
    target_faces = np.asarray(target_faces, dtype=np.int64)
    count = len(union)
    none = np.zeros(0, dtype=np.int64)
    empty = Paste(faces, none, none, 0, 0)
    if not len(target_faces) or not len(faces):
        return empty
    edge = max(median_edge_length(target, target_faces), median_edge_length(union, faces))
    distance, _ = cKDTree(_surface_samples(union, faces)).query(target, workers=-1)
    far = distance > gap * edge
    patch_faces = target_faces[far[target_faces].all(axis=1)]
    rims = boundary_loops(faces, count)
    if len(patch_faces) < min_faces or not rims:
        return empty
    _, piece = vertex_components(patch_faces, len(target))
    face_piece = piece[patch_faces[:, 0]]
    rim_vertices = np.concatenate(rims)
    rim_of = np.repeat(np.arange(len(rims)), [len(r) for r in rims])
    place = np.concatenate([np.arange(len(r)) for r in rims])
    tree = cKDTree(union[rim_vertices])
    used = np.zeros(count, dtype=bool)
    limit = (gap + RIM_SLACK) * edge
    new_faces, new_target = [], []
    patches = skipped = 0
    next_id = count
    for label in np.unique(face_piece):
        own = patch_faces[face_piece == label]
        if len(own) < min_faces:
            continue
        vertices = np.unique(own)
        ids = np.full(len(target), -1, dtype=np.int64)
        ids[vertices] = next_id + np.arange(len(vertices))
        # the union's positions, then the patches' so far and this one's (the ids' order)
        positions = np.vstack([union, *[target[v] for v in new_target], target[vertices]])
        trial = used.copy()
        seams = []
        for loop in boundary_loops(own, len(target)):
            seams += _seams(ids[loop[::-1]], rims, rim_of, place, tree, positions, trial, limit, MIN_RUN)
        if not seams:
            skipped += 1
            continue
        used = trial
        for seam in seams:
            used[seam[0]] = True
        new_faces += [ids[own]] + [zip_strip(rim, along, positions, closed=closed) for rim, along, closed in seams]
        new_target.append(vertices)
        next_id += len(vertices)
        patches += 1
    if not patches:
        return Paste(faces, none, none, 0, skipped)
    patch = np.concatenate([np.full(len(v), k, dtype=np.int64) for k, v in enumerate(new_target)])
    return Paste(np.vstack([faces, *new_faces]), np.concatenate(new_target), patch, patches, skipped)


def place_pasted(
    reference: np.ndarray, faces: np.ndarray, known: np.ndarray, points: np.ndarray, *, iterations: int = 16
) -> np.ndarray:
    """Positions ``[V, 3]`` (or ``[T, V, 3]``) of the pasted vertices (``known`` False) in the
    frames before the target, whose union positions are ``points`` (rows of ``known``
    vertices), by Laplacian coordinates solved over the patches and :data:`PLACEMENT_RINGS`
    rings of union vertices around them. The frames are consecutive, the last one just before
    the target, and are placed from the last to the first, each by the Laplacian coordinates of
    the one after it (``reference [V, 3]``, the union with its patches in the target frame, for
    the last): the pasted geometry follows the registered motion of its surroundings frame by
    frame, so each solve starts from a pose a frame away instead of the whole block away."""
    count = len(reference)
    points = np.asarray(points, dtype=np.float64)
    if known.all():
        return points.copy()
    adjacency = vertex_adjacency(faces, count)
    near = ~known
    for _ in range(PLACEMENT_RINGS):
        near = near | (adjacency @ near.astype(np.int64) > 0)
    local = faces[near[faces].all(axis=1)]
    ids = np.flatnonzero(near)
    index = np.full(count, -1, dtype=np.int64)
    index[ids] = np.arange(len(ids))
    frames = points.reshape(-1, count, 3)
    result = frames.copy()
    before = np.asarray(reference, dtype=np.float64)[ids]
    for t in range(len(frames) - 1, -1, -1):
        local_points = np.zeros((len(ids), 3))
        local_points[known[ids]] = frames[t, ids[known[ids]]]
        placed = register_by_laplacian(before, index[local], known[ids], local_points, iterations=iterations)
        result[t, ~known] = placed[index[~known]]
        # a vertex the local solve could not place (NaN) keeps the pose it had a frame later
        before = np.where(np.isnan(placed), before, placed)
    return result.reshape(points.shape)
