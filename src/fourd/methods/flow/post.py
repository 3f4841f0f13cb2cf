"""Postprocessing (paper 002, section 4(c)): refinement, a Laplace solve, marching cubes.

Multi-resolution scheme (the paper's hexadeca-tree, two levels): away from the flow surface
the 4D function is the signed distance of the flow's characteristic function (coarse cells,
interpolated); in a band of ``band`` coarse cells around the flow surface the space is refined
``refine`` times per axis (time keeps the flow grid's slices), and the fine values there are
the least-squares solution of

    sum_nodes omega_i (f_i - s_i)^2 + mu * sum_{4D edges} tau_e (f_i - f_j)^2

with the coarse values outside the band as Dirichlet boundary conditions (the flow labels
as boundary conditions of the Laplace system). Targets ``s`` are signed distances from the
data (distance to the tangent planes of the nearest oriented data points) on nodes near data,
weight 1, and from the flow solution on nodes deep inside or outside, weighted by depth;
nodes near the surface without data are unknown (weight 0) and filled by the Laplace term.
``tau_e`` is 1 on spatial edges and on temporal edges that touch a slice without data (they
let data of neighbouring frames shape frames without data), and ``time_weight`` on temporal
edges between two slices with data (the method's ``time_smoothness``, 0 by default: a part
that moves by more than its thickness per frame would be pulled off its own data).

The result is a :class:`FlowField` (a :class:`fourd.geometry.field.Field4D`), contoured per
time slice with marching cubes.
"""

from __future__ import annotations

import logging

import numba
import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.spatial import cKDTree

from fourd.geometry.marching import compact, marching_cubes
from fourd.geometry.meshes import component_volumes, remove_small_components
from fourd.geometry.normals import vertex_normals
from fourd.methods.flow.grid import SpaceTimeGrid
from fourd.methods.flow.krylov import jacobi_cg

log = logging.getLogger("fourd.methods.flow.post")


class FlowField:
    """The 4D implicit function of the flow method: negative inside, zero on the surface.

    Values on a regular fine grid per time slice (node ``i, j, k`` at
    ``origin + spacing * (i, j, k)``), trilinear in space and linear in time; outside the grid
    the field is positive (outside).

    Attributes
    ----------
    values : float32 [S, nx, ny, nz]
    origin : [3]; spacing : float; times : [S]
    """

    def __init__(self, values: np.ndarray, origin: np.ndarray, spacing: float, times: np.ndarray):
        self.values = np.ascontiguousarray(values, dtype=np.float32)
        self.origin = np.asarray(origin, float)
        self.spacing = float(spacing)
        self.times = np.asarray(times, float)

    def bounds(self) -> np.ndarray:
        """``[2, 3]`` spatial extent of the grid."""
        return np.stack(
            [self.origin, self.origin + self.spacing * (np.array(self.values.shape[1:]) - 1)]
        )

    def nodes(self) -> np.ndarray:
        """The grid's nodes [nx * ny * nz, 3] in C order (a slice's values ``.ravel()``)."""
        return self.origin + self.spacing * np.indices(self.values.shape[1:]).reshape(3, -1).T

    def _time_weights(self, times: np.ndarray):
        s = np.interp(times, self.times, np.arange(len(self.times)))
        s0 = np.clip(np.floor(s).astype(np.int64), 0, max(len(self.times) - 2, 0))
        s1 = np.minimum(s0 + 1, len(self.times) - 1)
        return s0, s1, s - s0

    def _sample(self, points: np.ndarray, slice_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        shape = np.array(self.values.shape[1:])
        g = (points - self.origin) / self.spacing
        base = np.clip(np.floor(g).astype(np.int64), 0, shape - 2)
        frac = g - base
        outside = np.any((g < 0) | (g > shape - 1), axis=1)
        frac = np.clip(frac, 0.0, 1.0)
        value = np.zeros(len(points))
        grad = np.zeros((len(points), 3))
        for i in (0, 1):
            for j in (0, 1):
                for k in (0, 1):
                    c = self.values[
                        slice_index, base[:, 0] + i, base[:, 1] + j, base[:, 2] + k
                    ].astype(float)
                    fx = frac[:, 0] if i else 1 - frac[:, 0]
                    fy = frac[:, 1] if j else 1 - frac[:, 1]
                    fz = frac[:, 2] if k else 1 - frac[:, 2]
                    value += c * fx * fy * fz
                    grad[:, 0] += c * (1 if i else -1) * fy * fz
                    grad[:, 1] += c * fx * (1 if j else -1) * fz
                    grad[:, 2] += c * fx * fy * (1 if k else -1)
        if outside.any():
            excess = np.linalg.norm(np.maximum(0, np.maximum(-g, g - (shape - 1))), axis=1)
            value[outside] = np.maximum(value[outside], 0) + excess[outside] * self.spacing
        return value, grad / self.spacing

    def value(self, points: np.ndarray, times) -> np.ndarray:
        """``f`` at ``points`` [M, 3] and ``times`` (scalar or [M]); [M]."""
        return self.value_and_gradient(points, times)[0]

    def gradient(self, points: np.ndarray, times) -> np.ndarray:
        """``(df/dx, df/dy, df/dz, df/dt)`` at ``points`` [M, 3], ``times``; [M, 4]."""
        return self.value_and_gradient(points, times)[1]

    def value_and_gradient(self, points: np.ndarray, times) -> tuple[np.ndarray, np.ndarray]:
        """``f`` [M] and its gradient [M, 4] from one sampling of the two nearest slices."""
        points = np.asarray(points, float).reshape(-1, 3)
        times = np.broadcast_to(np.asarray(times, float), (len(points),))
        s0, s1, w = self._time_weights(times)
        v0, g0 = self._sample(points, s0)
        v1, g1 = self._sample(points, s1)
        dt = (
            np.maximum(self.times[s1] - self.times[s0], 1e-12)
            if len(self.times) > 1
            else np.ones(len(points))
        )
        out = np.empty((len(points), 4))
        out[:, :3] = (1 - w)[:, None] * g0 + w[:, None] * g1
        out[:, 3] = np.where(s1 > s0, (v1 - v0) / dt, 0.0)
        return (1 - w) * v0 + w * v1, out


def flow_signed_distance(x: np.ndarray, h: float) -> np.ndarray:
    """Signed distance (input units, negative inside) of the set ``x > 0.5`` per slice,
    ``[S, X, Y, Z]``, with the zero level on the faces between inside and outside cells.
    (Data cells are set to one, so this level lies up to half a cell outside the data; a
    shift to the boundary cells' centres measured worse volumes, see the report.)"""
    out = np.empty(x.shape)
    for s in range(len(x)):
        inside = x[s] > 0.5
        if not inside.any():
            out[s] = ndimage.distance_transform_edt(np.ones_like(inside)) * 0 + 1e3 * h
            continue
        d_out = ndimage.distance_transform_edt(~inside)
        d_in = ndimage.distance_transform_edt(inside)
        out[s] = np.where(inside, -(d_in - 0.5), d_out - 0.5) * h
    return out


def _linear_weights(n: int, refine: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear interpolation along one axis of ``n`` cells refined ``refine`` times, fine node
    ``k`` at coarse coordinate ``(k + 0.5) / refine - 0.5``, clamped at the ends (as
    ``ndimage.map_coordinates`` with ``order=1, mode="nearest"``): the lower and upper coarse
    indices [refine n] and the upper one's weight [refine n]."""
    u = (np.arange(refine * n) + 0.5) / refine - 0.5
    lower = np.floor(u)
    weight = u - lower
    lower = lower.astype(np.int64)
    return np.clip(lower, 0, n - 1), np.clip(lower + 1, 0, n - 1), weight


@numba.njit(cache=True, parallel=True)
def _upsample(coarse, x0, x1, wx, y0, y1, wy, z0, z1, wz, out):
    """Trilinear values of ``coarse`` [X, Y, Z] at the fine nodes of ``out`` [rX, rY, rZ]
    (float32), per axis the :func:`_linear_weights`: what ``ndimage.map_coordinates`` with
    ``order=1`` computes (within float rounding), on all cores (squash-ball at resolution
    64, 20 slices of 128^3 nodes: 1.5 s in scipy's, on one core)."""
    for i in numba.prange(out.shape[0]):
        a0, a1, fa = x0[i], x1[i], wx[i]
        for j in range(out.shape[1]):
            b0, b1, fb = y0[j], y1[j], wy[j]
            for k in range(out.shape[2]):
                c0, c1, fc = z0[k], z1[k], wz[k]
                low = (1 - fb) * ((1 - fc) * coarse[a0, b0, c0] + fc * coarse[a0, b0, c1]) + fb * (
                    (1 - fc) * coarse[a0, b1, c0] + fc * coarse[a0, b1, c1]
                )
                high = (1 - fb) * ((1 - fc) * coarse[a1, b0, c0] + fc * coarse[a1, b0, c1]) + fb * (
                    (1 - fc) * coarse[a1, b1, c0] + fc * coarse[a1, b1, c1]
                )
                out[i, j, k] = (1 - fa) * low + fa * high


@numba.njit(cache=True)
def _stencil_csr(columns, diagonal, nodes, per_slice, smoothness, time_weights):
    """CSR arrays ``(data, indices, indptr)`` of :func:`implicit_function`'s Laplace system
    from its slot table ``columns`` [m, 9] (-1: no entry; slot 4 the diagonal ``diagonal``
    [m]; slots 0 and 8 the temporal edges to the previous and next slice, weighted
    ``-smoothness * time_weights[edge]``; the others ``-smoothness``), ``nodes`` [m] being the
    rows' node indices with ``per_slice`` nodes per slice."""
    m, width = columns.shape
    indptr = np.zeros(m + 1, dtype=np.int64)
    for i in range(m):
        count = 0
        for j in range(width):
            if columns[i, j] >= 0:
                count += 1
        indptr[i + 1] = indptr[i] + count
    indices = np.empty(indptr[m], dtype=columns.dtype)
    data = np.empty(indptr[m])
    for i in range(m):
        at = indptr[i]
        here = nodes[i] // per_slice
        for j in range(width):
            column = columns[i, j]
            if column < 0:
                continue
            indices[at] = column
            if j == 4:
                data[at] = diagonal[i]
            elif j == 0:
                data[at] = -(smoothness * time_weights[here - 1])
            elif j == width - 1:
                data[at] = -(smoothness * time_weights[here])
            else:
                data[at] = -smoothness
            at += 1
    return data, indices, indptr


def implicit_function(
    grid: SpaceTimeGrid,
    x: np.ndarray,
    points: list[np.ndarray | None],
    normals: list[np.ndarray | None],
    *,
    refine: int = 2,
    band: float = 2.0,
    smoothness: float = 0.5,
    time_weight: float = 1.0,
    neighbours: int = 4,
    rtol: float = 1e-5,
) -> FlowField:
    """Build the 4D implicit function from the flow solution ``x`` [S, X, Y, Z] and the data
    (per slice points [P, 3] and oriented normals, or None); see the module docstring for
    ``time_weight``."""
    h = grid.h
    hf = h / refine
    S = grid.slices
    coarse = flow_signed_distance(x, h)
    fine_shape = tuple(refine * n for n in grid.shape)
    origin = grid.origin + 0.5 * hf
    base = np.empty((S, *fine_shape), dtype=np.float32)
    axes = [_linear_weights(n, refine) for n in grid.shape]
    for s in range(S):
        _upsample(coarse[s], *axes[0], *axes[1], *axes[2], base[s])
    del coarse
    n_nodes = base.size
    unknown = np.flatnonzero((np.abs(base) < band * h).ravel())
    m = len(unknown)
    if m == 0:
        return FlowField(base, origin, hf, grid.times)
    # 32-bit node and column indices where they fit: squash-ball at resolution 64 has 44M fine
    # nodes and millions of band nodes, and this function held most of the method's memory
    index = np.int32 if n_nodes < np.iinfo(np.int32).max else np.int64
    unknown = unknown.astype(index)
    col = np.full(n_nodes, -1, dtype=index)
    col[unknown] = np.arange(m, dtype=index)
    omega = np.zeros(m)
    target = np.zeros(m)
    # flow targets, weighted by depth
    flow_values = base.ravel()[unknown].astype(float)
    depth_weight = np.clip((np.abs(flow_values) - 0.5 * h) / h, 0.0, 1.0)
    omega += 0.5 * depth_weight
    target += 0.5 * depth_weight * flow_values
    # data targets
    per_slice = int(np.prod(fine_shape))
    slice_of = unknown // per_slice
    positions = origin + hf * np.stack(np.unravel_index(unknown % per_slice, fine_shape), axis=1)
    for s in range(S):
        if points[s] is None or len(points[s]) == 0:
            continue
        mine = np.flatnonzero(slice_of == s)
        if not len(mine):
            continue
        k = min(neighbours, len(points[s]))
        tree = cKDTree(points[s])
        # the nearest point first, bounded (most band nodes are far from data), then the k
        # nearest only for the nodes near data
        nearest, _ = tree.query(positions[mine], distance_upper_bound=1.5 * h, workers=-1)
        near = nearest < 1.5 * hf
        sel = mine[near]
        d, idx = tree.query(positions[sel], k=k, workers=-1)
        if k == 1:
            d, idx = d[:, None], idx[:, None]
        plane = np.einsum(
            "nkj,nkj->nk", positions[sel][:, None, :] - points[s][idx], normals[s][idx]
        )
        wk = np.exp(-((d / (1.5 * hf)) ** 2))
        signed = (wk * plane).sum(axis=1) / np.maximum(wk.sum(axis=1), 1e-12)
        # data dominates where it is present: replace the flow target there
        omega[sel] = 1.0
        target[sel] = signed
        # nodes close to data but not within reach: no flow target (unknown region)
        around = (nearest >= 1.5 * hf) & (nearest < 1.5 * h)
        omega[mine[around]] = 0.0
        target[mine[around]] = 0.0
    del positions, slice_of
    # Laplace term on 4D edges: one CSR row per band node, its entries in column order
    # (the 4D neighbours at -stride, the node itself, the neighbours at +stride; the column
    # map is monotone in the node index)
    rhs = omega * target
    strides = np.array([per_slice, fine_shape[1] * fine_shape[2], fine_shape[2], 1], dtype=np.int64)
    shape4 = (S, *fine_shape)
    base_flat = base.ravel()
    coord4 = np.stack(np.unravel_index(unknown, shape4), axis=1).astype(index)
    order = [(axis, -1) for axis in range(4)] + [(axis, 1) for axis in reversed(range(4))]
    columns = np.full((m, 9), -1, dtype=index)
    diagonal = omega + 1e-8
    # temporal edge (s, s + 1): time_weight between two slices with data, 1 where one has none
    has_data = np.array([p is not None and len(p) > 0 for p in points])
    edge_time_weight = np.where(has_data[:-1] & has_data[1:], time_weight, 1.0)
    for slot, (axis, direction) in enumerate(order):
        ok = (coord4[:, axis] + direction >= 0) & (coord4[:, axis] + direction < shape4[axis])
        rows = np.flatnonzero(ok)
        if axis == 0:
            edge = coord4[rows, 0] + min(direction, 0)
            weight = smoothness * edge_time_weight[edge]
        else:
            weight = np.full(len(rows), smoothness)
        b = unknown[rows] + direction * strides[axis]
        cb = col[b]
        inner = cb >= 0
        diagonal[rows] += weight
        slot_index = slot if slot < 4 else slot + 1
        columns[rows[inner], slot_index] = cb[inner]
        rhs[rows[~inner]] += weight[~inner] * base_flat[b[~inner]]
    del coord4, col
    columns[:, 4] = np.arange(m)
    # the entries follow from the slots (no [m, 9] table of them: on squash-ball at
    # resolution 64, 6.7M band nodes, writing one took 1.5 s and 480 MB)
    matrix = sp.csr_matrix(
        _stencil_csr(columns, diagonal, unknown, per_slice, smoothness, edge_time_weight),
        shape=(m, m),
    )
    del columns
    # diagonally dominant wherever a node has a target: Jacobi-preconditioned CG needs a few
    # dozen steps (crane, 1.1M band nodes: 0.9 s against 13 s for smoothed-aggregation AMG,
    # 11 s of it the set-up)
    solution, info, _ = jacobi_cg(matrix, rhs, flow_values, rtol=rtol, maxiter=2000)
    if info != 0:
        log.warning("postprocessing Laplace solve did not reach %.0e", rtol)
    values = base.ravel()
    values[unknown] = solution
    log.debug("postprocessing: %d band nodes of %d", m, n_nodes)
    return FlowField(values.reshape(shape4), origin, hf, grid.times)


def drop_cavities(vertices, faces) -> tuple[np.ndarray, np.ndarray, int]:
    """The mesh without the inner surfaces of cavities, and how many there were.

    Marching cubes orients faces outward, so a pocket of outside enclosed by the solid has
    a negative signed volume. No scanner outside the object sees one; in the flow's output
    a cavity means the motion outran its speed bound (see ``time_substeps``).
    """
    if len(faces) == 0:
        return vertices, faces, 0
    face_label, volume = component_volumes(vertices, faces)
    cavity = volume < 0
    if not cavity.any() or volume.max() <= 0:
        return vertices, faces, 0
    return (*compact(vertices, faces[~cavity[face_label]]), int(cavity.sum()))


def extract_mesh(
    field: FlowField,
    slice_index: int,
    *,
    min_component: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed mesh of the zero set of one time slice (marching cubes on the padded slice),
    without the components smaller than ``min_component`` of the largest (cavities are kept:
    see :func:`drop_cavities`)."""
    values = field.values[slice_index].astype(np.float64)
    values = np.pad(
        values, 1, mode="constant", constant_values=max(float(values.max()), field.spacing)
    )
    values[values == 0.0] = 1e-9 * field.spacing
    vertices, faces = marching_cubes(
        values, origin=field.origin - field.spacing, spacing=field.spacing
    )
    return remove_small_components(vertices, faces, min_fraction=min_component, measure="volume")


def redistanced(
    field: FlowField, slice_index, meshes, *, near: float = 2.0, workers: int = -1
) -> FlowField:
    """A signed distance to the frames' meshes on ``field``'s grid: the field to slide a
    template along (:func:`~fourd.methods.flow.surface_distance`).

    The postprocessing's function is distance-like only near its data: elsewhere in the band
    its spatial gradient falls to a tenth of one, and Newton projections onto it overshoot
    or stall (a template slid on it without a data term ended up 9-13% of the radius off a
    squashed ellipsoid; 0.2-0.7% on this field). Per frame: within ``near`` grid spacings of
    the mesh, the distance to the tangent plane of the nearest mesh vertex (its area-weighted
    normal); farther, the distance to that vertex, with the sign of ``field`` after inside or
    outside pockets that do not reach the mesh (the small pieces :func:`extract_mesh` dropped)
    are flipped.

    Parameters
    ----------
    field : FlowField
    slice_index : int array [T], the slice of each frame.
    meshes : T (vertices [N, 3], faces [F, 3]) pairs, closed; a frame without faces keeps the
        field's values.

    Returns
    -------
    FlowField with T slices at ``field.times[slice_index]``.
    """
    slice_index = np.asarray(slice_index, dtype=np.int64)
    shape = field.values.shape[1:]
    nodes = field.nodes()
    out = np.empty((len(slice_index), *shape), dtype=np.float32)
    for i, (s, (vertices, faces)) in enumerate(zip(slice_index, meshes, strict=True)):
        if len(faces) == 0:
            out[i] = field.values[s]
            continue
        distance, plane = _nearest_vertex_distances(vertices, faces, nodes, workers)
        band = (distance < near * field.spacing).reshape(shape)
        inside = field.values[s] < 0
        for phase in (inside, ~inside):
            labels, _ = ndimage.label(phase)
            reaching = np.unique(labels[band & phase])
            stray = phase & ~np.isin(labels, reaching)
            inside = np.where(stray, ~inside, inside)
        values = np.where(inside.ravel(), -distance, distance)
        out[i] = np.where(band.ravel(), plane, values).reshape(shape)
    return FlowField(out, field.origin, field.spacing, field.times[slice_index])


def mesh_distance(
    vertices: np.ndarray,
    faces: np.ndarray,
    time: float,
    spacing: float,
    *,
    near: float = 2.0,
    padding: int = 4,
    workers: int = -1,
) -> FlowField:
    """A signed distance to one closed mesh, on a grid of its own: :func:`redistanced` for a
    frame whose flow solve is no longer in memory (a streamed run keeps only its meshes).

    Within ``near`` grid spacings of the mesh, the distance to the tangent plane of the
    nearest mesh vertex (its area-weighted normal); farther, the distance to that vertex.
    The sign there comes from the mesh alone: the band of nodes near it separates the grid
    into pieces (the mesh's vertices lie less than ``spacing`` apart, as a marching-cubes
    mesh of a grid of that spacing does); a piece that reaches the grid's border is outside,
    another is inside when most of its nodes lie behind their nearest vertex's tangent plane.

    Parameters
    ----------
    vertices : [N, 3]; faces : [F, 3], closed and outward oriented.
    time : float, the one slice's time.
    spacing : float, the grid's spacing (input units; the flow grid's, or finer).
    near : float, the band's half-width in grid spacings.
    padding : int, grid nodes beyond the mesh's box on every side (more than ``near``).

    Returns
    -------
    FlowField with one slice at ``time``, negative inside.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if len(faces) == 0:
        raise ValueError("mesh_distance needs a mesh with faces")
    origin = vertices.min(axis=0) - padding * spacing
    shape = tuple(np.ceil((vertices.max(axis=0) - origin) / spacing).astype(int) + padding + 1)
    nodes = origin + spacing * np.indices(shape).reshape(3, -1).T
    distance, plane = _nearest_vertex_distances(vertices, faces, nodes, workers)
    band = distance < near * spacing
    labels, count = ndimage.label(~band.reshape(shape))
    border = np.zeros(shape, dtype=bool)
    border[[0, -1]], border[:, [0, -1]], border[:, :, [0, -1]] = True, True, True
    outside = np.zeros(count + 1, dtype=bool)
    outside[np.unique(labels[border])] = True
    behind = np.bincount(labels.ravel(), weights=np.sign(plane), minlength=count + 1)
    inside = ~outside & (behind < 0)
    inside[0] = False  # label 0: the band, signed by its planes
    values = np.where(band, plane, np.where(inside[labels.ravel()], -distance, distance))
    return FlowField(
        values.reshape(1, *shape).astype(np.float32), origin, spacing, np.array([float(time)])
    )


def _nearest_vertex_distances(vertices, faces, nodes, workers) -> tuple[np.ndarray, np.ndarray]:
    """Per node [M, 3], the distance to the mesh's nearest vertex and the signed distance to
    that vertex's tangent plane (its area-weighted normal); ([M], [M])."""
    normals = vertex_normals(vertices, faces)
    distance, nearest = cKDTree(vertices).query(nodes, workers=workers)
    return distance, np.einsum("ij,ij->i", nodes - vertices[nearest], normals[nearest])
