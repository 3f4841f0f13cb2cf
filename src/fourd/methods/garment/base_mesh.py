"""A garment's frames parameterised onto a common base mesh (Popa's thesis, section 3.6.2,
after Kraevoy and Sheffer 2005 and Praun, Sweldens and Schröder 2001).

The base mesh is the off-surface anchors (3.6.1, one per opening) in a canonical pose: for a
T-shirt's four openings (neck, sleeves, waist) a tetrahedron, for three openings two
triangles (front and back) sharing their edges. A frame is parameterised onto it in four
steps:

1. **Closing** (:func:`closed_surface`). Each opening is closed by a cone from its anchor to
   the opening's loop, or to the arc of a loop that the opening is where an occlusion hole ran
   into it. (The thesis makes a small cone at the anchor and triangulates the gap between the
   cone and the loop; the cone here reaches the loop at once.) The other holes (what the
   cameras missed) are closed by the C1 membrane of equation 3.1
   (:func:`fourd.geometry.hole_filling.fill_holes`). The result is a closed surface of genus 0
   with the anchors as vertices.
2. **Charts** (:func:`base_charts`). One path per base edge, from anchor to anchor, the
   shortest along the edges that no earlier path uses, cut the closed surface into one disk
   per base facet. The base facets are paired with the charts by the anchors at their
   corners and by the side of each path the chart lies on, so a chart can only take the facet
   of its own orientation.
3. **The map of each chart onto its facet.** Its boundary runs along the facet's edges, each
   path at its arc-length fractions (so the two charts on either side of a path agree on it);
   the inside is Floater's mean-value map (a convex combination: a one-to-one map onto the
   triangle), then made stretch-minimising by Yoshizawa, Belyaev and Seidel's reweighting:
   each vertex's weights are divided by its neighbours' L2 stretch (Sander et al.) and the map
   solved again, as long as the chart's L2 stretch falls. (Kraevoy and Sheffer also let the
   vertices slide across the charts' borders; here the borders stay on the base edges, at
   their arc-length fractions.)
4. **Cross-parameterisation** (:func:`map_through_base`). A point given by a base facet and
   barycentric coordinates is found in another mesh's chart of that facet: the other mesh's
   triangle holding it, and the point there.

Frames parameterised this way are independent of each other (the thesis runs them side by
side), and two near-isometric frames get nearly the same map: the cross-parameterisation from
one to the other through the base is nearly isometric.

References
----------
V. Kraevoy, A. Sheffer, "Template-based mesh completion", SGP 2005 ([KS05]).
E. Praun, W. Sweldens, P. Schröder, "Consistent mesh parameterizations", SIGGRAPH 2001.
M. S. Floater, "Mean value coordinates", CAGD 20(1), 2003.
S. Yoshizawa, A. Belyaev, H.-P. Seidel, "A fast and simple stretch-minimizing mesh
parameterization", Shape Modeling International 2004.
P. V. Sander, J. Snyder, S. J. Gortler, H. Hoppe, "Texture mapping progressive meshes",
SIGGRAPH 2001 (the L2 stretch).
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.geodesic import edge_length_graph
from fourd.geometry.hole_filling import fill_holes
from fourd.geometry.meshes import face_adjacency

__all__ = ["BaseMesh", "BaseParameterization", "Charts", "base_charts", "base_mesh", "closed_surface",
           "map_through_base", "parameterize_onto_base", "vertex_base_coordinates"]

#: Reweighting rounds of the stretch minimisation at most (it stops earlier once the chart's
#: L2 stretch no longer falls).
STRETCH_ROUNDS = 8
#: A sliver's scale: edges shorter than this fraction of the median edge, and triangles of less
#: than this fraction squared of the mean area, count as degenerate (weights and stretch).
SLIVER = 1e-3
#: Triangles of the other mesh's chart tried for each point located there (nearest centres).
LOCATE_CANDIDATES = 16


class BaseMesh(NamedTuple):
    """The base mesh: the anchors in the canonical pose.

    vertices : float64 [K, 3]
        One per opening (``K`` = 3 or 4).
    faces : int64 [B, 3]
        Its facets: the tetrahedron's four, turned outward, for 4 openings; front and back for 3.
    """

    vertices: np.ndarray
    faces: np.ndarray


class Charts(NamedTuple):
    """A closed surface cut into one chart per base facet (:func:`base_charts`).

    chart : int64 [F]
        The base facet of each face.
    paths : list of int64 arrays
        The path of each base edge, from anchor to anchor (vertex indices of the surface), in
        the order of :func:`base_edges`.
    flipped : bool
        The surface is oriented against the base (the charts were found on the reversed
        faces).
    """

    chart: np.ndarray
    paths: list
    flipped: bool


class BaseParameterization(NamedTuple):
    """A closed surface mapped onto the base mesh (:func:`parameterize_onto_base`).

    face : int64 [R]
        The surface face of each row. A face lies in one facet, or across a base edge (then it
        has a row per facet it reaches).
    chart : int64 [R]
        The base facet of the row.
    corners : float64 [R, 3, 3]
        The face's corners' barycentric coordinates in that facet (a corner across a base edge,
        in the facet's plane unfolded over that edge, has a negative one).
    vertex_facet : int64 [N]
        The base facet each vertex lies in (-1: in no face).
    vertex_barycentric : float64 [N, 3]
        Its barycentric coordinates there (non-negative).
    stretch : float64
        The L2 stretch of the whole map, relative to one that keeps the surface's area (1 for
        an isometry).
    charts : Charts
    """

    face: np.ndarray
    chart: np.ndarray
    corners: np.ndarray
    vertex_facet: np.ndarray
    vertex_barycentric: np.ndarray
    stretch: float
    charts: Charts


def base_mesh(anchors: np.ndarray) -> BaseMesh:
    """The base mesh of the anchors ``[K, 3]`` in the canonical pose (module docstring); ``K``
    must be 3 or 4."""
    anchors = np.asarray(anchors, dtype=np.float64)
    if anchors.ndim != 2 or anchors.shape[1] != 3 or len(anchors) not in (3, 4):
        raise InputError(f"the base-mesh parameterisation needs a garment of 3 or 4 openings, got {len(anchors)}")
    if len(anchors) == 3:
        return BaseMesh(anchors, np.array([[0, 1, 2], [0, 2, 1]], dtype=np.int64))
    faces = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]], dtype=np.int64)
    centre = anchors.mean(axis=0)
    corners = anchors[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    if np.any(np.abs(np.einsum("fd,fd->f", normal, corners.mean(axis=1) - centre)) < 1e-12 * np.ptp(anchors) ** 3):
        raise InputError("the garment's four openings lie in one plane: no base tetrahedron")
    inward = np.einsum("fd,fd->f", normal, corners.mean(axis=1) - centre) < 0
    faces[inward] = faces[inward][:, ::-1]
    return BaseMesh(anchors, faces)


def base_edges(base: BaseMesh) -> np.ndarray:
    """The base's edges ``[E, 2]`` (sorted pairs) in the order their paths are traced: the
    first facet's three, then the rest (each later edge then joins two anchors on the border
    of one region the earlier paths leave)."""
    first = base.faces[0]
    edges = [tuple(sorted((int(first[k]), int(first[(k + 1) % 3])))) for k in range(3)]
    for face in base.faces[1:]:
        for k in range(3):
            edge = tuple(sorted((int(face[k]), int(face[(k + 1) % 3]))))
            if edge not in edges:
                edges.append(edge)
    return np.array(edges, dtype=np.int64)


def closed_surface(vertices: np.ndarray, faces: np.ndarray, openings: list, anchors: np.ndarray):
    """A garment's surface closed: each opening by a cone from its anchor, every other hole
    by the C1 membrane (equation 3.1; :func:`fourd.geometry.hole_filling.fill_holes`).
    Returns ``(vertices [N + K + M, 3], faces, apex [K])``: the anchors appended as vertices
    ``apex``, then the membranes' vertices.

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
    openings : list of int arrays
        Per anchor, the boundary vertices of its opening in order along a boundary loop: the
        whole loop, or the arc of it that the opening is (where an occlusion hole ran into the
        opening, or two openings share a loop). An arc's cone closes over the chord from its
        last vertex to its first; what is left of its loop is then a hole like the others.
    anchors : array [K, 3]
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    anchors = np.asarray(anchors, dtype=np.float64).reshape(-1, 3)
    if len(openings) != len(anchors):
        raise InputError(f"{len(openings)} opening loops for {len(anchors)} anchors")
    directed = set(zip(faces.ravel().tolist(), np.roll(faces, -1, axis=1).ravel().tolist(), strict=True))
    apex = len(vertices) + np.arange(len(anchors))
    cones = []
    for opening, top in zip(openings, apex, strict=True):
        opening = np.asarray(opening, dtype=np.int64)
        if len(opening) < 3:
            raise InputError(f"an opening of {len(opening)} boundary vertices cannot be closed by a cone")
        following = np.roll(opening, -1)
        # the loop's edge (u, v) runs u -> v in a face: its cone triangle runs v -> u; the
        # chord of an arc (not an edge yet) goes the way most of the arc's edges go
        along = np.array([(int(u), int(v)) in directed for u, v in zip(opening, following, strict=True)])
        along[-1] = along[:-1].mean() >= 0.5 if len(opening) > 1 else along[-1]
        first = np.where(along, following, opening)
        second = np.where(along, opening, following)
        cones.append(np.column_stack([first, second, np.full(len(opening), top)]))
    coned_vertices, coned_faces = np.vstack([vertices, anchors]), np.vstack([faces, *cones])
    holes = [loop for loop in boundary_loops(coned_faces, len(coned_vertices)) if len(loop) >= 3]
    if holes:
        filled = fill_holes(coned_vertices, coned_faces, holes=holes)
        coned_vertices, coned_faces = filled.vertices, filled.faces
    return coned_vertices, coned_faces, apex


def _path(graph: sp.csr_matrix, blocked: np.ndarray, start: int, end: int) -> np.ndarray | None:
    """The shortest path from ``start`` to ``end`` avoiding the ``blocked`` vertices (None when
    there is none), without a step over two sides of a triangle."""
    open_ = ~blocked
    open_[[start, end]] = True
    keep = sp.diags(open_.astype(np.float64))
    allowed = (keep @ graph @ keep).tocsr()
    allowed.eliminate_zeros()
    distance, previous = csgraph.dijkstra(allowed, indices=start, return_predecessors=True)
    if not np.isfinite(distance[end]):
        return None
    path = [end]
    while path[-1] != start:
        path.append(int(previous[path[-1]]))
    path = path[::-1]
    # a path over two sides of a triangle (weighted lengths allow it) would flatten that
    # triangle onto a base edge: take the third side instead
    k = 0
    while k + 2 < len(path):
        if graph[path[k], path[k + 2]] != 0:
            del path[k + 1]
            k = max(k - 1, 0)
        else:
            k += 1
    return np.array(path, dtype=np.int64)


def _tracing_orders(base: BaseMesh, edges: list):
    """Orders to trace the base edges' paths in: a facet's three edges first (they cut the
    surface in two), then the others in every order, facet after facet."""
    for face in base.faces:
        first = [edges.index(tuple(sorted((int(face[k]), int(face[(k + 1) % 3]))))) for k in range(3)]
        rest = [k for k in range(len(edges)) if k not in first]
        for tail in itertools.permutations(rest):
            yield first + list(tail)


def _trace(lengths: list, apex: np.ndarray, edges: list, order: list, count: int) -> list | None:
    """The paths of the base edges (in ``edges``' order) traced in ``order``, each avoiding the
    earlier ones; None when one is cut off."""
    blocked = np.zeros(count, dtype=bool)
    blocked[apex] = True
    paths = [None] * len(edges)
    for k in order:
        a, b = edges[k]
        path = _path(lengths[k], blocked, int(apex[a]), int(apex[b]))
        if path is None:
            return None
        blocked[path] = True
        paths[k] = path
    return paths


def _face_components(faces: np.ndarray, cut: set) -> tuple[int, np.ndarray]:
    pairs, edges = face_adjacency(faces)
    keep = np.array([(int(a), int(b)) not in cut for a, b in edges], dtype=bool) if len(edges) else np.zeros(0, bool)
    pairs = pairs[keep]
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(faces), len(faces)))
    return csgraph.connected_components(graph, directed=False)


def _guided(graph: sp.csr_matrix, vertices: np.ndarray, guide: np.ndarray, reach: float) -> sp.csr_matrix:
    """The edge lengths of ``graph`` times ``1 + (d / reach)^2``, ``d`` the distance from the
    edge's midpoint to the guide's points."""
    coo = graph.tocoo()
    middle = 0.5 * (vertices[coo.row] + vertices[coo.col])
    distance, _ = cKDTree(guide).query(middle)
    return sp.csr_matrix((coo.data * (1.0 + (distance / reach) ** 2), (coo.row, coo.col)), shape=graph.shape)


def base_charts(vertices: np.ndarray, faces: np.ndarray, apex: np.ndarray, base: BaseMesh, *,
                guides: list | None = None, reach: float = 0.0, paths: list | None = None) -> Charts:
    """The closed surface (:func:`closed_surface`) cut into one chart per base facet by a path
    per base edge between the anchors ``apex`` (module docstring, step 2).

    With ``guides`` (one point array ``[P, 3]`` per base edge, in :func:`base_edges`' order:
    another frame's paths brought near this one), each path is the shortest by edge lengths
    times ``1 + (d / reach)^2``, ``d`` an edge's distance from its guide: where two ways round
    are nearly as short (over the chest or over the back), the paths then go the way the guide
    went. With ``paths`` (vertex arrays in :func:`base_edges`' order, another surface's of the
    same connectivity) the surface is cut along those.

    Raises
    ------
    InputError
        When the paths do not cut the surface into the base's facets (the surface is not a
        sphere with the anchors on it, or a chart's sides disagree on its facet).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    apex = np.asarray(apex, dtype=np.int64)
    if paths is None:
        graph = edge_length_graph(vertices, faces)
        edges = [tuple(edge) for edge in base_edges(base).tolist()]
        lengths = [graph if guides is None else _guided(graph, vertices, guides[k], reach) for k in range(len(edges))]
        for order in _tracing_orders(base, edges):
            paths = _trace(lengths, apex, edges, order, len(vertices))
            if paths is not None:
                break
    if paths is None:
        raise InputError("the garment's surface cannot be cut into base charts: in every order tried, "
                         "the earlier paths cut an anchor off from another")
    cut = {tuple(sorted((int(u), int(v)))) for path in paths for u, v in zip(path[:-1], path[1:], strict=True)}
    count, component = _face_components(faces, cut)
    if count != len(base.faces):
        raise InputError(f"the garment's surface is cut into {count} pieces by the paths between its anchors, "
                         f"not {len(base.faces)}: it is not a closed surface of genus 0 once its openings are closed")
    for flipped in (False, True):
        oriented = faces[:, ::-1] if flipped else faces
        facet_of = _facets_of_components(oriented, component, count, paths, base)
        if facet_of is not None:
            return Charts(facet_of[component], paths, flipped)
    raise InputError("the charts of the garment's surface do not match the base mesh's facets "
                     "(the openings are in another order on the surface than the anchors)")


def _facets_of_components(faces, component, count, paths, base: BaseMesh) -> np.ndarray | None:
    """The base facet of each chart, or None when a chart's sides name different facets or two
    charts the same one. A chart lying left of the path ``a -> b`` (it holds the directed edge
    ``u -> v`` of consecutive path vertices) is the facet with the directed edge ``a -> b``."""
    facet_of_edge = {}
    for index, face in enumerate(base.faces):
        for k in range(3):
            facet_of_edge[(int(face[k]), int(face[(k + 1) % 3]))] = index
    owner = {}
    for f, face in enumerate(faces):
        for k in range(3):
            owner[(int(face[k]), int(face[(k + 1) % 3]))] = f
    which = np.full(count, -1, dtype=np.int64)
    for (a, b), path in zip(base_edges(base), paths, strict=True):
        for u, v, forward in ((path[0], path[1], (a, b)), (path[1], path[0], (b, a))):
            face = owner.get((int(u), int(v)))
            if face is None:
                return None
            facet = facet_of_edge.get(forward)
            if facet is None:
                return None
            piece = component[face]
            if which[piece] not in (-1, facet):
                return None
            which[piece] = facet
    if np.any(which < 0) or len(set(which.tolist())) != count:
        return None
    return which


def _mean_value_weights(vertices: np.ndarray, faces: np.ndarray, count: int) -> sp.csr_matrix:
    """Floater's mean-value weights ``w_ij = (tan(a/2) + tan(b/2)) / |v_i - v_j|`` (``a``,
    ``b`` the angles at ``v_i`` beside the edge), ``[N, N]``, not normalised. On a sliver
    (a scan's surface has some) the lengths are floored at :data:`SLIVER` of the median edge
    and the half-angle tangents capped at ``1 / SLIVER``, so one sliver cannot swamp a row."""
    corners = vertices[faces]
    shortest = SLIVER * float(np.median(np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)))
    rows, cols, values = [], [], []
    for k in range(3):
        i, j, m = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        to_j = corners[:, (k + 1) % 3] - corners[:, k]
        to_m = corners[:, (k + 2) % 3] - corners[:, k]
        len_j, len_m = np.linalg.norm(to_j, axis=1), np.linalg.norm(to_m, axis=1)
        cosine = np.einsum("fd,fd->f", to_j, to_m) / np.maximum(len_j * len_m, 1e-300)
        half = np.minimum(np.tan(0.5 * np.arccos(np.clip(cosine, -1.0, 1.0))), 1.0 / SLIVER)
        rows += [i, i]
        cols += [j, m]
        values += [half / np.maximum(len_j, shortest), half / np.maximum(len_m, shortest)]
    weights = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(count, count))
    # a little of the uniform weights: a vertex all of whose angles are degenerate still has
    # a row, and the system stays regular
    uniform = weights.copy()
    uniform.data[:] = SLIVER * float(np.median(weights.data))
    return weights + uniform


def _facet_frame(corners: np.ndarray) -> np.ndarray:
    """A base facet's corners ``[3, 3]`` in its own plane ``[3, 2]`` (first at the origin,
    second on the x axis, counter-clockwise)."""
    first = corners[1] - corners[0]
    second = corners[2] - corners[0]
    x = first / np.linalg.norm(first)
    normal = np.cross(first, second)
    y = np.cross(normal / np.linalg.norm(normal), x)
    return np.array([[0.0, 0.0], [np.linalg.norm(first), 0.0], [second @ x, second @ y]])


def _triangle_stretch(points: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sander's L2 stretch of each triangle's map from the plane ``uv [F, 3, 2]`` to space
    ``points [F, 3, 3]``, and the triangles' areas in space."""
    du1, du2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    area_uv = 0.5 * (du1[:, 0] * du2[:, 1] - du1[:, 1] * du2[:, 0])
    q1, q2 = points[:, 1] - points[:, 0], points[:, 2] - points[:, 0]
    safe = np.where(np.abs(area_uv) > 1e-300, area_uv, 1e-300)
    s_s = (q1 * du2[:, 1, None] - q2 * du1[:, 1, None]) / (2 * safe[:, None])
    s_t = (q2 * du1[:, 0, None] - q1 * du2[:, 0, None]) / (2 * safe[:, None])
    with np.errstate(over="ignore", invalid="ignore"):
        stretch = np.sqrt(0.5 * (np.sum(s_s**2, axis=1) + np.sum(s_t**2, axis=1)))
    area = 0.5 * np.linalg.norm(np.cross(q1, q2), axis=1)
    # a degenerate triangle (a sliver of the scan) has no stretch to speak of
    sliver = area <= SLIVER**2 * area.mean()
    stretch = np.where(sliver, 1.0, np.where(area_uv > 0, stretch, np.inf))
    return stretch, np.where(sliver, 0.0, area)


def _relative_stretch(points: np.ndarray, layout: np.ndarray, left_out: np.ndarray | None = None):
    """The L2 stretch of a map from the plane ``layout [F, 3, 2]`` to space ``points [F, 3, 3]``
    relative to one that keeps the whole area (1 where it keeps areas and shapes): the whole
    map's, each triangle's, and the triangles' areas in space (0 on slivers and on the
    ``left_out`` triangles, which count for nothing)."""
    stretch, area = _triangle_stretch(points, layout)
    area_3d = 0.5 * np.linalg.norm(np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0]), axis=1)
    first, second = layout[:, 1] - layout[:, 0], layout[:, 2] - layout[:, 0]
    area_uv = 0.5 * np.abs(first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0])
    if left_out is not None:
        stretch[left_out], area[left_out] = 1.0, 0.0
        area_3d, area_uv = area_3d[~left_out], area_uv[~left_out]
    relative = stretch * np.sqrt(area_uv.sum() / area_3d.sum())
    return float(np.sqrt(np.sum(area * relative**2) / np.sum(area))), relative, area


def _vertex_scales(faces: np.ndarray, relative: np.ndarray, area: np.ndarray, count: int) -> np.ndarray:
    """Each vertex's L2 stretch, area-weighted over its triangles (1 where it has none): what
    Yoshizawa et al. divide the vertex's weights by in the next round."""
    squared = np.bincount(faces.ravel(), weights=np.repeat(area * relative**2, 3), minlength=count)
    weight = np.bincount(faces.ravel(), weights=np.repeat(area, 3), minlength=count)
    scale = np.sqrt(squared / np.maximum(weight, 1e-300))
    return np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)


def _chart_map(vertices, faces, border, border_uv, weights) -> np.ndarray:
    """The stretch-minimising convex map of one chart (module docstring, step 3): ``uv [N, 2]``
    for the chart's vertices, ``border`` fixed at ``border_uv``."""
    count = len(vertices)
    inside = np.ones(count, dtype=bool)
    inside[border] = False
    free = np.flatnonzero(inside)
    uv = np.zeros((count, 2))
    uv[border] = border_uv
    best, best_stretch = None, np.inf
    scale = np.ones(count)
    for _ in range(STRETCH_ROUNDS):
        scaled = weights @ sp.diags(1.0 / scale)
        system = sp.diags(np.asarray(scaled.sum(axis=1)).ravel()) - scaled
        if len(free):
            right = -(system[free][:, border] @ uv[border])
            solve = spla.factorized(system[free][:, free].tocsc())
            uv[free] = np.column_stack([solve(right[:, 0]), solve(right[:, 1])])
        total, relative, area = _relative_stretch(vertices[faces], uv[faces])
        if best is not None and not total < best_stretch:
            break
        best, best_stretch = uv.copy(), total
        if not np.isfinite(total):
            break
        scale = _vertex_scales(faces, relative, area, count)
    return best


def _unfoldings(base: BaseMesh, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The maps between the facets' planes: ``(linear [B, B, 2, 2], shift [B, B, 2])``, entry
    ``[g, f]`` taking a point in facet ``g``'s frame into facet ``f``'s. Facets sharing one edge
    (a tetrahedron's): ``g`` unfolded about it, a rigid motion. Facets sharing all three
    (front and back): the affine map of their corners, which keeps every border point."""
    count = len(base.faces)
    linear = np.zeros((count, count, 2, 2))
    shift = np.zeros((count, count, 2))
    for g in range(count):
        for f in range(count):
            if f == g:
                linear[g, f] = np.eye(2)
                continue
            shared = [int(v) for v in base.faces[g] if v in base.faces[f]]
            from_g = np.array([frames[g][list(base.faces[g]).index(v)] for v in shared])
            to_f = np.array([frames[f][list(base.faces[f]).index(v)] for v in shared])
            if len(shared) == 3:
                matrix = np.linalg.solve((from_g[1:] - from_g[0]), (to_f[1:] - to_f[0])).T
            else:
                along_g, along_f = from_g[1] - from_g[0], to_f[1] - to_f[0]
                angle = np.arctan2(along_f[1], along_f[0]) - np.arctan2(along_g[1], along_g[0])
                matrix = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
            linear[g, f] = matrix
            shift[g, f] = to_f[0] - matrix @ from_g[0]
    return linear, shift


def _settle(home: np.ndarray, uv: np.ndarray, frames: np.ndarray, base: BaseMesh, rotation, shift):
    """Each point moved into the facet that holds it: a point past an edge of its facet is
    carried over that edge (at most three times; then clamped into the facet it reached).
    Returns ``(home, uv, barycentric)``."""
    home, uv = home.copy(), uv.copy()
    # the facet across the edge opposite each facet's corner
    beyond = np.array([[next(g for g in range(len(base.faces)) if g != f and
                             {int(face[(c + 1) % 3]), int(face[(c + 2) % 3])} <= set(base.faces[g].tolist()))
                        for c in range(3)] for f, face in enumerate(base.faces)], dtype=np.int64)
    for _ in range(3):
        bary = _batch_barycentric(frames[home], uv)
        outside = bary.min(axis=1) < -1e-12
        if not outside.any():
            break
        which = np.flatnonzero(outside)
        across = beyond[home[which], np.argmin(bary[which], axis=1)]
        uv[which] = np.einsum("pab,pb->pa", rotation[home[which], across], uv[which]) + shift[home[which], across]
        home[which] = across
    bary = np.clip(_batch_barycentric(frames[home], uv), 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    return home, np.einsum("pk,pkd->pd", bary, frames[home]), bary


def _slide(vertices, faces, apex, base: BaseMesh, frames, home, uv, rotation, shift) -> tuple | None:
    """The map relaxed across the charts' borders (module docstring, step 3): every vertex
    but the anchors free on the base, its neighbours in other facets unfolded into its own
    facet's plane; the stretch-minimising mean-value system solved, the vertices settled into
    the facets they reached, and again, as long as the L2 stretch falls (``rotation, shift``:
    :func:`_unfoldings`). Returns the vertices' facets and positions in them, or None when the
    first solve already folds the map."""
    count = len(vertices)
    weights = _mean_value_weights(vertices, faces, count).tocoo()
    is_apex = np.zeros(count, dtype=bool)
    is_apex[apex] = True
    anchor_of = np.full(count, -1, dtype=np.int64)
    anchor_of[apex] = np.arange(len(apex))
    free = np.flatnonzero(~is_apex)
    index = np.full(count, -1, dtype=np.int64)
    index[free] = np.arange(len(free))
    keep = ~is_apex[weights.row]
    i, j, w = weights.row[keep], weights.col[keep], weights.data[keep]
    corner_slot = np.array([[list(face).index(k) if k in face else -1 for k in range(len(apex))] for face in base.faces])
    best, best_stretch = None, np.inf
    scale = np.ones(count)
    for _ in range(STRETCH_ROUNDS):
        weight = w / scale[j]
        block = rotation[home[j], home[i]] * weight[:, None, None]  # [E, 2, 2]
        rows, cols, values = [], [], []
        right = np.zeros((len(free), 2))
        to_free = ~is_apex[j]
        for a in range(2):
            for b in range(2):
                rows.append(2 * index[i[to_free]] + a)
                cols.append(2 * index[j[to_free]] + b)
                values.append(block[to_free, a, b])
        np.add.at(right, index[i[to_free]], -(weight[to_free, None] * shift[home[j[to_free]], home[i[to_free]]]))
        # an anchor's place in the plane of the vertex's facet: its corner, or unfolded from a
        # facet that has it
        at_apex = np.flatnonzero(~to_free)
        anchor = anchor_of[j[at_apex]]
        facet = home[i[at_apex]]
        slot = corner_slot[facet, anchor]
        place = np.zeros((len(at_apex), 2))
        direct = slot >= 0
        place[direct] = frames[facet[direct], slot[direct]]
        for row in np.flatnonzero(~direct):
            options = [g for g in range(len(base.faces)) if corner_slot[g, anchor[row]] >= 0]
            images = [rotation[g, facet[row]] @ frames[g, corner_slot[g, anchor[row]]] + shift[g, facet[row]] for g in options]
            place[row] = min(images, key=lambda point, r=row: np.linalg.norm(point - uv[i[at_apex[r]]]))
        np.add.at(right, index[i[at_apex]], -(weight[at_apex, None] * place))
        total = np.bincount(index[i], weights=weight, minlength=len(free))
        for a in range(2):
            rows.append(2 * np.arange(len(free)) + a)
            cols.append(2 * np.arange(len(free)) + a)
            values.append(-total)
        system = sp.csc_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(2 * len(free), 2 * len(free)))
        solution = spla.spsolve(system, right.ravel()).reshape(-1, 2)
        moved = uv.copy()
        moved[free] = solution
        new_home, new_uv, _ = _settle(home, moved, frames, base, rotation, shift)
        new_home[apex], new_uv[apex] = home[apex], uv[apex]
        stretch, relative, area = _map_stretch(vertices, faces, new_home, new_uv, rotation, shift, apex)
        if not np.isfinite(stretch) or (best is not None and not stretch < best_stretch):
            break
        best, best_stretch = (new_home, new_uv), stretch
        home, uv = new_home, new_uv
        scale = _vertex_scales(faces, relative, area, count)
    return best


def _in_frame(faces, home, uv, target, rotation, shift) -> np.ndarray:
    """Each face's corners ``[F, 3, 2]`` in the plane of facet ``target [F]`` (unfolded)."""
    corner_home = home[faces]  # [F, 3]
    corners = uv[faces]
    goal = np.repeat(target[:, None], 3, axis=1)
    return np.einsum("fcab,fcb->fca", rotation[corner_home, goal], corners) + shift[corner_home, goal]


def _map_stretch(vertices, faces, home, uv, rotation, shift, apex):
    """:func:`_relative_stretch` of the map, each triangle laid out in its first corner's
    facet. The cones' triangles at the anchors are left out: an anchor is a cone point of the
    base, where the facets around it cannot all be unfolded into one plane, and those triangles
    are not the garment."""
    layout = _in_frame(faces, home, uv, home[faces[:, 0]], rotation, shift)
    return _relative_stretch(vertices[faces], layout, np.isin(faces, apex).any(axis=1))


def parameterize_onto_base(
    vertices: np.ndarray,
    faces: np.ndarray,
    apex: np.ndarray,
    base: BaseMesh,
    *,
    guides: list | None = None,
    reach: float = 0.0,
    paths: list | None = None,
    slide: bool = True,
) -> BaseParameterization:
    """A closed surface with the anchors as its vertices ``apex [K]`` (:func:`closed_surface`)
    mapped onto the base mesh, one chart per facet (module docstring, steps 2-3).

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
        Closed, genus 0.
    apex : int array [K]
        The anchors' vertices, in the base's vertex order.
    base : BaseMesh
    guides, reach, paths
        As for :func:`base_charts`.
    slide : bool
        Let the vertices slide across the charts' borders (Kraevoy and Sheffer; a base of four
        anchors only). False: the borders stay on the base edges at their arc-length fractions.

    Returns
    -------
    BaseParameterization
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    apex = np.asarray(apex, dtype=np.int64)
    charts = base_charts(vertices, faces, apex, base, guides=guides, reach=reach, paths=paths)
    oriented = faces[:, ::-1] if charts.flipped else faces
    # arc-length fraction of every path vertex along its base edge
    fraction = {}
    for (a, b), path in zip(base_edges(base), charts.paths, strict=True):
        steps = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(vertices[path], axis=0), axis=1))]
        for vertex, s in zip(path.tolist(), (steps / steps[-1]).tolist(), strict=True):
            fraction[vertex] = (int(a), int(b), s)
    frames = np.array([_facet_frame(base.vertices[face]) for face in base.faces])
    home = np.zeros(len(vertices), dtype=np.int64)
    uv = np.zeros((len(vertices), 2))
    for facet, base_face in enumerate(base.faces):
        members = np.flatnonzero(charts.chart == facet)
        local, inverse = np.unique(oriented[members], return_inverse=True)
        local_faces = inverse.reshape(-1, 3)
        slot = {int(v): k for k, v in enumerate(base_face)}
        border = np.array([k for k, v in enumerate(local.tolist()) if v in fraction], dtype=np.int64)
        border_uv = np.empty((len(border), 2))
        for row, k in enumerate(border):
            a, b, s = fraction[int(local[k])]
            if s in (0.0, 1.0):  # an anchor: the facet's corner (it ends several paths)
                a = b = int(np.flatnonzero(apex == local[k])[0])
            border_uv[row] = (1 - s) * frames[facet][slot[a]] + s * frames[facet][slot[b]]
        weights = _mean_value_weights(vertices[local], local_faces, len(local))
        home[local], uv[local] = facet, _chart_map(vertices[local], local_faces, border, border_uv, weights)
    rotation, shift = _unfoldings(base, frames)
    if slide and len(base.faces) == 4:
        slid = _slide(vertices, oriented, apex, base, frames, home, uv, rotation, shift)
        if slid is not None:
            home, uv = slid
    stretch, _, _ = _map_stretch(vertices, oriented, home, uv, rotation, shift, apex)
    # a face's rows: every facet one of its corners lies in. The face is laid out in its
    # first corner's facet (its other corners unfolded over the edge they are near), then
    # that layout is carried into each facet: unfolding each corner straight into a facet
    # would take the two sides of a cone point at an anchor the two ways round it.
    reference = home[faces[:, 0]]
    layout = _in_frame(faces, home, uv, reference, rotation, shift)
    pairs = np.unique(np.column_stack([np.tile(np.arange(len(faces)), 3), home[faces.T.ravel()]]), axis=0)
    row_face, row_facet = pairs[:, 0], pairs[:, 1]
    source = reference[row_face]
    layout = np.einsum("rab,rcb->rca", rotation[source, row_facet], layout[row_face]) + shift[source, row_facet][:, None]
    corners = _batch_barycentric(frames[np.repeat(row_facet, 3)], layout.reshape(-1, 2)).reshape(-1, 3, 3)
    vertex_bary = np.clip(_batch_barycentric(frames[home], uv), 0.0, None)
    vertex_bary /= vertex_bary.sum(axis=1, keepdims=True)
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    return BaseParameterization(row_face, row_facet, corners, np.where(used, home, -1), vertex_bary, stretch, charts)


def vertex_base_coordinates(parameterization: BaseParameterization, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Where the first ``count`` vertices of a surface lie on the base, ``(facets [count],
    barycentric [count, 3])`` (the anchors a closed surface appends come after them)."""
    return parameterization.vertex_facet[:count], parameterization.vertex_barycentric[:count]


def _batch_barycentric(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``[P, 3]`` of ``points [P, 2]`` in ``triangles [P, 3, 2]``."""
    e1, e2 = triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    d = points - triangles[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    s = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
    t = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    return np.column_stack([1.0 - s - t, s, t])


def map_through_base(facets: np.ndarray, barycentric: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                     parameterization: BaseParameterization) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points of the base (facet ``facets [P]``, ``barycentric [P, 3]`` in it) found on another
    surface through its parameterisation (module docstring, step 4).

    Returns ``(points [P, 3], faces [P], barycentric [P, 3])``: the points on the surface
    ``vertices, faces``, the face holding each and the coordinates there (clamped into the
    face where the point fell just outside every triangle of the facet).
    """
    facets = np.asarray(facets, dtype=np.int64)
    barycentric = np.asarray(barycentric, dtype=np.float64)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    found_face = np.zeros(len(facets), dtype=np.int64)
    found_bary = np.zeros((len(facets), 3))
    # every facet as the same reference triangle: barycentric coordinates are affine-invariant
    reference = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    for facet in np.unique(facets):
        asked = np.flatnonzero(facets == facet)
        members = np.flatnonzero(parameterization.chart == facet)
        if not len(members):
            raise InputError(f"the surface has no chart for base facet {facet}")
        triangles = parameterization.corners[members] @ reference  # [M, 3, 2]
        points = barycentric[asked] @ reference
        tree = cKDTree(triangles.mean(axis=1))
        k = min(LOCATE_CANDIDATES, len(members))
        _, near = tree.query(points, k=k)
        near = near.reshape(len(asked), k)
        coords = _batch_barycentric(triangles[near.ravel()], np.repeat(points, k, axis=0)).reshape(len(asked), k, 3)
        best = np.argmax(coords.min(axis=2), axis=1)
        rows = np.arange(len(asked))
        chosen = np.clip(coords[rows, best], 0.0, None)
        found_face[asked] = parameterization.face[members[near[rows, best]]]
        found_bary[asked] = chosen / chosen.sum(axis=1, keepdims=True)
    points = np.einsum("pk,pkd->pd", found_bary, vertices[faces[found_face]])
    return points, found_face, found_bary
