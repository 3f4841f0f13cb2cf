"""Local relaxation of a cross-parameterisation (thesis section 5.4.3).

The patch map (:mod:`~fourd.methods.assembly.crossparam`) is close to the right map but can
be locally bad, with flipped triangles where neighbouring vertices took different patches.
The relaxation minimises the change of the source's Laplacian coordinates (eq. 5.1),

    min over ṽ on the target surface of  sum_i |(L ṽ)_i - R_i (L v)_i|^2,

``v`` the source vertices, ``ṽ`` their mapped points, ``L`` the source Laplacian. The thesis
writes ``|L ṽ - L v|``; the frames differ by a motion, so here each source Laplacian vector is
first turned by its vertex's rotation ``R_i`` (the one best aligning the source one-ring's
edges with the mapped one-ring's, as in as-rigid-as-possible modelling), which the Laplacian
editing the thesis cites ([LSA+05]) also factors out. A rigidly moved copy then keeps the
identity map, where the plain difference would pull every vertex. Rows whose vertex or a
neighbour has no mapped point are left out; those vertices stay unmapped.

With the rotations held for a sweep, the energy as a function of one vertex's mapped point
``p`` (everything else held) is ``c_i |p - q_i|^2`` plus a constant: ``q_i`` is where the
vertex would go unconstrained and ``c_i`` the sum of the squares of ``L``'s column ``i``.
The search of the thesis, random walks from the vertex's point, each optimising the vertex's
Laplacian vector, is then mostly a set of line searches: the steepest tangent direction
(towards ``q_i``) and half of ``walks`` random tangent directions are walked over the target's
faces (:mod:`fourd.geometry.surface_walk`) by the step that brings the point nearest ``q_i``
along them; the other half walk a random length. The best end is taken when it lowers the
energy. A move may not flip more of the vertex's triangles than it finds flipped, and one
that flips fewer wins over any that does not, whatever it costs: flipped triangles are fixed
first. A triangle is flipped when its mapped normal points against the target's normals at
its mapped corners.

Vertices are visited in decreasing order of their error, as in the thesis, but in batches
that move at once: a batch holds vertices more than two edges apart (an independent set of
the squared adjacency), whose moves change disjoint sets of rows and so do not interact. The
batches come from a Jones-Plassmann selection with the error's quartile as the priority (a
vertex goes when no remaining vertex within two edges is in a higher quartile, ties broken at
random), so the order follows the error without the long chains a smooth priority gives.
The rotations are refitted at every sweep.

References
----------
Y. Lipman, O. Sorkine, M. Alexa, D. Cohen-Or, D. Levin, C. Rössl, H.-P. Seidel, "Laplacian
framework for interactive mesh editing", IJSM 2005 ([LSA+05] of the thesis).
O. Sorkine, M. Alexa, "As-rigid-as-possible surface modeling", SGP 2007 (the one-ring
rotations).
M. T. Jones, P. E. Plassmann, "A parallel graph coloring heuristic", SIAM J. Sci. Comput.
14(3), 1993.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.laplacian import cotangent_laplacian, uniform_laplacian
from fourd.geometry.meshes import median_edge_length, mesh_arrays, vertex_adjacency
from fourd.geometry.rotations import one_ring_rotations
from fourd.geometry.surface_walk import TINY_STEP, face_neighbours, face_unit_normals, walk_point
from fourd.methods.assembly.options import RelaxOptions

log = logging.getLogger("fourd.methods.assembly.relax")

#: Error levels (quantiles) of the visiting order within a sweep.
ORDER_LEVELS = 4
#: Edges a walk may cross (:func:`fourd.geometry.surface_walk.walk_on_surface`'s default).
MAX_CROSSINGS = 64


class RelaxedMap(NamedTuple):
    """A relaxed map of the source vertices onto the target (:func:`relax_map`).

    faces : int64 [N]
        Target triangle of each source vertex (-1 where unmapped, as given).
    barycentric : float64 [N, 3]
    points : float64 [N, 3]
        The mapped points (NaN where unmapped).
    energy : float64 [S + 1]
        The energy (module docstring; input units squared) before the first sweep and after
        each of the ``S`` sweeps.
    flipped : int64 [S + 1]
        Flipped source triangles (:func:`flipped_triangles`) before and after each sweep.
    moved : int64 [S]
        Vertices that moved in each sweep.
    """

    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray
    energy: np.ndarray
    flipped: np.ndarray
    moved: np.ndarray


def source_laplacian(vertices: np.ndarray, faces: np.ndarray, kind: str = "uniform") -> sp.csr_matrix:
    """The Laplacian of the relaxation ``[N, N]`` (positive semi-definite convention of
    :mod:`fourd.geometry.laplacian`): uniform, or cotangent with negative weights clamped."""
    if kind == "uniform":
        return uniform_laplacian(len(vertices), faces)
    if kind == "cotangent":
        return cotangent_laplacian(vertices, faces, clamp_negative=True)
    raise ValueError(f"laplacian must be 'uniform' or 'cotangent', got {kind!r}")


def mapped_points(target_vertices: np.ndarray, target_faces: np.ndarray, faces: np.ndarray,
                  barycentric: np.ndarray) -> np.ndarray:
    """Points ``[N, 3]`` of a map given as target triangles ``faces [N]`` (-1: unmapped, NaN)
    and ``barycentric [N, 3]``."""
    faces = np.asarray(faces, dtype=np.int64)
    corners = np.asarray(target_vertices, dtype=np.float64)[np.asarray(target_faces)[np.maximum(faces, 0)]]
    points = np.einsum("nk,nkd->nd", np.asarray(barycentric, dtype=np.float64), corners)
    points[faces < 0] = np.nan
    return points


def flipped_triangles(source_faces: np.ndarray, target_vertices: np.ndarray, target_faces: np.ndarray,
                      faces: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
    """Source triangles the map flips, bool ``[F]``: the normal of the triangle of its mapped
    corners points against (or is perpendicular to) the sum of the target triangles' normals
    at those corners. Triangles with an unmapped corner are not flipped."""
    source_faces = np.asarray(source_faces, dtype=np.int64)
    faces = np.asarray(faces, dtype=np.int64)
    points = mapped_points(target_vertices, target_faces, faces, barycentric)
    normals = face_unit_normals(target_vertices, target_faces)[np.maximum(faces, 0)]
    corners = points[source_faces]
    mapped = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    reference = normals[source_faces].sum(axis=1)
    complete = (faces[source_faces] >= 0).all(axis=1)
    return complete & ~(np.einsum("fd,fd->f", mapped, reference) > 0)


class _Problem(NamedTuple):
    laplacian: sp.csr_matrix
    rows: sp.csc_matrix  # the Laplacian's complete rows, by columns
    weight: np.ndarray  # [N] c_i
    delta: np.ndarray  # [N, 3] source Laplacian vectors
    complete: np.ndarray  # [N] rows in the energy
    edges: sp.csr_matrix  # one-ring weights for the rotations
    near: sp.csr_matrix  # vertices within two edges (no diagonal)
    incident: np.ndarray  # [N, D] source faces at each vertex, -1 padded
    face_ok: np.ndarray  # [F] source faces with every corner mapped
    source_faces: np.ndarray
    target_vertices: np.ndarray
    target_faces: np.ndarray
    target_normals: np.ndarray
    target_neighbours: np.ndarray
    scale: float  # the source's median edge length


def _incident_faces(faces: np.ndarray, count: int) -> np.ndarray:
    vertex = faces.ravel()
    order = np.argsort(vertex, kind="stable")
    vertex = vertex[order]
    start = np.searchsorted(vertex, np.arange(count))
    slot = np.arange(len(vertex)) - start[vertex]
    table = np.full((count, max(int(slot.max(initial=-1)) + 1, 1)), -1, dtype=np.int64)
    table[vertex, slot] = order // 3
    return table


def _problem(source_vertices, source_faces, target_vertices, target_faces, mapped, kind) -> _Problem:
    count = len(source_vertices)
    laplacian = source_laplacian(source_vertices, source_faces, kind)
    adjacency = vertex_adjacency(source_faces, count)
    unmapped_near = adjacency @ (~mapped).astype(np.float64)
    complete = mapped & (unmapped_near == 0)
    rows = sp.diags(complete.astype(np.float64)) @ laplacian
    weight = np.asarray(rows.multiply(rows).sum(axis=0)).ravel()
    edges = abs(laplacian - sp.diags(laplacian.diagonal())).tocsr()
    ring = adjacency + sp.identity(count, format="csr")
    near = (ring @ ring).tocsr()
    near.setdiag(0.0)
    near.eliminate_zeros()
    return _Problem(
        laplacian, rows.tocsc(), weight, laplacian @ source_vertices, complete, edges, near,
        _incident_faces(source_faces, count), mapped[source_faces].all(axis=1), source_faces,
        target_vertices, target_faces, face_unit_normals(target_vertices, target_faces),
        face_neighbours(target_faces), median_edge_length(source_vertices, source_faces),
    )


def _goals(problem: _Problem, source_vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``R_i (L v)_i`` ``[N, 3]``, ``R_i`` the rotation best aligning vertex ``i``'s source
    one-ring edges with the mapped ones."""
    return np.einsum("nab,nb->na", one_ring_rotations(problem.edges, source_vertices, points), problem.delta)


def _residual(problem: _Problem, points: np.ndarray, goals: np.ndarray) -> np.ndarray:
    return (problem.laplacian @ points - goals) * problem.complete[:, None]


def _energy(problem: _Problem, source_vertices: np.ndarray, points: np.ndarray) -> float:
    return float(np.sum(_residual(problem, points, _goals(problem, source_vertices, points)) ** 2))


@numba.njit(cache=True, nogil=True)
def _vertex_flips(incident, face_ok, source_faces, target_normals, points, faces, vertex, px, py, pz, face):
    """Flipped triangles around ``vertex`` with it at the point ``(px, py, pz)`` in target
    triangle ``face``: a triangle counts when every corner is mapped; it is flipped when the
    normal of its mapped corners does not point along the sum of the target normals at them."""
    flips = 0
    for d in range(incident.shape[1]):
        triangle = incident[vertex, d]
        if triangle < 0 or not face_ok[triangle]:
            continue
        moved = 0
        while source_faces[triangle, moved] != vertex:
            moved += 1
        one, two = source_faces[triangle, (moved + 1) % 3], source_faces[triangle, (moved + 2) % 3]
        nx = target_normals[face, 0] + target_normals[faces[one], 0] + target_normals[faces[two], 0]
        ny = target_normals[face, 1] + target_normals[faces[one], 1] + target_normals[faces[two], 1]
        nz = target_normals[face, 2] + target_normals[faces[one], 2] + target_normals[faces[two], 2]
        # the corners in the triangle's order from the moved one: the same orientation
        ax, ay, az = points[one, 0] - px, points[one, 1] - py, points[one, 2] - pz
        bx, by, bz = points[two, 0] - px, points[two, 1] - py, points[two, 2] - pz
        dot = (ay * bz - az * by) * nx + (az * bx - ax * bz) * ny + (ax * by - ay * bx) * nz
        if not dot > 0:
            flips += 1
    return flips


@numba.njit(cache=True, nogil=True, parallel=True)
def _step(batch, goal, faces, bary, points, target_vertices, target_faces, target_normals, target_neighbours,
          incident, face_ok, source_faces, angle, reach, moved):
    """One step of :func:`_move` for every batch vertex (in place): the tangent step towards
    its ``goal [B, 3]``, then ``W`` random directions (``angle [B, W]`` in the target face's
    frame; the first half walked to the point nearest the goal, the rest by ``reach [B, W]``);
    the end with the fewest flipped triangles, then the lowest energy, is taken if it flips
    fewer than now or lowers the energy. The batch's vertices are independent (module
    docstring), so they move in parallel."""
    walks = angle.shape[1]
    half = walks // 2
    tries = walks + 1
    for b in numba.prange(len(batch)):
        end_bary = np.empty((tries, 3))
        end_face = np.empty(tries, dtype=np.int64)
        end_point = np.empty((tries, 3))
        vertex = batch[b]
        f = faces[vertex]
        hx, hy, hz = points[vertex, 0], points[vertex, 1], points[vertex, 2]
        gx, gy, gz = goal[b, 0], goal[b, 1], goal[b, 2]
        nx, ny, nz = target_normals[f, 0], target_normals[f, 1], target_normals[f, 2]
        tx, ty, tz = gx - hx, gy - hy, gz - hz
        along = tx * nx + ty * ny + tz * nz
        tx, ty, tz = tx - along * nx, ty - along * ny, tz - along * nz
        i0, i1 = target_faces[f, 0], target_faces[f, 1]
        fx = target_vertices[i1, 0] - target_vertices[i0, 0]
        fy = target_vertices[i1, 1] - target_vertices[i0, 1]
        fz = target_vertices[i1, 2] - target_vertices[i0, 2]
        length = np.sqrt(fx * fx + fy * fy + fz * fz)
        b0, b1, b2 = max(bary[vertex, 0], 0.0), max(bary[vertex, 1], 0.0), max(bary[vertex, 2], 0.0)
        total = b0 + b1 + b2
        if not (length > 0 and total > 0):  # a degenerate triangle gives no tangent frame
            continue
        fx, fy, fz = fx / length, fy / length, fz / length
        b0, b1, b2 = b0 / total, b1 / total, b2 / total  # every walk starts here
        sx, sy, sz = ny * fz - nz * fy, nz * fx - nx * fz, nx * fy - ny * fx
        now = (hx - gx) ** 2 + (hy - gy) ** 2 + (hz - gz) ** 2
        fewest, best, best_gain = 1 << 62, -1, np.inf
        for k in range(tries):
            if k == 0:
                dx, dy, dz = tx, ty, tz
            else:
                c, s = np.cos(angle[b, k - 1]), np.sin(angle[b, k - 1])
                ux, uy, uz = c * fx + s * sx, c * fy + s * sy, c * fz + s * sz
                step = ux * tx + uy * ty + uz * tz if k - 1 < half else reach[b, k - 1]
                dx, dy, dz = step * ux, step * uy, step * uz
            end_bary[k, 0], end_bary[k, 1], end_bary[k, 2] = b0, b1, b2
            face, _ = walk_point(target_vertices, target_faces, target_neighbours, target_normals, f, end_bary[k],
                                 dx, dy, dz, MAX_CROSSINGS, TINY_STEP)
            e0, e1, e2 = max(end_bary[k, 0], 0.0), max(end_bary[k, 1], 0.0), max(end_bary[k, 2], 0.0)
            e = e0 + e1 + e2
            if not e > 0:
                continue
            end_bary[k, 0], end_bary[k, 1], end_bary[k, 2] = e0 / e, e1 / e, e2 / e
            end_face[k] = face
            for x in range(3):
                end_point[k, x] = (end_bary[k, 0] * target_vertices[target_faces[face, 0], x]
                                   + end_bary[k, 1] * target_vertices[target_faces[face, 1], x]
                                   + end_bary[k, 2] * target_vertices[target_faces[face, 2], x])
            gain = (end_point[k, 0] - gx) ** 2 + (end_point[k, 1] - gy) ** 2 + (end_point[k, 2] - gz) ** 2 - now
            flips = _vertex_flips(incident, face_ok, source_faces, target_normals, points, faces, vertex,
                                  end_point[k, 0], end_point[k, 1], end_point[k, 2], face)
            if flips < fewest or (flips == fewest and gain < best_gain):
                fewest, best, best_gain = flips, k, gain
        flips_now = _vertex_flips(incident, face_ok, source_faces, target_normals, points, faces, vertex,
                                  hx, hy, hz, f)
        if best >= 0 and (fewest < flips_now or (fewest == flips_now and best_gain < 0)):
            faces[vertex] = end_face[best]
            for x in range(3):
                bary[vertex, x] = end_bary[best, x]
                points[vertex, x] = end_point[best, x]
            moved[b] = True


def _move(problem, batch, faces, bary, points, residual, rng, options: RelaxOptions) -> int:
    """Move the batch's vertices (in place); returns how many moved."""
    start = points[batch].copy()
    rows = problem.rows[:, batch]  # the energy rows the batch's vertices enter
    pull = rows.T @ residual
    goal = np.ascontiguousarray(start - pull / problem.weight[batch, None])  # q_i
    moved = np.zeros(len(batch), dtype=bool)
    for _ in range(options.steps):
        angle = rng.uniform(0.0, 2.0 * np.pi, size=(len(batch), options.walks))
        # the second half walk a random length: the way out of a flip may cost energy
        reach = problem.scale * 10.0 ** rng.uniform(-2.0, 0.0, size=angle.shape)
        _step(batch, goal, faces, bary, points, problem.target_vertices, problem.target_faces, problem.target_normals,
              problem.target_neighbours, problem.incident, problem.face_ok, problem.source_faces, angle, reach, moved)
    residual += rows @ (points[batch] - start)
    return int(moved.sum())


def _batches(near: sp.csr_matrix, error: np.ndarray, movable: np.ndarray, rng) -> list[np.ndarray]:
    """Independent sets of ``near`` covering ``movable``, higher error levels first
    (Jones-Plassmann; module docstring), each in increasing vertex order."""
    levels = np.zeros(len(error))
    if movable.any():
        edges = np.quantile(error[movable], np.linspace(0.0, 1.0, ORDER_LEVELS + 1)[1:-1])
        levels = np.searchsorted(edges, error, side="right").astype(np.float64)
    key = levels + rng.random(len(error)) * 0.5  # random ties within a level
    candidates = np.flatnonzero(movable)
    rounds = _selection_rounds(near.indptr, near.indices, key, movable, candidates[np.argsort(-key[candidates])])
    order = candidates[np.argsort(rounds[candidates], kind="stable")]
    return np.split(order, np.flatnonzero(np.diff(rounds[order])) + 1) if len(order) else []


@numba.njit(cache=True, nogil=True)
def _selection_rounds(indptr, indices, key, movable, descending):
    """The Jones-Plassmann round of each movable vertex ``[N]``: a vertex is selected in the
    round after the last of its movable neighbours with a higher key (``descending``: the
    movable vertices by decreasing key), so round 0 holds the local maxima."""
    rounds = np.zeros(len(key), dtype=np.int64)
    for vertex in descending:
        highest = -1
        for slot in range(indptr[vertex], indptr[vertex + 1]):
            other = indices[slot]
            if movable[other] and key[other] > key[vertex] and rounds[other] > highest:
                highest = rounds[other]
        rounds[vertex] = highest + 1
    return rounds


def relax_map(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    faces: np.ndarray,
    barycentric: np.ndarray,
    options: RelaxOptions | None = None,
    *,
    fixed: np.ndarray | None = None,
) -> RelaxedMap:
    """Relax a map of the source vertices onto the target surface (thesis section 5.4.3;
    module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
        Both meshes oriented the same way (outward normals).
    faces : int array [N]
        Target triangle of each source vertex's mapped point (-1: unmapped).
    barycentric : array [N, 3]
        Its coordinates in that triangle.
    options : RelaxOptions, optional
    fixed : bool array [N], optional
        Vertices that keep their mapped point.

    Returns
    -------
    RelaxedMap
    """
    options = RelaxOptions() if options is None else options
    source_vertices, source_faces = mesh_arrays(source_vertices, source_faces)
    target_vertices, target_faces = mesh_arrays(target_vertices, target_faces)
    faces = np.array(faces, dtype=np.int64).reshape(-1)
    bary = np.array(barycentric, dtype=np.float64).reshape(-1, 3)
    count = len(source_vertices)
    if len(faces) != count or len(bary) != count:
        raise ValueError(f"faces and barycentric must have one row per source vertex ({count}), "
                         f"got {len(faces)} and {len(bary)}")
    if np.any(faces >= len(target_faces)):
        raise ValueError("faces index target triangles out of range")
    mapped = faces >= 0
    fixed = np.zeros(count, dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool).reshape(-1)
    problem = _problem(source_vertices, source_faces, target_vertices, target_faces, mapped, options.laplacian)
    movable = mapped & ~fixed & (problem.weight > 0)
    points = np.nan_to_num(mapped_points(target_vertices, target_faces, faces, bary))
    rng = np.random.default_rng(options.seed)

    def flips() -> int:
        return int(flipped_triangles(source_faces, target_vertices, target_faces, faces, bary).sum())

    energy, flipped, moved = [_energy(problem, source_vertices, points)], [flips()], []
    for _ in range(options.sweeps):
        residual = _residual(problem, points, _goals(problem, source_vertices, points))
        error = np.sum(residual**2, axis=1)
        total = 0
        for batch in _batches(problem.near, error, movable, rng):
            total += _move(problem, batch, faces, bary, points, residual, rng, options)
        energy.append(_energy(problem, source_vertices, points))
        flipped.append(flips())
        moved.append(total)
        if options.tolerance > 0 and energy[-2] - energy[-1] < options.tolerance * energy[0]:
            break
    log.debug("relaxation: energy %.3g -> %.3g, flipped %d -> %d", energy[0], energy[-1], flipped[0], flipped[-1])
    points[~mapped] = np.nan
    return RelaxedMap(faces, bary, points, np.array(energy), np.array(flipped, dtype=np.int64),
                      np.array(moved, dtype=np.int64))
