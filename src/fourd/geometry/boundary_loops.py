"""The boundary loops of a triangle mesh, each as its vertices in order.

A boundary edge is a side used by one face only; it is directed as that face runs, so a loop
of an outward-oriented mesh runs the same way around every hole. A vertex where two loops
touch (a "bow tie") splits the walk there, so every boundary edge belongs to exactly one
loop and a loop passes each of its vertices once.

Examples
--------
>>> faces = np.array([[0, 1, 2], [0, 2, 3]])  # a square, one loop of four vertices
>>> [loop.tolist() for loop in boundary_loops(faces, 4)]
[[0, 1, 2, 3]]
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_edges", "boundary_loops"]


def boundary_edges(faces: np.ndarray, count: int) -> np.ndarray:
    """The sides of ``faces [F, 3]`` that no other face shares, directed as their face runs:
    int64 ``[B, 2]`` (from, to) over ``count`` vertices."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if not len(faces):
        return np.zeros((0, 2), dtype=np.int64)
    a, b = faces.ravel(), np.roll(faces, -1, axis=1).ravel()
    keys = np.minimum(a, b) * np.int64(count) + np.maximum(a, b)
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    single = counts[inverse] == 1
    return np.stack([a[single], b[single]], axis=1)


def boundary_loops(faces: np.ndarray, count: int) -> list[np.ndarray]:
    """Every boundary loop of ``faces [F, 3]`` (``count`` vertices) as int64 vertex indices in
    order, the longest (most vertices) first. A closed mesh has none."""
    edges = boundary_edges(faces, count)
    if not len(edges):
        return []
    order = np.argsort(edges[:, 0], kind="stable")
    starts = edges[order, 0]
    first_out = np.searchsorted(starts, np.arange(count + 1))  # edges leaving v: first_out[v]:first_out[v+1]
    used = np.zeros(len(edges), dtype=bool)
    loops = []
    for seed in range(len(order)):
        if used[seed]:
            continue
        loop = []
        edge = seed
        while not used[edge]:
            used[edge] = True
            frm, to = edges[order[edge]]
            loop.append(frm)
            candidates = np.arange(first_out[to], first_out[to + 1])
            free = candidates[~used[candidates]]
            if not len(free):
                break
            edge = free[0]
        loops.extend(_simple_loops(loop))
    loops.sort(key=len, reverse=True)
    return loops


def _simple_loops(walk: list) -> list[np.ndarray]:
    """A closed walk split where it passes a vertex twice (loops touching at a bow-tie
    vertex) into loops that each pass every vertex once."""
    loops, stack, position = [], [], {}
    for vertex in walk:
        if vertex in position:
            start = position[vertex]
            loop = stack[start:]
            loops.append(np.asarray(loop, dtype=np.int64))
            for v in loop[1:]:
                del position[v]
            del stack[start + 1 :]
        else:
            position[vertex] = len(stack)
            stack.append(vertex)
    if stack:
        loops.append(np.asarray(stack, dtype=np.int64))
    return loops
