"""Small handles of a mesh (topological noise) opened, to be capped like holes.

A surface reconstructed from scans grows tiny handles where two sheets of the surface face each
other a few point spacings apart (between the legs, under an arm): the per-frame surface
perforates the gap into a web of tunnels, and a whole animation that takes one frame's
connectivity keeps them (``experiments/assembly_handles.py``: crane's first frame, genus 0-22
with the scan's noise).

A handle is found as a ball that is not a disk: the faces within ``hops`` edges of a vertex
whose Euler characteristic ``V - E + F`` is at most 0 (a disk has 1). Removing such a ball's
faces and capping each loop of the opening with a disk lowers the genus by ``g + b - 1 >= 1``
(the ball's own genus ``g`` and boundary loops ``b``), unless the removal splits the surface (a
thin part cut through), which is refused. Balls that reach a boundary of the mesh are left
alone: around a hole a ball is an annulus, and the hole is closed anyway. This is a local form
of topological noise removal (Guskov and Wood, Topological noise removal, Graphics Interface
2001: handles found as non-disk neighbourhoods and cut), with the capping left to
:func:`fourd.geometry.hole_filling.fill_holes`.

Examples
--------
>>> import trimesh
>>> torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.05, major_sections=64, minor_sections=6)
>>> keep = open_small_handles(torus.vertices, torus.faces)
>>> int((~keep).sum()) > 0  # the thin ring is one small handle: a ball around it is cut out
True
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.boundary_loops import boundary_edges, boundary_loops
from fourd.geometry.fans import fan_count
from fourd.geometry.meshes import face_pieces, vertex_adjacency

__all__ = ["ball_euler", "capped_genus", "open_small_handles"]


def capped_genus(faces: np.ndarray, count: int) -> int:
    """The genus the surface ``faces [F, 3]`` (``count`` vertices) would have with every
    boundary loop capped by a disk, summed over its pieces (faces joined by sides): ``(2 C -
    chi - loops) / 2``, with a vertex where separate fans of faces meet (a pinch) counted once
    per fan, as if pulled apart."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return 0
    sides = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    euler = fan_count(faces) - len(np.unique(sides[:, 0] * np.int64(count) + sides[:, 1])) + len(faces)
    return (2 * face_pieces(faces)[0] - euler - len(boundary_loops(faces, count))) // 2


def ball_euler(faces: np.ndarray, count: int, hops: int, seeds: np.ndarray | None = None,
               alive: np.ndarray | None = None) -> np.ndarray:
    """The Euler characteristic of the faces within ``hops`` edges of each seed (all vertices by
    default), counting only the ``alive [F]`` faces: int64 ``[S]``. A ball that touches a
    boundary side of the mesh comes back 1, as a disk."""
    faces = np.asarray(faces, dtype=np.int64)
    alive = np.ones(len(faces), dtype=bool) if alive is None else np.asarray(alive, dtype=bool)
    seeds = np.arange(count) if seeds is None else np.asarray(seeds, dtype=np.int64)
    live = faces[alive]
    adjacency = vertex_adjacency(live, count) if len(live) else sp.csr_matrix((count, count))
    on_boundary = np.zeros(count, dtype=bool)
    on_boundary[boundary_edges(live, count).ravel()] = True
    incidence = sp.csr_matrix((np.ones(3 * len(live)), (live.ravel(), np.repeat(np.arange(len(live)), 3))),
                              shape=(count, len(live)))
    across = _across(live, count)
    return _ball_euler(adjacency.indptr, adjacency.indices, incidence.indptr, incidence.indices, live, across,
                       on_boundary, int(hops), seeds)


def _across(faces: np.ndarray, count: int) -> np.ndarray:
    """``[F, 3]``: the face across each side (side ``k`` from corner ``k`` to ``k + 1``), -1 on
    a boundary or a side of more than two faces."""
    sides = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    keys = np.minimum(sides[:, 0], sides[:, 1]) * np.int64(count) + np.maximum(sides[:, 0], sides[:, 1])
    order = np.argsort(keys, kind="stable")
    _, start, counts = np.unique(keys[order], return_index=True, return_counts=True)
    across = np.full(len(keys), -1, dtype=np.int64)
    pairs = start[counts == 2]
    a, b = order[pairs], order[pairs + 1]
    across[a], across[b] = b // 3, a // 3
    return across.reshape(-1, 3)


@numba.njit(cache=True)
def _ball_euler(indptr, indices, face_ptr, face_index, faces, across, on_boundary, hops, seeds):
    count, face_count = len(indptr) - 1, len(faces)
    vertex_mark = np.full(count, -1, dtype=np.int64)
    face_mark = np.full(face_count, -1, dtype=np.int64)
    depth = np.zeros(count, dtype=np.int64)
    queue = np.empty(count, dtype=np.int64)
    inside = np.empty(face_count, dtype=np.int64)
    result = np.ones(len(seeds), dtype=np.int64)
    for s in range(len(seeds)):
        seed = seeds[s]
        vertex_mark[seed] = s
        depth[seed] = 0
        queue[0] = seed
        head, tail, touches = 0, 1, on_boundary[seed]
        while head < tail:
            v = queue[head]
            head += 1
            if depth[v] == hops:
                continue
            for j in range(indptr[v], indptr[v + 1]):
                w = indices[j]
                if vertex_mark[w] != s:
                    vertex_mark[w] = s
                    depth[w] = depth[v] + 1
                    queue[tail] = w
                    tail += 1
                    touches = touches or on_boundary[w]
        if touches:
            continue
        found = 0
        for q in range(tail):
            v = queue[q]
            for j in range(face_ptr[v], face_ptr[v + 1]):
                f = face_index[j]
                if face_mark[f] != s and vertex_mark[faces[f, 0]] == s and vertex_mark[faces[f, 1]] == s \
                        and vertex_mark[faces[f, 2]] == s:
                    face_mark[f] = s
                    inside[found] = f
                    found += 1
        used = 0
        for q in range(tail):
            v = queue[q]
            for j in range(face_ptr[v], face_ptr[v + 1]):
                if face_mark[face_index[j]] == s:
                    used += 1
                    break
        rim = 0
        for i in range(found):
            for k in range(3):
                g = across[inside[i], k]
                if g < 0 or face_mark[g] != s:
                    rim += 1
        result[s] = used - (3 * found + rim) // 2 + found
    return result


def open_small_handles(vertices: np.ndarray, faces: np.ndarray, *, hops: int = 3,
                       most: int = 256) -> np.ndarray:
    """Which faces to keep so that the mesh's small handles (those a ball of ``hops`` edges
    holds) are opened: bool ``[F]``. Capping the openings (they are boundary loops like any
    hole) gives a surface of lower genus. At most ``most`` balls are cut; none that would split
    a piece of the surface in two. ``vertices`` only size the mesh (the test is combinatorial)."""
    faces = np.asarray(faces, dtype=np.int64)
    count = len(vertices)
    keep = np.ones(len(faces), dtype=bool)
    if len(faces) == 0 or capped_genus(faces, count) <= 0:
        return keep
    euler = ball_euler(faces, count, hops)
    candidates = np.flatnonzero(euler <= 0)
    candidates = candidates[np.argsort(euler[candidates], kind="stable")]
    pieces = face_pieces(faces)[0]
    adjacency = vertex_adjacency(faces, count)
    incidence = sp.csr_matrix((np.ones(3 * len(faces)), (faces.ravel(), np.repeat(np.arange(len(faces)), 3))),
                              shape=(count, len(faces)))
    blocked = np.zeros(count, dtype=bool)
    inside = np.zeros(count, dtype=bool)
    cut = 0
    for seed in candidates:
        if cut >= most:
            break
        if blocked[seed]:
            continue
        ball = _ball(adjacency, seed, hops)
        inside[ball] = True
        near = _faces_at(incidence, ball)
        region = near[keep[near] & inside[faces[near]].all(axis=1)]
        inside[ball] = False
        region = _without_pinches(faces, keep, region, incidence)
        trial = keep.copy()
        trial[region] = False
        # an opening of one loop cannot split a piece; one of several may (a thin part cut through)
        if len(boundary_loops(faces[region], count)) > 1 and face_pieces(faces[trial])[0] > pieces:
            blocked[ball] = True
            continue
        keep = trial
        # no later ball meets this one, so the Euler characteristics found above still hold
        blocked[_ball(adjacency, seed, 2 * hops + 1)] = True
        cut += 1
    return keep


def _faces_at(incidence: sp.csr_matrix, vertices: np.ndarray) -> np.ndarray:
    """The faces with a corner among ``vertices`` (``incidence``: vertex -> face)."""
    return np.unique(incidence[vertices].indices)


def _without_pinches(faces: np.ndarray, keep: np.ndarray, region: np.ndarray, incidence: sp.csr_matrix,
                     rounds: int = 8) -> np.ndarray:
    """The faces ``region`` (indices) grown so that no vertex on its rim is left with two or
    more separate fans of kept faces (a bow-tie, which capping would leave pinched): such a
    vertex's faces join the region."""
    for _ in range(rounds):
        corners = np.unique(faces[region])
        around = _faces_at(incidence, corners)
        around = around[keep[around] & ~np.isin(around, region)]
        rim = np.intersect1d(corners, faces[around])
        if not len(rim):
            return region
        star = np.searchsorted(rim, faces[around].ravel())
        star = np.bincount(star[rim[np.minimum(star, len(rim) - 1)] == faces[around].ravel()], minlength=len(rim))
        sides = np.sort(np.stack([faces[around], np.roll(faces[around], -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
        keys, shared = np.unique(sides, axis=0, return_counts=True)
        inner = keys[shared == 2].ravel()
        at = np.searchsorted(rim, inner)
        inner_at = np.bincount(at[rim[np.minimum(at, len(rim) - 1)] == inner], minlength=len(rim))
        # faces around a rim vertex minus the sides two of them share: its fans
        pinched = rim[star - inner_at > 1]
        if not len(pinched):
            return region
        grown = _faces_at(incidence, pinched)
        region = np.union1d(region, grown[keep[grown]])
    return region


def _ball(adjacency: sp.csr_matrix, seed: int, hops: int) -> np.ndarray:
    """The vertices within ``hops`` edges of ``seed``."""
    reached = {int(seed)}
    front = [int(seed)]
    indptr, indices = adjacency.indptr, adjacency.indices
    for _ in range(hops):
        step = []
        for v in front:
            for w in indices[indptr[v]:indptr[v + 1]].tolist():
                if w not in reached:
                    reached.add(w)
                    step.append(w)
        front = step
    return np.fromiter(reached, dtype=np.int64, count=len(reached))
