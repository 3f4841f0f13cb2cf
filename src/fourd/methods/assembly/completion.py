"""Geometry only the target has, pasted into the union mesh (thesis section 5.6, second half).

After a pair map the union mesh (the source's connectivity) has a position in the target frame
for every vertex. A target triangle whose three corners lie farther than ``gap`` from that
placed union mesh is geometry the source lacks (a hole of the source's scan that the target
saw); connected such triangles form a patch. Each boundary loop of a patch is matched to the
boundary loop of the union mesh (the hole's rim) that runs beside it, and the band between the
two loops is triangulated, so the two connectivities become one (:func:`zip_loops`). The
thesis maps the union's rim onto the target, cuts the target's triangles along it and remeshes
the seam in the plane; here the seam band is the triangles of ``gap`` width that the patch
leaves out, and it is triangulated by the shortest-diagonal zipper (the strip triangulation of
Fuchs, Kedem and Uselton 1977) between the two loops: the same union of connectivities, with a
band one triangle wide. A patch whose loops do not all find a rim of their own shape (a partial
overlap, a sheet's border) is left out and counted.

The patch's positions in the target's frames are the target's own; in the source's frames they
are placed by the Laplacian coordinates of the union mesh in the target frame with the union's
vertices held (:func:`fourd.methods.assembly.registration.register_by_laplacian`, [LSA+05]),
over the patch and a few rings of the union around it (rows farther away hold no unknown).

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

__all__ = ["Paste", "paste_target_only", "place_pasted", "zip_loops"]

#: A patch loop and a union rim match when every point of each lies within the gap plus this
#: many edges of the other.
RIM_SLACK = 3.0
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
        Patches left out (no matching rim, or a rim already taken).
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


def zip_loops(rim: np.ndarray, loop: np.ndarray, positions: np.ndarray) -> np.ndarray | None:
    """Triangles ``[K, 3]`` of the band between two closed loops of vertex ids: ``rim`` as the
    union's faces run along it, ``loop`` as the patch's faces run along it (so the two run
    opposite ways around the band). Each step adds the triangle whose new diagonal is shorter
    (``positions [V, 3]``); every rim and loop edge is used once, against its own face's
    direction, so the glued mesh stays consistently oriented. None when the loops are not
    side by side (they run the same way around the band)."""
    along = loop[::-1]  # now parallel to the rim
    p_rim, p_along = positions[rim], positions[along]
    start = int(cKDTree(p_along).query(p_rim[0])[1])
    along = np.roll(along, -start)
    p_along = np.roll(p_along, -start, axis=0)
    # parallel loops: their tangents at nearest points agree
    t_rim = np.roll(p_rim, -1, axis=0) - p_rim
    t_along = np.roll(p_along, -1, axis=0) - p_along
    nearest = cKDTree(p_along).query(p_rim)[1]
    if np.sum(t_rim * t_along[nearest]) <= 0.0:
        return None
    m, n = len(rim), len(along)
    faces = []
    i = j = 0
    while i < m or j < n:
        u0, u1 = rim[i % m], rim[(i + 1) % m]
        t0, t1 = along[j % n], along[(j + 1) % n]
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


def _loop_distance(a: np.ndarray, b: np.ndarray) -> float:
    """The larger directed distance between two point sets (their Hausdorff distance over the
    points)."""
    return max(float(cKDTree(b).query(a)[0].max()), float(cKDTree(a).query(b)[0].max()))


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
    if len(patch_faces) < min_faces:
        return empty
    _, piece = vertex_components(patch_faces, len(target))
    face_piece = piece[patch_faces[:, 0]]
    rims = boundary_loops(faces, count)
    taken = np.zeros(len(rims), dtype=bool)
    new_faces, new_target = [], []
    patches = skipped = 0
    next_id = count
    for label in np.unique(face_piece):
        own = patch_faces[face_piece == label]
        if len(own) < min_faces:
            continue
        loops = boundary_loops(own, len(target))
        matched = []
        for loop in loops:
            best, best_distance = -1, np.inf
            for r, rim in enumerate(rims):
                if taken[r] or r in {m for m, _ in matched}:
                    continue
                d = _loop_distance(target[loop], union[rim])
                if d < best_distance:
                    best, best_distance = r, d
            if best < 0 or best_distance > (gap + RIM_SLACK) * edge:
                break
            matched.append((best, loop))
        if len(matched) != len(loops) or not loops:
            skipped += 1
            continue
        vertices = np.unique(own)
        ids = np.full(len(target), -1, dtype=np.int64)
        ids[vertices] = next_id + np.arange(len(vertices))
        # the union's positions, then the patches' so far and this one's (the ids' order)
        full = np.vstack([union, *[target[v] for v in new_target], target[vertices]])
        seams = []
        for r, loop in matched:
            seam = zip_loops(rims[r], ids[loop], full)
            if seam is None:
                break
            seams.append(seam)
        if len(seams) != len(matched):
            skipped += 1
            continue
        for r, _ in matched:
            taken[r] = True
        new_faces += [ids[own], *seams]
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
    """Positions ``[V, 3]`` of the pasted vertices (``known`` False) in another frame whose
    union positions are ``points`` (rows of ``known`` vertices), by the Laplacian coordinates
    of ``reference [V, 3]`` (the union with its patches in the target frame), solved over the
    patches and :data:`PLACEMENT_RINGS` rings of union vertices around them."""
    count = len(reference)
    adjacency = vertex_adjacency(faces, count)
    near = ~known
    for _ in range(PLACEMENT_RINGS):
        near = near | (adjacency @ near.astype(np.int64) > 0)
    local = faces[near[faces].all(axis=1)]
    ids = np.flatnonzero(near)
    index = np.full(count, -1, dtype=np.int64)
    index[ids] = np.arange(len(ids))
    local_points = np.zeros((len(ids), 3))
    local_points[known[ids]] = points[ids[known[ids]]]
    placed = register_by_laplacian(
        reference[ids], index[local], known[ids], local_points, iterations=iterations
    )
    result = np.array(points, dtype=np.float64)
    result[~known] = placed[index[~known]]
    return result
