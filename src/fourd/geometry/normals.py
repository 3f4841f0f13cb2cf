"""Point normals: PCA over neighbours, oriented by the sensors or by consistent propagation.

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
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

from fourd.geometry.neighbors import knn


class Normals(NamedTuple):
    """Estimated normals.

    normals : float64 [P, 3], unit.
    flatness : float64 [P], 1 - 3*lambda_min/(sum lambda) in [0, 1]; near 1 on flat regions,
        near 0 on noise or sharp features (a confidence for the normal's direction).
    """

    normals: np.ndarray
    flatness: np.ndarray


def pca_normals(points: np.ndarray, k: int = 16, *, indices: np.ndarray | None = None) -> Normals:
    """Unoriented PCA normals from the ``k`` nearest neighbours (the point itself included).

    Parameters
    ----------
    points : ndarray [P, 3]
    k : int
    indices : ndarray int [P, k], optional
        Precomputed neighbour indices (self excluded).
    """
    points = np.asarray(points, dtype=np.float64)
    if indices is None:
        _, indices = knn(points, k)
    neighbourhood = np.concatenate([points[:, None, :], points[indices]], axis=1)
    centred = neighbourhood - neighbourhood.mean(axis=1, keepdims=True)
    covariance = np.einsum("pki,pkj->pij", centred, centred)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    normals = eigenvectors[:, :, 0]
    total = np.maximum(eigenvalues.sum(axis=1), 1e-300)
    flatness = np.clip(1.0 - 3.0 * eigenvalues[:, 0] / total, 0.0, 1.0)
    return Normals(normals / np.linalg.norm(normals, axis=1, keepdims=True), flatness)


@numba.njit(cache=True)
def _propagate_signs(order, predecessors, edge_sign):
    signs = np.ones(len(predecessors), dtype=np.float64)
    for node in order:
        parent = predecessors[node]
        if parent >= 0:
            signs[node] = signs[parent] * edge_sign[node]
    return signs


def _neighbour_graph(normals: np.ndarray, indices: np.ndarray) -> sp.csr_matrix:
    count, k = indices.shape
    rows = np.repeat(np.arange(count), k)
    cols = indices.ravel()
    weight = 1.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols])) + 1e-6
    graph = sp.csr_matrix((weight, (rows, cols)), shape=(count, count))
    return graph.maximum(graph.T)


def orient_by_propagation(points: np.ndarray, normals: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Make neighbouring normals agree by propagation over a minimum spanning tree of the
    neighbour graph (weights 1 - |n_i . n_j|), then point each connected part outwards: its
    normal at the point furthest from the part's centroid faces away from the centroid.

    Returns the re-oriented normals, [P, 3].
    """
    graph = _neighbour_graph(normals, indices)
    tree = minimum_spanning_tree(graph)
    tree = tree + tree.T
    parts, labels = connected_components(tree, directed=False)
    oriented = normals.copy()
    for part in range(parts):
        members = np.flatnonzero(labels == part)
        centroid = points[members].mean(axis=0)
        offsets = points[members] - centroid
        root = members[int(np.argmax(np.einsum("ij,ij->i", offsets, offsets)))]
        order, predecessors = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        parent = predecessors[order]
        parent_safe = np.where(parent >= 0, parent, order)
        step_sign = np.sign(np.einsum("ij,ij->i", normals[order], normals[parent_safe]))
        step_sign[step_sign == 0] = 1.0
        edge_sign = np.ones(len(points))
        edge_sign[order] = step_sign
        signs = _propagate_signs(order, predecessors, edge_sign)[order]
        oriented[order] = normals[order] * signs[:, None]
        if np.dot(oriented[root], points[root] - centroid) < 0:
            oriented[order] *= -1.0
    return oriented


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
    points: np.ndarray, normals: np.ndarray, sensors: np.ndarray, indices: np.ndarray
) -> np.ndarray:
    """Flip whole connected parts of the neighbour graph so that, summed over the part, the
    normals face the sensors better than their flips do.

    Used after :func:`orient_by_propagation`: neighbours already agree, and the sensors
    decide one sign per part. On the crane scans this orients 99.6-99.8% of points like the
    truth, against 70-82% for orienting every point towards its nearest sensor.
    """
    count = len(points)
    graph = sp.csr_matrix(
        (np.ones(indices.size), (np.repeat(np.arange(count), indices.shape[1]), indices.ravel())),
        shape=(count, count),
    )
    parts, labels = connected_components(graph, directed=False)
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
) -> Normals:
    """Oriented unit normals of a scanned point set.

    PCA over the ``k`` nearest neighbours, then orientation by ``mode``:
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
    _, indices = knn(points, k)
    unoriented = pca_normals(points, k, indices=indices)
    has_sensors = sensors is not None and len(sensors) > 0
    if mode == "sensors" and has_sensors:
        oriented = orient_to_sensors(points, unoriented.normals, np.asarray(sensors, float), indices)
    else:
        oriented = orient_by_propagation(points, unoriented.normals, indices)
        if mode == "auto" and has_sensors:
            oriented = orient_parts_to_sensors(points, oriented, np.asarray(sensors, float), indices)
    return Normals(oriented, unoriented.flatness)


def nearest_normals(points: np.ndarray, reference_points: np.ndarray, reference_normals: np.ndarray) -> np.ndarray:
    """Normals of the nearest reference point for each of ``points`` ([P, 3])."""
    _, index = cKDTree(reference_points).query(points, workers=-1)
    return reference_normals[index]
