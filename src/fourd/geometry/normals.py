"""Point normals: PCA over neighbours, oriented by the sensors or by consistent propagation;
and the area-weighted vertex normals of triangle meshes.

References
----------
Hoppe, DeRose, Duchamp, McDonald, Stuetzle: Surface reconstruction from unorganized points,
SIGGRAPH 1992 (PCA normals, orientation by propagation over a Riemannian graph).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fourd.geometry.eigen3 import DEGENERATE, smallest_eigenpair
from fourd.geometry.heap import heap_pop, sift_up
from fourd.geometry.neighbors import knn


class Normals(NamedTuple):
    """Estimated normals.

    normals : float64 [P, 3], unit.
    flatness : float64 [P], 1 - 3*lambda_min/(sum lambda) in [0, 1]; near 1 on flat regions,
        near 0 on noise or sharp features (a confidence for the normal's direction).
    """

    normals: np.ndarray
    flatness: np.ndarray


@numba.njit(cache=True)
def _smallest_eigenpair(C, out):
    """Smallest eigenvalue of the symmetric 3x3 ``C`` (returned) and its unit eigenvector
    (written to ``out``): :func:`fourd.geometry.eigen3.smallest_eigenpair`, ``(0, 0, 1)`` for
    an isotropic ``C``, LAPACK when the closed form is degenerate."""
    value, x, y, z, status = smallest_eigenpair(
        C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2], 1e-24
    )
    if status == DEGENERATE:
        values, vectors = np.linalg.eigh(C)
        out[:] = vectors[:, 0]
        return values[0]
    out[0], out[1], out[2] = x, y, z
    return value


@numba.njit(cache=True, parallel=True, nogil=True)
def _pca_kernel(points, indices, normals, flatness):
    for p in numba.prange(len(points)):
        k = indices.shape[1]
        mean = points[p].copy()
        for a in range(k):
            mean += points[indices[p, a]]
        mean /= k + 1
        C = np.zeros((3, 3))
        for a in range(-1, k):
            q = points[p] if a < 0 else points[indices[p, a]]
            d0 = q[0] - mean[0]
            d1 = q[1] - mean[1]
            d2 = q[2] - mean[2]
            C[0, 0] += d0 * d0
            C[0, 1] += d0 * d1
            C[0, 2] += d0 * d2
            C[1, 1] += d1 * d1
            C[1, 2] += d1 * d2
            C[2, 2] += d2 * d2
        C[1, 0] = C[0, 1]
        C[2, 0] = C[0, 2]
        C[2, 1] = C[1, 2]
        smallest = _smallest_eigenpair(C, normals[p])
        total = max(C[0, 0] + C[1, 1] + C[2, 2], 1e-300)
        flatness[p] = min(max(1.0 - 3.0 * smallest / total, 0.0), 1.0)


def pca_normals(points: np.ndarray, k: int = 16, *, indices: np.ndarray | None = None) -> Normals:
    """Unoriented PCA normals from the ``k`` nearest neighbours (the point itself included).

    Parameters
    ----------
    points : ndarray [P, 3]
    k : int
    indices : ndarray int [P, k], optional
        Precomputed neighbour indices (self excluded).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    if indices is None:
        _, indices = knn(points, k)
    normals = np.empty_like(points)
    flatness = np.empty(len(points))
    _pca_kernel(points, np.ascontiguousarray(indices, dtype=np.int64), normals, flatness)
    return Normals(normals, flatness)


@numba.njit(cache=True, nogil=True)
def _reverse_adjacency(indices):
    """CSR lists of the points that have each point among their neighbours."""
    count, k = indices.shape
    pointer = np.zeros(count + 1, dtype=np.int64)
    for p in range(count):
        for a in range(k):
            pointer[indices[p, a] + 1] += 1
    for p in range(count):
        pointer[p + 1] += pointer[p]
    fill = pointer[:-1].copy()
    members = np.empty(count * k, dtype=np.int64)
    for p in range(count):
        for a in range(k):
            q = indices[p, a]
            members[fill[q]] = p
            fill[q] += 1
    return pointer, members


@numba.njit(cache=True, nogil=True)
def _propagate_over_spanning_tree(normals, indices, pointer, members, signs, labels):
    """Prim's minimum spanning tree of the symmetric neighbour graph (weights
    ``1 - |n_i . n_j|``; a heap of the unreached points keyed by their lightest edge to the
    tree), grown from every not yet reached point in turn; each point takes the sign that
    makes its normal agree with its tree parent's. ``labels`` gets the part index."""
    count, k = indices.shape
    keys = np.full(count, np.inf)
    parent = np.empty(count, dtype=np.int64)
    heap = np.empty(count, dtype=np.int64)
    where = np.full(count, -1, dtype=np.int64)
    reached = np.zeros(count, dtype=np.bool_)
    part = 0
    for seed in range(count):
        if reached[seed]:
            continue
        keys[seed] = 0.0
        parent[seed] = seed
        heap[0] = seed
        where[seed] = 0
        size = 1
        while size > 0:
            node, size = heap_pop(keys, heap, where, size)
            reached[node] = True
            labels[node] = part
            up = parent[node]
            if node == up:
                signs[node] = 1.0
            else:
                d = (
                    normals[node, 0] * normals[up, 0]
                    + normals[node, 1] * normals[up, 1]
                    + normals[node, 2] * normals[up, 2]
                )
                signs[node] = signs[up] if d >= 0 else -signs[up]
            for a in range(k + pointer[node + 1] - pointer[node]):
                j = indices[node, a] if a < k else members[pointer[node] + a - k]
                if reached[j]:
                    continue
                d = (
                    normals[node, 0] * normals[j, 0]
                    + normals[node, 1] * normals[j, 1]
                    + normals[node, 2] * normals[j, 2]
                )
                weight = 1.0 - abs(d)
                if weight < keys[j]:
                    keys[j] = weight
                    parent[j] = node
                    if where[j] < 0:
                        heap[size] = j
                        where[j] = size
                        size += 1
                    sift_up(keys, heap, where, where[j])
        part += 1
    return part


def orient_by_propagation(points: np.ndarray, normals: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Make neighbouring normals agree by propagation over a minimum spanning tree of the
    neighbour graph (weights 1 - |n_i . n_j|), then point each connected part outwards: its
    normal at the point furthest from the part's centroid faces away from the centroid.

    Returns the re-oriented normals, [P, 3].
    """
    return _propagate(points, normals, indices)[0]


def _propagate(points, normals, indices):
    """:func:`orient_by_propagation`, also returning the connected parts of the symmetric
    neighbour graph: ``(normals [P, 3], labels [P], part count)``."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    indices = np.ascontiguousarray(indices, dtype=np.int64)
    count = len(points)
    if count == 0:
        return normals.copy(), np.zeros(0, dtype=np.int64), 0
    pointer, members = _reverse_adjacency(indices)
    signs = np.ones(count)
    labels = np.empty(count, dtype=np.int64)
    parts = _propagate_over_spanning_tree(normals, indices, pointer, members, signs, labels)
    oriented = normals * signs[:, None]
    sizes = np.bincount(labels, minlength=parts)
    centroids = np.stack(
        [np.bincount(labels, weights=points[:, c], minlength=parts) for c in range(3)], axis=1
    ) / sizes[:, None]
    offsets = points - centroids[labels]
    reach = np.einsum("ij,ij->i", offsets, offsets)
    # the furthest point of every part: last of each part when sorted by (part, reach)
    order = np.lexsort((reach, labels))
    roots = order[np.cumsum(sizes) - 1]
    outward = np.einsum("ij,ij->i", oriented[roots], offsets[roots]) >= 0
    return np.where(outward[labels][:, None], oriented, -oriented), labels, parts


def orient_to_sensors(
    points: np.ndarray,
    normals: np.ndarray,
    sensors: np.ndarray,
    indices: np.ndarray,
    *,
    rounds: int = 8,
) -> np.ndarray:
    """Orient normals towards the scanner that most plausibly saw each point, then let
    neighbours vote for a few rounds so that isolated wrong signs are corrected.

    The seen-from sensor is taken to be the nearest one (surfaces face the camera closest to
    them in a ring set-up); its vote is weighted by how squarely the point faces it.

    Parameters
    ----------
    sensors : ndarray [K, 3]
    indices : ndarray int [P, k] neighbour indices (self excluded).
    """
    to_sensor = sensors[None, :, :] - points[:, None, :]
    distance = np.linalg.norm(to_sensor, axis=2)
    nearest = np.argmin(distance, axis=1)
    direction = to_sensor[np.arange(len(points)), nearest] / distance[np.arange(len(points)), nearest, None]
    cosine = np.einsum("ij,ij->i", normals, direction)
    signs = np.where(cosine >= 0, 1.0, -1.0)
    prior = np.abs(cosine)
    agreement = np.einsum("ij,ikj->ik", normals, normals[indices])
    for _ in range(rounds):
        vote = prior * signs + 0.5 * np.einsum("ik,ik->i", agreement, signs[indices]) / indices.shape[1] * 4.0
        new = np.where(vote >= 0, 1.0, -1.0)
        if np.array_equal(new, signs):
            break
        signs = new
    return normals * signs[:, None]


def orient_parts_to_sensors(
    points: np.ndarray,
    normals: np.ndarray,
    sensors: np.ndarray,
    indices: np.ndarray,
    *,
    labels: np.ndarray | None = None,
) -> np.ndarray:
    """Flip whole connected parts of the neighbour graph so that, summed over the part, the
    normals face the sensors better than their flips do.

    Used after :func:`orient_by_propagation`: neighbours already agree, and the sensors
    decide one sign per part. On the crane scans this orients 99.6-99.8% of points like the
    truth, against 70-82% for orienting every point towards its nearest sensor.

    ``labels`` [P] (optional): the connected parts when already known (the propagation finds
    them); otherwise they are computed from ``indices``.
    """
    count = len(points)
    if labels is None:
        graph = sp.csr_matrix(
            (
                np.ones(indices.size),
                (np.repeat(np.arange(count), indices.shape[1]), indices.ravel()),
            ),
            shape=(count, count),
        )
        parts, labels = connected_components(graph, directed=False)
    else:
        parts = int(labels.max()) + 1 if count else 0
    to_sensor = np.asarray(sensors, dtype=np.float64)[None, :, :] - points[:, None, :]
    distance = np.linalg.norm(to_sensor, axis=2)
    nearest = np.argmin(distance, axis=1)
    rows = np.arange(count)
    # The nearest sensor is taken as the one that saw the point; summed over a part this vote
    # is reliable even though single points often face away from their nearest sensor.
    score = np.einsum("pj,pj->p", normals, to_sensor[rows, nearest]) / distance[rows, nearest]
    votes = np.bincount(labels, weights=score, minlength=parts)
    return np.where((votes[labels] < 0)[:, None], -normals, normals)


def estimate_normals(
    points: np.ndarray,
    *,
    k: int = 16,
    sensors: np.ndarray | None = None,
    mode: str = "auto",
    indices: np.ndarray | None = None,
) -> Normals:
    """Oriented unit normals of a scanned point set.

    PCA over the ``k`` nearest neighbours (``indices`` [P, k]: neighbour lists already at
    hand, self excluded), then orientation by ``mode``:
    ``"auto"`` (default): consistent propagation, then one sign per connected part voted by
    the sensors when given (see :func:`orient_parts_to_sensors`); ``"sensors"``: every point towards its nearest sensor with
    a neighbour vote; ``"propagation"``: propagation with an outward check only.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(2000, 3)); p /= np.linalg.norm(p, axis=1, keepdims=True)
    >>> n = estimate_normals(p).normals
    >>> bool(np.mean(np.einsum('ij,ij->i', n, p)) > 0.95)
    True
    """
    if mode not in ("auto", "sensors", "propagation"):
        raise ValueError(f"mode must be auto, sensors or propagation, got {mode!r}")
    points = np.asarray(points, dtype=np.float64)
    if indices is None:
        _, indices = knn(points, k)
    elif len(indices) != len(points):
        raise ValueError(f"indices must have one row per point ({len(points)}), got {len(indices)}")
    unoriented = pca_normals(points, k, indices=indices)
    has_sensors = sensors is not None and len(sensors) > 0
    if mode == "sensors" and has_sensors:
        oriented = orient_to_sensors(points, unoriented.normals, np.asarray(sensors, float), indices)
    else:
        oriented, labels, _ = _propagate(points, unoriented.normals, indices)
        if mode == "auto" and has_sensors:
            oriented = orient_parts_to_sensors(
                points, oriented, np.asarray(sensors, float), indices, labels=labels
            )
    return Normals(oriented, unoriented.flatness)


def nearest_normals(points: np.ndarray, reference_points: np.ndarray, reference_normals: np.ndarray) -> np.ndarray:
    """Normals of the nearest reference point for each of ``points`` ([P, 3])."""
    _, index = cKDTree(reference_points).query(points, workers=-1)
    return reference_normals[index]


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals of a triangle mesh.

    Parameters
    ----------
    vertices : array [N, 3] or [T, N, 3]
    faces : int array [F, 3]

    Returns
    -------
    ndarray, float64, same shape as ``vertices``
        Unit normals: the sum of the (unnormalised, hence area-weighted) normals of the faces
        around each vertex. Vertices without faces, or whose faces cancel, get ``(0, 0, 1)``.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(np.asarray(faces, dtype=np.int64).reshape(-1, 3))
    frames = vertices[None] if vertices.ndim == 2 else vertices
    if len(faces) and (faces.min() < 0 or faces.max() >= frames.shape[1]):
        raise ValueError(f"faces index vertices outside 0..{frames.shape[1] - 1}")
    out = np.zeros_like(frames)
    for t in range(len(frames)):
        if len(faces):
            _accumulate_face_normals(np.ascontiguousarray(frames[t]), faces, out[t])
        _normalize_rows(out[t])
    return out[0] if vertices.ndim == 2 else out


@numba.njit(cache=True)
def _normalize_rows(normals):
    """Scale each row of ``normals`` [N, 3] to unit length in place: ``(0, 0, 1)`` where it
    is zero, ``(0, 0, 0)`` where its length is NaN (numpy's divide-where, compiled)."""
    for i in range(len(normals)):
        length = np.sqrt(normals[i, 0] * normals[i, 0] + normals[i, 1] * normals[i, 1]
                         + normals[i, 2] * normals[i, 2])
        if np.isnan(length):
            normals[i, 0] = 0.0
            normals[i, 1] = 0.0
            normals[i, 2] = 0.0
        elif length > 1e-300:
            for a in range(3):
                normals[i, a] /= length
        else:
            normals[i, 0] = 0.0
            normals[i, 1] = 0.0
            normals[i, 2] = 1.0


@numba.njit(cache=True)
def _accumulate_face_normals(vertices, faces, out):
    """Add each face's unnormalised normal (twice its area) to ``out`` [N, 3] at its three
    vertices, faces in order."""
    for f in range(len(faces)):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        u0 = vertices[b, 0] - vertices[a, 0]
        u1 = vertices[b, 1] - vertices[a, 1]
        u2 = vertices[b, 2] - vertices[a, 2]
        v0 = vertices[c, 0] - vertices[a, 0]
        v1 = vertices[c, 1] - vertices[a, 1]
        v2 = vertices[c, 2] - vertices[a, 2]
        n0 = u1 * v2 - u2 * v1
        n1 = u2 * v0 - u0 * v2
        n2 = u0 * v1 - u1 * v0
        for corner in range(3):
            v = faces[f, corner]
            out[v, 0] += n0
            out[v, 1] += n1
            out[v, 2] += n2
