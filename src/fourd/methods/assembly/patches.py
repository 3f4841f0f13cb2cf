"""Matching disk-shaped patches on a source and a target mesh, grown around anchors (thesis
section 5.4.2, "Patch Growth").

A patch is a geodesic ball (Dijkstra distances along the edges) made a disk: the faces with
every corner within the radius, the piece holding the centre, small holes filled. The source
patch and the target patch of a pair grow together, with the same radius, until both hold
``patch_anchors`` matching anchors (an anchor matches when its source vertex lies in the
source patch and its target triangle in the target patch); a pair that reaches the largest
radius with fewer than ``min_anchors`` is discarded. The radius then grows by the ignored
boundary band, so the anchors lie where the map is kept. When the two balls at that radius
are not both disks (a limb thinner than the patch, where the ball wraps round it), the pair
is tried once more at the smaller radius where ``min_anchors`` anchors enter (the thesis
asks for 3-5 anchors a patch): on crane's and dfaust-hopping's first pairs that covers 0.4%
and 1.1% more of the source.

The first pass grows a pair around every anchor, or (``centre_spacing``) around anchors that
far apart, then around the other anchors no kept patch covers yet: a patch holds several
anchors, so pairs around all of them cover each vertex many times over. A second pass grows
pairs around the source vertices no kept patch covers yet (outside its boundary band). Such a
vertex has no known image, so the thesis grows the target patch around the nearest anchor's
image instead; here the target patch is centred on the vertex's estimated image, the target
vertex whose geodesic distances from the nearest anchors' images best match the vertex's own
distances from those anchors (a geodesic multilateration), so both patches cover the same piece
of surface (for a rigidly moved copy, exactly the same) and grow as before. When a pair fails,
the uncovered vertices within half the distance from its centre to the nearest anchor are not
tried again. Vertices that stay uncovered have no counterpart on the target.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.flattening import boundary_loop_vertices
from fourd.geometry.geodesic import (
    GeodesicBall,
    GeodesicScratch,
    edge_length_graph,
    geodesic_ball,
    geodesic_scratch,
)
from fourd.geometry.meshes import face_adjacency, face_areas, median_edge_length
from fourd.methods.assembly.anchors import Anchors, spread_anchors
from fourd.methods.assembly.options import CrossParamOptions

log = logging.getLogger("fourd.methods.assembly.patches")

#: Holes of a patch are the pieces of the rest of the mesh lying within this multiple of the
#: radius (a piece reaching farther is the outside).
HOLE_REACH = 1.5
#: The geodesic searches of a pair start at this many times the reach its anchors need at their
#: mean density (:func:`grow_patches`); the 90th percentile of the reach found was 1.45-1.64
#: times that on the first pairs of crane, dfaust-hopping and touching-spheres. Only the time
#: depends on it (a short search is doubled).
SEARCH_SLACK = 1.6


class Patch(NamedTuple):
    """A disk-shaped piece of a mesh.

    faces : int64 [K]
        The mesh's faces in the patch (sorted).
    vertices : int64 [M]
        Their vertices (sorted).
    distance : float64 [M]
        Geodesic distance of each from the patch's centre (along edges; input units).
    radius : float
        The patch's radius (input units).
    """

    faces: np.ndarray
    vertices: np.ndarray
    distance: np.ndarray
    radius: float


class PatchPair(NamedTuple):
    """Matching patches on the source and the target.

    source, target : Patch
    anchors : int64 [K]
        The matching anchors (indices into :class:`Anchors`), at least ``min_anchors``.
    centre : int
        The source vertex at the source patch's centre.
    """

    source: Patch
    target: Patch
    anchors: np.ndarray
    centre: int


class GrownPatches(NamedTuple):
    """What :func:`grow_patches` found.

    pairs : list of PatchPair
    discarded : int
        Pairs given up (too few anchors within the largest radius, or not a disk).
    covered : bool [N]
        Source vertices inside some kept source patch, outside its boundary band.
    """

    pairs: list
    discarded: int
    covered: np.ndarray


class _Mesh(NamedTuple):
    vertices: np.ndarray
    faces: np.ndarray
    graph: sp.csr_matrix  # edge lengths
    incidence: sp.csr_matrix  # vertex -> faces [N, F]
    face_graph: sp.csr_matrix  # face -> edge-adjacent faces [F, F]
    degree: np.ndarray  # edge-adjacent faces of each face [F] (below 3: on the mesh's own boundary)
    first_face: np.ndarray  # a face of each vertex [N] (F for a vertex of no face)
    slot: np.ndarray  # -1 per vertex [N], scratch of _patch_vertices (left as found)
    search: GeodesicScratch  # scratch of the geodesic searches (left as found)
    face_state: np.ndarray  # 0 per face [F], scratch of _disk_faces (left as found)
    near_faces: np.ndarray  # [F], scratch of _disk_faces


def _mesh(vertices, faces) -> _Mesh:
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    adjacency = face_adjacency(faces)[0]
    count = len(faces)
    rows = np.repeat(np.arange(count), 3)
    incidence = sp.csr_matrix((np.ones(3 * count, dtype=bool), (faces.ravel(), rows)), shape=(len(vertices), count))
    face_graph = sp.csr_matrix(
        (np.ones(2 * len(adjacency), dtype=bool), (np.r_[adjacency[:, 0], adjacency[:, 1]], np.r_[adjacency[:, 1], adjacency[:, 0]])),
        shape=(count, count),
    )
    degree = np.bincount(adjacency.ravel(), minlength=count)
    first_face = np.full(len(vertices), count, dtype=np.int64)
    np.minimum.at(first_face, faces.ravel(), rows)
    return _Mesh(vertices, faces, edge_length_graph(vertices, faces), incidence, face_graph, degree, first_face,
                 np.full(len(vertices), -1, dtype=np.int64), geodesic_scratch(len(vertices)),
                 np.zeros(count, dtype=np.int8), np.empty(count, dtype=np.int64))


def _ball(mesh: _Mesh, seeds, offsets, limit: float) -> GeodesicBall:
    """Geodesic distance ``[N]`` from the nearest seed plus its offset (inf beyond ``limit``),
    and the vertices reached."""
    return geodesic_ball(mesh.graph, seeds, offsets, limit, mesh.search)


def _distances(mesh: _Mesh, seeds, offsets, limit: float) -> np.ndarray:
    """:func:`_ball`'s distances ``[N]``."""
    return _ball(mesh, seeds, offsets, limit).distances


def _disk(mesh: _Mesh, ball: GeodesicBall, radius: float, seed_face: int) -> Patch | None:
    """The geodesic ball of ``radius`` as a disk holding ``seed_face``, or None when it is
    not one.

    Works on the faces near the ball only (a corner within ``HOLE_REACH * radius``): a piece of
    the rest of the mesh that leaves them reaches farther than that, so it is not a hole."""
    distance = ball.distances
    faces = _disk_faces(mesh.faces, mesh.face_graph.indptr, mesh.face_graph.indices, mesh.degree,
                        mesh.incidence.indptr, mesh.incidence.indices, distance, ball.vertices, float(radius),
                        HOLE_REACH * float(radius), int(seed_face), mesh.face_state, mesh.near_faces)
    if not len(faces):
        return None
    vertices, local_faces = _patch_vertices(mesh.faces, faces, mesh.slot)
    try:
        boundary_loop_vertices(local_faces, len(vertices))
    except ValueError:
        return None
    return Patch(faces, vertices, distance[vertices], float(radius))


@numba.njit(cache=True, nogil=True)
def _patch_vertices(faces, chosen, slot):
    """The vertices of the ``chosen`` faces (sorted, ``[M]``) and those faces in their
    indices (``[K, 3]``): ``np.unique`` and ``np.searchsorted`` in one pass, with ``slot``
    (-1 per mesh vertex) as scratch, left as it was found."""
    found = np.empty(3 * len(chosen), dtype=np.int64)
    count = 0
    for f in chosen:
        for k in range(3):
            v = faces[f, k]
            if slot[v] < 0:
                slot[v] = 0
                found[count] = v
                count += 1
    vertices = np.sort(found[:count])
    for i in range(count):
        slot[vertices[i]] = i
    local = np.empty((len(chosen), 3), dtype=np.int64)
    for j in range(len(chosen)):
        for k in range(3):
            local[j, k] = slot[faces[chosen[j], k]]
    for i in range(count):
        slot[vertices[i]] = -1
    return vertices, local


@numba.njit(cache=True, nogil=True)
def _disk_faces(faces, graph_start, graph_faces, degree, incident_start, incident_faces, distance, reached,
                radius, reach, seed_face, state, near):
    """:func:`_near_disk_faces` with the scratch ``state`` (0 per face ``[F]``) reset to 0 after."""
    result, count = _near_disk_faces(faces, graph_start, graph_faces, degree, incident_start, incident_faces,
                                     distance, reached, radius, reach, seed_face, state, near)
    for i in range(count):
        state[near[i]] = 0
    return result


@numba.njit(cache=True, nogil=True)
def _near_disk_faces(faces, graph_start, graph_faces, degree, incident_start, incident_faces, distance, reached,
                     radius, reach, seed_face, state, near):
    """The faces of :func:`_disk` (sorted; none when the seed face is not in the ball): the
    faces near the ball (a corner within ``reach``); among them the edge-connected piece of
    faces with every corner within ``radius`` that holds the seed; and the pieces of the other
    near faces that stay within ``reach`` and touch neither a face beyond the near ones nor
    the mesh's own border (holes). ``reached``: the vertices of finite ``distance`` (no
    other is read). ``state`` (0 per face) and ``near`` (``[F]``) are scratch: returns the
    faces and how many near faces ``near`` lists, whose ``state`` is left changed."""
    # 0 far, 1 near, 2 in the piece, 3 rest, 4 hole, 5 rest that is not a hole
    count = 0
    for v in reached:
        if distance[v] <= reach:
            for e in range(incident_start[v], incident_start[v + 1]):
                f = incident_faces[e]
                if state[f] == 0:
                    state[f] = 1
                    near[count] = f
                    count += 1
    empty = np.empty(0, dtype=np.int64)
    if state[seed_face] == 0:
        return empty, count
    for k in range(3):
        if not distance[faces[seed_face, k]] <= radius:
            return empty, count
    queue = np.empty(count, dtype=np.int64)
    queue[0] = seed_face
    state[seed_face] = 2
    head, tail = 0, 1
    while head < tail:
        f = queue[head]
        head += 1
        for e in range(graph_start[f], graph_start[f + 1]):
            g = graph_faces[e]
            if (state[g] == 1 and distance[faces[g, 0]] <= radius and distance[faces[g, 1]] <= radius
                    and distance[faces[g, 2]] <= radius):
                state[g] = 2
                queue[tail] = g
                tail += 1
    for i in range(count):
        if state[near[i]] == 1:
            state[near[i]] = 3
    for i in range(count):
        start = near[i]
        if state[start] != 3:
            continue
        # one piece of the rest: a hole unless it leaves the near faces, meets the mesh's
        # border or reaches farther than ``reach``
        begin = tail
        queue[tail] = start
        tail += 1
        state[start] = 4
        head = begin
        farthest = 0.0
        outside = False
        while head < tail:
            f = queue[head]
            head += 1
            farthest = max(farthest, distance[faces[f, 0]], distance[faces[f, 1]], distance[faces[f, 2]])
            neighbours = 0
            for e in range(graph_start[f], graph_start[f + 1]):
                g = graph_faces[e]
                if state[g] != 0:
                    neighbours += 1
                if state[g] == 3:
                    state[g] = 4
                    queue[tail] = g
                    tail += 1
            if degree[f] < 3 or degree[f] > neighbours:
                outside = True
        if outside or not farthest <= reach:
            for j in range(begin, tail):
                state[queue[j]] = 5
    kept = 0
    for i in range(count):
        if state[near[i]] == 2 or state[near[i]] == 4:
            kept += 1
    result = np.empty(kept, dtype=np.int64)
    kept = 0
    for i in range(count):
        if state[near[i]] == 2 or state[near[i]] == 4:
            result[kept] = near[i]
            kept += 1
    result.sort()
    return result, count


def _pair(source: _Mesh, target: _Mesh, anchors: Anchors, support: np.ndarray, centre: int, ds: GeodesicBall,
          dt: GeodesicBall, target_face: int, options: CrossParamOptions,
          largest: float) -> PatchPair | None:
    """Grow the pair around ``centre`` (source) and the target point of ``dt``'s origin (in
    ``target_face``) with one radius until it holds ``patch_anchors`` matching anchors, or
    ``min_anchors`` when those balls are not disks (``support``:
    :meth:`Anchors.target_corners`)."""
    for wanted in dict.fromkeys((options.patch_anchors, options.min_anchors)):
        radius = _radius(anchors, support, ds.distances, dt.distances, options, largest, wanted)
        if radius is None:
            return None
        src = _disk(source, ds, radius, int(source.first_face[centre]))
        tgt = _disk(target, dt, radius, target_face)
        if src is not None and tgt is not None:
            break
    else:
        return None
    in_source = np.isin(anchors.source, src.vertices)
    in_target = (np.isin(support, tgt.vertices) | (support < 0)).all(axis=1)
    matching = np.flatnonzero(in_source & in_target)
    if len(matching) < options.min_anchors:
        return None
    return PatchPair(src, tgt, matching, int(centre))


def _radius(anchors: Anchors, support: np.ndarray, ds: np.ndarray, dt: np.ndarray,
            options: CrossParamOptions, largest: float, wanted: int | None = None) -> float | None:
    """The pair's radius: the one at which ``wanted`` anchors (by default ``patch_anchors``)
    lie in both patches (an anchor enters at the larger of its source and target distances),
    widened by the ignored boundary band, at most ``largest``; None when fewer than
    ``min_anchors`` enter by then."""
    wanted = options.patch_anchors if wanted is None else wanted
    entered, entry = _nearest_entries(anchors.source, support, ds, dt, float(largest), int(wanted))
    if entered < options.min_anchors:
        return None
    return min(entry / (1.0 - options.boundary_band), largest)


@numba.njit(cache=True, nogil=True)
def _nearest_entries(source, support, ds, dt, largest, wanted):
    """How many anchors enter by ``largest`` and the radius at which the ``wanted``-th (or the
    last, when fewer) enters (:func:`_radius`)."""
    smallest = np.full(wanted, np.inf)
    entered = 0
    for a in range(len(source)):
        entry = ds[source[a]]
        for c in range(3):
            if support[a, c] >= 0 and dt[support[a, c]] > entry:
                entry = dt[support[a, c]]
        if not entry <= largest:
            continue
        entered += 1
        if entry < smallest[wanted - 1]:
            i = wanted - 1
            while i > 0 and smallest[i - 1] > entry:
                smallest[i] = smallest[i - 1]
                i -= 1
            smallest[i] = entry
    return entered, smallest[min(wanted, entered) - 1] if entered else np.inf


def _near_distances(source: _Mesh, target: _Mesh, anchors: Anchors, support: np.ndarray, centre: int, seeds, offsets,
                    options: CrossParamOptions, largest: float,
                    start: float) -> tuple[GeodesicBall, GeodesicBall]:
    """The geodesic balls ``(ds, dt)`` a pair around ``centre`` and the target ``seeds``
    needs, searched no farther than it needs: from ``start``, doubled until the pair's radius
    times ``HOLE_REACH`` lies within the search (then every distance :func:`_pair` reads is
    the same as with the search to ``largest``)."""
    limit = min(start, largest)
    while True:
        ds = _ball(source, [centre], [0.0], limit)
        dt = _ball(target, seeds, offsets, limit)
        if limit >= largest:
            return ds, dt
        radius = _radius(anchors, support, ds.distances, dt.distances, options, largest)
        if radius is not None and HOLE_REACH * radius <= limit:
            return ds, dt
        limit = min(largest, 2.0 * limit)


def _image(target: _Mesh, corners: np.ndarray, offsets: np.ndarray, reach: np.ndarray,
           limit: float) -> int:
    """The target vertex whose geodesic distances from the given anchors' target points best
    match the source vertex's distances ``reach [K]`` from those anchors (least squares over
    the vertices all of them reach within ``reach + limit``); -1 when none does.

    Anchor ``k`` is searched to ``reach[k] + margin``, the margin from half the largest
    ``reach``, doubled while a vertex beyond some search could cost less than the best one
    found (its cost is at least ``margin^2``), so the answer is that of the searches to
    ``reach + limit``. The nearest anchor's search, the smallest, gives the candidates."""
    farthest = float(np.max(reach))
    margin = min(limit, 0.5 * farthest) if farthest > 0 else limit
    order = np.argsort(reach, kind="stable")
    while True:
        first = order[0]
        distance = _distances(target, corners[first], offsets[first], reach[first] + margin)
        candidates = np.flatnonzero(np.isfinite(distance))
        cost = (distance[candidates] - reach[first]) ** 2
        for k in order[1:]:
            cost += (_distances(target, corners[k], offsets[k], reach[k] + margin)[candidates] - reach[k]) ** 2
        best = int(np.argmin(cost)) if len(cost) else -1
        if margin >= limit or (best >= 0 and cost[best] < margin**2):
            return int(candidates[best]) if best >= 0 and np.isfinite(cost[best]) else -1
        margin = min(limit, 2.0 * margin)


def _nearest_anchors(source: _Mesh, anchors: Anchors, centre: int, count: int, largest: float, start: float):
    """The ``count`` anchors nearest ``centre`` along the source (those within ``largest``),
    the distances of every anchor and of every source vertex from ``centre`` (inf beyond the
    search), searched from ``start``, doubled until ``count`` anchors lie within it."""
    search = min(start, largest)
    while True:
        distance = _distances(source, [centre], [0.0], search)
        reach = distance[anchors.source]
        if np.isfinite(reach).sum() >= count or search >= largest:
            near = np.argsort(reach, kind="stable")[:count]
            return near[np.isfinite(reach[near])], reach, distance
        search = min(largest, 2.0 * search)


def grow_patches(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    anchors: Anchors,
    options: CrossParamOptions | None = None,
) -> GrownPatches:
    """Grow matching patch pairs around the anchors, then around the uncovered source vertices
    (module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
    anchors : Anchors
    options : CrossParamOptions, optional

    Returns
    -------
    GrownPatches
    """
    options = CrossParamOptions() if options is None else options
    source = _mesh(source_vertices, source_faces)
    target = _mesh(target_vertices, target_faces)
    diagonal = float(np.linalg.norm(np.ptp(source.vertices[source.faces.ravel()], axis=0)))
    largest = options.max_radius * diagonal
    anchor_points = anchors.target_points(target.vertices, target.faces)
    corners = target.faces[anchors.target_faces]  # [A, 3]
    support = anchors.target_corners(target.faces)
    offsets = np.linalg.norm(target.vertices[corners] - anchor_points[:, None], axis=2)
    covered = np.zeros(len(source.vertices), dtype=bool)
    used = np.zeros(len(source.vertices), dtype=bool)
    used[np.setdiff1d(np.arange(len(source.vertices)), source.faces.ravel())] = True
    pairs, discarded = [], 0
    # the searches start at SEARCH_SLACK times what they need where the anchors lie at their
    # mean density (a disk holding ``patch_anchors`` of them), and double when that is short
    anchor_reach = np.sqrt(options.patch_anchors * face_areas(source.vertices, source.faces).sum()
                           / (np.pi * max(len(anchors.source), 1)))
    anchor_search = min(largest, SEARCH_SLACK * anchor_reach)
    pair_search = min(largest, SEARCH_SLACK * HOLE_REACH * anchor_reach / (1.0 - options.boundary_band))

    def keep(pair: PatchPair | None) -> bool:
        nonlocal discarded
        if pair is None:
            discarded += 1
            return False
        pairs.append(pair)
        inner = pair.source.distance <= (1.0 - options.boundary_band) * pair.source.radius
        covered[pair.source.vertices[inner]] = True
        return True

    first = np.arange(len(anchors.source))
    if options.centre_spacing > 0 and len(first):
        spacing = options.centre_spacing * median_edge_length(source.vertices, source.faces)
        first = np.flatnonzero(spread_anchors(anchors, source.vertices, spacing))

    def around_anchor(a: int) -> None:
        ds, dt = _near_distances(source, target, anchors, support, anchors.source[a], corners[a], offsets[a],
                                 options, largest, pair_search)
        keep(_pair(source, target, anchors, support, anchors.source[a], ds, dt,
                   int(anchors.target_faces[a]), options, largest))
        used[anchors.source[a]] = True

    for a in first:
        around_anchor(a)
    # then the anchors the spread passed over that no patch covers: their images are known
    for a in range(len(anchors.source)):
        if not covered[anchors.source[a]] and not used[anchors.source[a]]:
            around_anchor(a)
    while True:
        left = np.flatnonzero(~covered & ~used)
        if len(left) == 0:
            break
        centre = int(left[0])
        used[centre] = True
        near, reach, from_centre = _nearest_anchors(source, anchors, centre, options.patch_anchors, largest,
                                                    anchor_search)
        if len(near) < options.min_anchors:
            discarded += 1
            continue
        image = _image(target, corners[near], offsets[near], reach[near], 2.0 * largest)
        if image >= 0:
            ds, dt = _near_distances(source, target, anchors, support, centre, [image], [0.0], options, largest,
                                     pair_search)
            if keep(_pair(source, target, anchors, support, centre, ds, dt, int(target.first_face[image]),
                          options, largest)):
                continue
        else:
            discarded += 1
        # a failed pair rules out its neighbours within half the distance to its nearest
        # anchor: they see the same anchors at nearly the same distances. Retrying them one by
        # one cost 34 of 36 s on a crane pair with a tenth of the source unmatched (3,336
        # tries, one kept; now 435 tries, the same one kept)
        used[from_centre <= 0.5 * reach[near].min()] = True
    log.debug("patches: %d kept, %d discarded, %.1f%% of the source covered",
              len(pairs), discarded, 100.0 * covered.mean())
    return GrownPatches(pairs, discarded, covered)
