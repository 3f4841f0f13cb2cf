"""Holes of a mesh filled by a smooth membrane (Popa's thesis, section 3.6.2, after Kraevoy
and Sheffer 2005).

Each chosen boundary loop is a hole: its vertices are laid out around a circle (by arc length;
a hole is a disk), the disk is triangulated at the loop's mean edge length
(:func:`fourd.geometry.polygon_triangulation.triangulate_polygon`), and the new inner vertices
are placed in 3D by the least-squares membrane of equation 3.1, ``sum_i |P_i - sum_j w_ij
P_j|^2`` over the hole's inner vertices (uniform weights). With ``smooth`` the thesis' terms
for the loop's own vertices are added, ``|P'_i - sum_j w_ij P_j|^2`` over their whole new
neighbourhood (old and new neighbours): they fix nothing on the loop but bend the membrane to
leave it along the surrounding surface, a C1 join instead of a crease (Figure 3.8).

Examples
--------
>>> import trimesh
>>> sphere = trimesh.creation.icosphere(3)
>>> keep = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] < 0.8
>>> filled = fill_holes(sphere.vertices, sphere.faces[keep])
>>> trimesh.Trimesh(filled.vertices, filled.faces, process=False).is_watertight
True
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.meshes import face_areas, vertex_adjacency, vertex_components
from fourd.geometry.polygon_triangulation import triangulate_polygon

__all__ = ["FilledMesh", "fill_holes", "membrane_positions", "small_holes"]


class FilledMesh(NamedTuple):
    """A mesh with holes filled.

    vertices : float64 [N + M, 3]
        The input vertices, then the ``M`` new ones.
    faces : int64 [F + G, 3]
        The input faces, then the ``G`` new ones (oriented like their neighbours).
    filled : bool [N + M]
        True for the new vertices.
    holes : list of int64 arrays
        The boundary loops that were filled.
    """

    vertices: np.ndarray
    faces: np.ndarray
    filled: np.ndarray
    holes: list


def fill_holes(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    holes: list | None = None,
    max_loop: int | None = None,
    smooth: bool | float = True,
    area_matched: bool = False,
) -> FilledMesh:
    """Fill holes of a triangle mesh (see the module docstring).

    Parameters
    ----------
    vertices : float [N, 3]
    faces : int [F, 3]
    holes : list of int arrays, optional
        The loops to fill, as from :func:`fourd.geometry.boundary_loops.boundary_loops` (in
        their direction). Default: every boundary loop, or those of at most ``max_loop``
        vertices (a garment keeps its openings, fills the rest).
    smooth : bool or float
        Add the loop vertices' terms (a C1 membrane); False gives the C0 membrane; a number in
        between weights those terms.
    area_matched : bool
        Space the disk's inner vertices so that they number about what the hole's flat area
        (:func:`small_holes`) holds at the loop's edge length, rather than the circle of the
        loop's perimeter: a long, narrow hole (a slit under an arm) laid out on that circle
        would get the circle's area in vertices, tens of times too many.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError("fill_holes needs vertices [N, 3] and faces [F, 3]")
    if holes is None:
        holes = boundary_loops(faces, len(vertices))
        if max_loop is not None:
            holes = [loop for loop in holes if len(loop) <= max_loop]
    all_vertices = [vertices]
    all_faces = [faces]
    count = len(vertices)
    inner_sets = []
    edges = _EdgeSet(faces, len(vertices))
    for loop in holes:
        loop = np.asarray(loop, dtype=np.int64)
        if len(loop) < 3:
            continue
        new_points, new_faces = _disk(vertices[loop], area_matched)
        inner = len(new_points) - len(loop)
        index = np.concatenate([loop[::-1], count + np.arange(inner)])  # disk order: loop reversed
        hole_faces = index[new_faces]
        if edges.clash(hole_faces, loop):
            # a chord of the disk is already a side of the mesh (a face poking into the hole):
            # a fan around one new vertex adds no chord
            inner = 1
            hole_faces = np.column_stack([np.roll(loop, -1), loop, np.full(len(loop), count)])
        edges.add(hole_faces)
        start = vertices[loop].mean(axis=0)
        all_vertices.append(np.repeat(start[None], inner, axis=0))
        all_faces.append(hole_faces)
        inner_sets.append(count + np.arange(inner))
        count += inner
    out_vertices = np.concatenate(all_vertices)
    out_faces = np.concatenate(all_faces)
    filled = np.zeros(len(out_vertices), dtype=bool)
    filled[len(vertices):] = True
    if inner_sets:
        out_vertices = _membrane(out_vertices, out_faces, filled, holes, smooth)
    return FilledMesh(out_vertices, out_faces, filled, list(holes))


class _EdgeSet:
    """The sides of a mesh's faces (over its ``count`` vertices, before any hole's), growing as
    holes are filled, to tell whether a hole's new faces would repeat a side."""

    def __init__(self, faces: np.ndarray, count: int):
        self.count = count
        self.keys = set(_side_keys(faces, count).tolist())

    def clash(self, hole_faces: np.ndarray, loop: np.ndarray) -> bool:
        """Whether a chord of ``hole_faces [G, 3]`` (a side joining two of the ``loop``'s
        vertices that is not a side of the loop) is a side already: the filled mesh would have
        a side of more than two faces there."""
        sides = _side_keys(hole_faces, self.count)
        chords = np.setdiff1d(sides, _pair_keys(np.column_stack([loop, np.roll(loop, -1)]), self.count))
        return any(int(key) in self.keys for key in chords)

    def add(self, hole_faces: np.ndarray) -> None:
        self.keys.update(_side_keys(hole_faces, self.count).tolist())


def _side_keys(faces: np.ndarray, count: int) -> np.ndarray:
    """The distinct sides of ``faces [F, 3]`` between two of the first ``count`` vertices, as
    :func:`_pair_keys`."""
    faces = np.asarray(faces, dtype=np.int64)
    return _pair_keys(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), count)


def _pair_keys(pairs: np.ndarray, count: int) -> np.ndarray:
    """The distinct vertex pairs ``[E, 2]`` between two of the first ``count`` vertices, as
    ``low * count + high``."""
    pairs = np.sort(np.asarray(pairs, dtype=np.int64), axis=1)
    pairs = pairs[pairs[:, 1] < count]
    return np.unique(pairs[:, 0] * np.int64(count) + pairs[:, 1])


def _flat_area(ring: np.ndarray) -> float:
    """A closed loop's vector area ``|sum_i p_i x p_(i+1)| / 2`` (``ring [K, 3]``)."""
    return 0.5 * float(np.linalg.norm(np.cross(ring, np.roll(ring, -1, axis=0)).sum(axis=0)))


def _disk(ring: np.ndarray, area_matched: bool = False):
    """The hole's triangulation in the plane: the loop (reversed, so the new faces turn like
    the mesh) on a circle by arc length, inner points at its mean edge length (with
    ``area_matched``, that length times the square root of the circle's area over the loop's
    flat area)."""
    ring = ring[::-1]
    steps = np.linalg.norm(np.diff(np.vstack([ring, ring[:1]]), axis=0), axis=1)
    perimeter = float(steps.sum())
    if perimeter <= 0:
        raise InputError("a hole's boundary has no length")
    angle = 2 * np.pi * np.concatenate([[0.0], np.cumsum(steps[:-1])]) / perimeter
    radius = perimeter / (2 * np.pi)
    circle = radius * np.column_stack([np.cos(angle), np.sin(angle)])
    spacing = float(steps.mean())
    if area_matched:
        spacing *= np.sqrt(max(np.pi * radius**2 / max(_flat_area(ring), 1e-300), 1.0))
    return triangulate_polygon(circle, spacing)


def _membrane(vertices, faces, filled, holes, smooth):
    """Least-squares positions of the new vertices (equation 3.1, with the C1 terms)."""
    return membrane_positions(vertices[None], faces, filled, holes, smooth=smooth)[0]


def membrane_positions(frames: np.ndarray, faces: np.ndarray, filled: np.ndarray, holes: list, *,
                       smooth: float = 1.0, weights: sp.spmatrix | None = None) -> np.ndarray:
    """The membrane's vertices placed in every frame of an animated mesh: ``frames [T, N, 3]``
    with the ``filled [N]`` vertices (of holes bounded by the loops ``holes``, as
    :func:`fill_holes` returns them, or any arrays of the holes' rim vertices) replaced by their
    least-squares membrane over that frame's other vertices (equation 3.1, with the C1 terms
    weighted by ``smooth``: 1 the thesis' C1 membrane, 0 the flat one). ``weights`` ``[N, N]``,
    rows summing to 1, are the equation's ``w_ij`` (the thesis' mean-value weights of the base
    embedding, :func:`fourd.methods.garment.base_holes.base_mean_value_weights`); None: the
    uniform weights of the mesh's neighbours. One factorisation for all frames: the operator
    does not depend on the positions."""
    frames = np.asarray(frames, dtype=np.float64)
    filled = np.asarray(filled, dtype=bool)
    result = frames.copy()
    if not filled.any():
        return result
    count = frames.shape[1]
    if weights is None:
        adjacency = vertex_adjacency(np.asarray(faces, dtype=np.int64), count)
        degree = np.asarray(adjacency.sum(axis=1)).ravel()
        weights = sp.diags(1.0 / np.maximum(degree, 1)) @ adjacency
    laplacian = (sp.identity(count) - weights).tocsr()  # rows P_i - sum_j w_ij P_j
    rows = np.flatnonzero(filled)
    scale = np.ones(len(rows))
    if smooth and holes:
        rim = np.unique(np.concatenate([np.asarray(h) for h in holes]))
        rows = np.concatenate([rows, rim])
        scale = np.concatenate([scale, np.full(len(rim), np.sqrt(float(smooth)))])
    operator = sp.diags(scale) @ laplacian[rows]
    unknown = np.flatnonzero(filled)
    known = np.flatnonzero(~filled)
    a = operator[:, unknown].tocsc()
    solve = spla.factorized((a.T @ a).tocsc())
    # every frame's three coordinates as right-hand sides [K, 3T]
    known_positions = frames[:, known].transpose(1, 0, 2).reshape(len(known), -1)
    right = a.T @ -(operator[:, known] @ known_positions)
    solution = np.column_stack([solve(right[:, k]) for k in range(right.shape[1])])
    result[:, unknown] = solution.reshape(len(unknown), len(frames), 3).transpose(1, 0, 2)
    return result


def small_holes(vertices: np.ndarray, faces: np.ndarray, *, max_fraction: float) -> list:
    """The boundary loops of a mesh that are holes rather than its outline: those whose flat
    area (the loop's vector area, ``|sum_i p_i x p_(i+1)| / 2``, the least projected area of
    any surface spanning it) is at most ``max_fraction`` of the area of the connected piece of
    surface the loop bounds. A scan's hole in a closed body spans a small part of it; the
    outline of an open sheet spans about all of it. Loops as
    :func:`fourd.geometry.boundary_loops.boundary_loops` gives them."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    loops = boundary_loops(faces, len(vertices))
    if not loops or max_fraction <= 0:
        return []
    _, component = vertex_components(faces, len(vertices))
    piece_area = np.bincount(component[faces[:, 0]], weights=face_areas(vertices, faces),
                             minlength=int(component.max()) + 1)
    chosen = []
    for loop in loops:
        loop = np.asarray(loop, dtype=np.int64)
        if len(loop) < 3:
            continue
        if _flat_area(vertices[loop]) <= max_fraction * piece_area[component[loop[0]]]:
            chosen.append(loop)
    return chosen
