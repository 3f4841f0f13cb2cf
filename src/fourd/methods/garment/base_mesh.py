"""A garment's frames parameterised onto a common base mesh (Popa's thesis, section 3.6.2,
after Kraevoy and Sheffer 2005 and Praun, Sweldens and Schröder 2001).

The base mesh is the off-surface anchors (3.6.1, one per opening) in a canonical pose: for a
T-shirt's four openings (neck, sleeves, waist) a tetrahedron, for three openings two
triangles (front and back) sharing their edges. A frame is parameterised onto it in four
steps:

1. **Closing** (:func:`closed_surface`). Each opening is closed by a cone from its anchor to
   the opening's loop. (The thesis makes a small cone at the anchor and triangulates the gap
   between the cone and the loop; the cone here reaches the loop at once.) The other holes
   (what the cameras missed) are closed first by the caller with the C1 membrane of
   equation 3.1 (:func:`fourd.geometry.hole_filling.fill_holes`). The result is a closed
   surface of genus 0 with the anchors as vertices.
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

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from fourd.errors import InputError
from fourd.geometry.geodesic import edge_length_graph
from fourd.geometry.meshes import face_adjacency, face_areas

__all__ = ["BaseMesh", "BaseParameterization", "Charts", "base_charts", "base_mesh", "closed_surface",
           "map_through_base", "parameterize_onto_base", "vertex_base_coordinates"]

#: Reweighting rounds of the stretch minimisation at most (it stops earlier once the chart's
#: L2 stretch no longer falls).
STRETCH_ROUNDS = 8
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

    chart : int64 [F]
        The base facet each face is mapped into.
    corners : float64 [F, 3, 3]
        Each face corner's barycentric coordinates in that facet (a vertex on a chart's border
        has one set per chart; the sets name the same point of the base).
    stretch : float64 [B]
        Each chart's L2 stretch at the end, relative to a map that keeps the chart's area (1 for
        an isometry).
    charts : Charts
    """

    chart: np.ndarray
    corners: np.ndarray
    stretch: np.ndarray
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
    """Each opening loop closed by a cone from its anchor: ``(vertices [N + K, 3], faces,
    apex [K])``, the anchors appended as vertices ``apex``, each cone's triangles oriented like
    the faces along its loop.

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
        Its only boundary loops are the openings (the other holes filled).
    openings : list of int arrays
        The openings' boundary loops, in the anchors' order.
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
    for loop, top in zip(openings, apex, strict=True):
        loop = np.asarray(loop, dtype=np.int64)
        following = np.roll(loop, -1)
        # the loop's edge (u, v) runs u -> v in a face: its cone triangle runs v -> u
        along = np.array([(int(u), int(v)) in directed for u, v in zip(loop, following, strict=True)])
        first = np.where(along, following, loop)
        second = np.where(along, loop, following)
        cones.append(np.column_stack([first, second, np.full(len(loop), top)]))
    return np.vstack([vertices, anchors]), np.vstack([faces, *cones]), apex


def _path(graph: sp.csr_matrix, blocked: np.ndarray, start: int, end: int) -> np.ndarray:
    open_ = ~blocked
    open_[[start, end]] = True
    keep = sp.diags(open_.astype(np.float64))
    allowed = (keep @ graph @ keep).tocsr()
    allowed.eliminate_zeros()
    distance, previous = csgraph.dijkstra(allowed, indices=start, return_predecessors=True)
    if not np.isfinite(distance[end]):
        raise InputError("the garment's surface cannot be cut into base charts: an anchor is cut off "
                         "from another by the earlier paths")
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
                guides: list | None = None, reach: float = 0.0) -> Charts:
    """The closed surface (:func:`closed_surface`) cut into one chart per base facet by a path
    per base edge between the anchors ``apex`` (module docstring, step 2).

    With ``guides`` (one point array ``[P, 3]`` per base edge, in :func:`base_edges`' order:
    another frame's paths brought near this one), each path is the shortest by edge lengths
    times ``1 + (d / reach)^2``, ``d`` an edge's distance from its guide: where two ways round
    are nearly as short (over the chest or over the back), the paths then go the way the guide
    went.

    Raises
    ------
    InputError
        When the paths do not cut the surface into the base's facets (the surface is not a
        sphere with the anchors on it, or a chart's sides disagree on its facet).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    apex = np.asarray(apex, dtype=np.int64)
    graph = edge_length_graph(vertices, faces)
    blocked = np.zeros(len(vertices), dtype=bool)
    blocked[apex] = True
    paths = []
    for index, (a, b) in enumerate(base_edges(base)):
        lengths = graph if guides is None else _guided(graph, vertices, guides[index], reach)
        path = _path(lengths, blocked, int(apex[a]), int(apex[b]))
        blocked[path] = True
        paths.append(path)
    cut = {tuple(sorted((int(u), int(v)))) for path in paths for u, v in zip(path[:-1], path[1:], strict=True)}
    count, component = _face_components(faces, cut)
    if count != len(base.faces):
        raise InputError(f"the garment's surface is cut into {count} pieces by the paths between its anchors, "
                         f"not {len(base.faces)}: it is not a closed surface of genus 0 once its openings are closed")
    for flipped in (False, True):
        oriented = faces[:, ::-1] if flipped else faces
        facet_of = _facets_of_components(oriented, component, count, paths, base, apex)
        if facet_of is not None:
            return Charts(facet_of[component], paths, flipped)
    raise InputError("the charts of the garment's surface do not match the base mesh's facets "
                     "(the openings are in another order on the surface than the anchors)")


def _facets_of_components(faces, component, count, paths, base: BaseMesh, apex) -> np.ndarray | None:
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
    ``b`` the angles at ``v_i`` beside the edge), ``[N, N]``, not normalised."""
    corners = vertices[faces]
    rows, cols, values = [], [], []
    for k in range(3):
        i, j, m = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        to_j = corners[:, (k + 1) % 3] - corners[:, k]
        to_m = corners[:, (k + 2) % 3] - corners[:, k]
        len_j, len_m = np.linalg.norm(to_j, axis=1), np.linalg.norm(to_m, axis=1)
        cosine = np.einsum("fd,fd->f", to_j, to_m) / np.maximum(len_j * len_m, 1e-300)
        half = np.tan(0.5 * np.arccos(np.clip(cosine, -1.0, 1.0)))
        rows += [i, i]
        cols += [j, m]
        values += [half / np.maximum(len_j, 1e-300), half / np.maximum(len_m, 1e-300)]
    return sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(count, count))


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
    stretch = np.sqrt(0.5 * (np.sum(s_s**2, axis=1) + np.sum(s_t**2, axis=1)))
    area = 0.5 * np.linalg.norm(np.cross(q1, q2), axis=1)
    return np.where(area_uv > 0, stretch, np.inf), area


def _chart_map(vertices, faces, border, border_uv, weights) -> tuple[np.ndarray, float]:
    """The stretch-minimising convex map of one chart (module docstring, step 3): ``uv [N, 2]``
    for the chart's vertices (``border`` fixed at ``border_uv``) and its relative L2 stretch."""
    count = len(vertices)
    inside = np.ones(count, dtype=bool)
    inside[border] = False
    free = np.flatnonzero(inside)
    uv = np.zeros((count, 2))
    uv[border] = border_uv
    area_3d = face_areas(vertices, faces).sum()
    best, best_stretch = None, np.inf
    scale = np.ones(count)
    for _ in range(STRETCH_ROUNDS):
        scaled = weights @ sp.diags(1.0 / scale)
        system = sp.diags(np.asarray(scaled.sum(axis=1)).ravel()) - scaled
        if len(free):
            right = -(system[free][:, border] @ uv[border])
            solve = spla.factorized(system[free][:, free].tocsc())
            uv[free] = np.column_stack([solve(right[:, 0]), solve(right[:, 1])])
        stretch, area = _triangle_stretch(vertices[faces], uv[faces])
        first, second = uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]
        uv_area = 0.5 * np.abs(first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]).sum()
        relative = stretch * np.sqrt(uv_area / area_3d)  # 1 where the map keeps areas and shapes
        total = float(np.sqrt(np.sum(area * relative**2) / np.sum(area)))
        if not total < best_stretch:
            break
        best, best_stretch = uv.copy(), total
        # each vertex's L2 stretch, area-weighted over its triangles
        squared = np.bincount(faces.ravel(), weights=np.repeat(area * relative**2, 3), minlength=count)
        weight = np.bincount(faces.ravel(), weights=np.repeat(area, 3), minlength=count)
        scale = np.sqrt(squared / np.maximum(weight, 1e-300))
        scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    return best, best_stretch


def parameterize_onto_base(vertices: np.ndarray, faces: np.ndarray, apex: np.ndarray, base: BaseMesh, *,
                           guides: list | None = None, reach: float = 0.0) -> BaseParameterization:
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
    guides, reach
        As for :func:`base_charts`.

    Returns
    -------
    BaseParameterization
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    apex = np.asarray(apex, dtype=np.int64)
    charts = base_charts(vertices, faces, apex, base, guides=guides, reach=reach)
    # arc-length fraction of every path vertex along its base edge
    fraction = {}
    for (a, b), path in zip(base_edges(base), charts.paths, strict=True):
        steps = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(vertices[path], axis=0), axis=1))]
        for vertex, s in zip(path.tolist(), (steps / steps[-1]).tolist(), strict=True):
            fraction[vertex] = (int(a), int(b), s)
    corners = np.zeros((len(faces), 3, 3))
    stretch = np.zeros(len(base.faces))
    for facet, base_face in enumerate(base.faces):
        members = np.flatnonzero(charts.chart == facet)
        chart_faces = faces[members]
        local, inverse = np.unique(chart_faces, return_inverse=True)
        local_faces = inverse.reshape(-1, 3)
        if charts.flipped:
            local_faces = local_faces[:, ::-1]
        frame = _facet_frame(base.vertices[base_face])
        slot = {int(v): k for k, v in enumerate(base_face)}
        border = np.array([k for k, v in enumerate(local.tolist()) if v in fraction], dtype=np.int64)
        border_uv = np.empty((len(border), 2))
        for row, k in enumerate(border):
            a, b, s = fraction[int(local[k])]
            if s in (0.0, 1.0):  # an anchor: the facet's corner (it ends several paths)
                a = b = int(np.flatnonzero(apex == local[k])[0])
            border_uv[row] = (1 - s) * frame[slot[a]] + s * frame[slot[b]]
        weights = _mean_value_weights(vertices[local], local_faces, len(local))
        uv, stretch[facet] = _chart_map(vertices[local], local_faces, border, border_uv, weights)
        if charts.flipped:
            local_faces = local_faces[:, ::-1]
        corners[members] = _barycentric_2d(frame, uv[local_faces].reshape(-1, 2)).reshape(-1, 3, 3)
    return BaseParameterization(charts.chart, corners, stretch, charts)


def vertex_base_coordinates(parameterization: BaseParameterization, faces: np.ndarray,
                            count: int) -> tuple[np.ndarray, np.ndarray]:
    """Where each of a surface's ``count`` vertices lies on the base: ``(facets [N],
    barycentric [N, 3])``, read from one face at the vertex (a vertex on a chart's border has
    the same point in every chart); the vertices from ``count`` on (the anchors a closed
    surface appends) are left out. A vertex in no face gets facet -1."""
    faces = np.asarray(faces, dtype=np.int64)
    size = max(count, int(faces.max(initial=-1)) + 1)
    facets = np.full(size, -1, dtype=np.int64)
    barycentric = np.zeros((size, 3))
    for corner in range(3):
        facets[faces[:, corner]] = parameterization.chart
        barycentric[faces[:, corner]] = parameterization.corners[:, corner]
    return facets[:count], barycentric[:count]


def _barycentric_2d(triangle: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``[P, 3]`` of ``points [P, 2]`` in ``triangle [3, 2]``."""
    a, b, c = triangle
    matrix = np.column_stack([b - a, c - a])
    st = np.linalg.solve(matrix, (points - a).T).T
    return np.column_stack([1.0 - st.sum(axis=1), st])


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
    face where the point fell just outside every triangle of the chart, as on its border).
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
        found_face[asked] = members[near[rows, best]]
        found_bary[asked] = chosen / chosen.sum(axis=1, keepdims=True)
    points = np.einsum("pk,pkd->pd", found_bary, vertices[faces[found_face]])
    return points, found_face, found_bary
