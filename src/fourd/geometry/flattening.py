"""Flattening disk-shaped patches of a triangle mesh into the plane: LSCM and ABF++, and the
stretch of the resulting map.

Both methods leave the boundary free and pin two vertices (by default two boundary vertices far
apart) to fix the similarity the energies are blind to; the flattening is then scaled so that
its area equals the patch's (for a developable patch the map is an isometry, stretch 1).

- :func:`lscm` (Lévy et al. 2002) minimises the conformal energy: per triangle, the complex
  least-squares residual of the map being a similarity of the triangle, one sparse linear
  least-squares solve.
- :func:`abf` (ABF++, Sheffer et al. 2005) first finds the plane angles closest to the surface's
  angles (relative error, weights ``1 / beta^2``) subject to the triangle, planarity and wheel
  (reconstruction) constraints, by Newton steps on the Lagrangian whose KKT system is reduced
  twice (the angles, then the triangle multipliers, both diagonal blocks) to a sparse system
  over the interior vertices only; then the same least-squares solve as LSCM lays the triangles
  of those angles out in the plane (:func:`angles_to_uv`, ABF++ section 5).

Inputs are patches: one connected disk (one boundary loop), every vertex used by a face,
consistently oriented faces. The output ``uv`` keeps the faces' orientation (a face
counter-clockwise seen from its normal side is counter-clockwise in the plane).

References
----------
B. Lévy, S. Petitjean, N. Ray, J. Maillot, "Least squares conformal maps for automatic texture
atlas generation", SIGGRAPH 2002 (section 3: the energy, eq. 5-7; two pinned vertices).
A. Sheffer, B. Lévy, M. Mogilnitsky, A. Bogomyakov, "ABF++: fast and robust angle based
flattening", ACM TOG 24(2), 2005 (section 3: the constraints and Newton iteration; section 4:
the two-step elimination; section 5: reconstruction by least squares from the angles).
T. Popa, "Capturing and modeling of deformable objects", PhD thesis, UBC 2009, section 5.4.2
(ABF++ flattens the matching patches of the local cross-parameterisation).
P. V. Sander, J. Snyder, S. J. Gortler, H. Hoppe, "Texture mapping progressive meshes",
SIGGRAPH 2001 (section 3: stretch as the singular values of the map's Jacobian).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
from scipy.linalg.lapack import zposv
from scipy.sparse.linalg import MatrixRankWarning, spsolve

__all__ = [
    "AbfOptions",
    "Flattening",
    "abf",
    "angle_distortion",
    "angles_to_uv",
    "boundary_loop_vertices",
    "corner_angles",
    "flatten",
    "lscm",
    "map_singular_values",
    "signed_uv_areas",
]


@dataclass(frozen=True)
class AbfOptions:
    """Settings of :func:`abf`.

    Attributes
    ----------
    max_iterations : int
        Newton steps at most (ABF++ reports convergence in a few to a few tens).
    tolerance : float
        Stop when the KKT residual (the Lagrangian's gradient in angles and multipliers,
        Euclidean norm, radians) falls below this.
    min_angle : float
        Angles are kept within ``[min_angle, pi - min_angle]`` (radians), optimal and current,
        so every sine stays positive on a patch with slivers.
    """

    max_iterations: int = 30
    tolerance: float = 1e-9
    min_angle: float = 1e-4

    def __post_init__(self):
        if int(self.max_iterations) != self.max_iterations or self.max_iterations < 0:
            raise ValueError(f"max_iterations must be an integer >= 0, got {self.max_iterations!r}")
        if not self.tolerance > 0:
            raise ValueError(f"tolerance must be > 0, got {self.tolerance!r}")
        if not 0 < self.min_angle < np.pi / 6:
            raise ValueError(f"min_angle must be in (0, pi/6), got {self.min_angle!r}")


class Flattening(NamedTuple):
    """A patch laid out in the plane.

    uv : float64 [N, 2]
        One point per vertex, in the patch's units (scaled to its area).
    pinned : int64 [2]
        The two vertices held during the solve (``uv[pinned[0]]`` is the origin and
        ``uv[pinned[1]]`` lies on the positive u axis).
    iterations : int
        Newton steps taken (0 for LSCM).
    residual : float
        Final KKT residual of the angle optimisation (0 for LSCM).
    converged : bool
        Whether the residual fell below the tolerance (always True for LSCM).
    """

    uv: np.ndarray
    pinned: np.ndarray
    iterations: int = 0
    residual: float = 0.0
    converged: bool = True


def _check(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must have shape [N, 3], got {list(vertices.shape)}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"faces must have shape [F, 3] with F >= 1, got {list(faces.shape)}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError("faces index vertices out of range")
    if np.bincount(faces.ravel(), minlength=len(vertices)).min() == 0:
        raise ValueError("every vertex of a patch must belong to a face (compact it first)")
    return vertices, faces


def _edges(faces: np.ndarray, count: int):
    """Undirected edge keys of every face side ``[F, 3]`` (side ``k`` joins corners ``k`` and
    ``k + 1``) and how many faces share each side's edge ``[F, 3]``."""
    a, b = faces, np.roll(faces, -1, axis=1)
    keys = np.minimum(a, b) * np.int64(count) + np.maximum(a, b)
    _, inverse, counts = np.unique(keys.ravel(), return_inverse=True, return_counts=True)
    return keys, counts[inverse].reshape(faces.shape)


def boundary_loop_vertices(faces: np.ndarray, count: int) -> np.ndarray:
    """Whether each of ``count`` vertices lies on the boundary (an edge of one face), bool
    ``[count]``; raises ``ValueError`` unless the faces form one disk (connected, Euler
    characteristic 1, manifold edges, a boundary that never touches itself)."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    problem, euler, parts, boundary = _disk_check(faces, int(count))
    if problem == 1:
        raise ValueError("the patch has an edge of three or more faces (not a manifold disk)")
    if problem == 2:
        raise ValueError(f"the patch is not a disk (Euler characteristic {euler}, a disk has 1)")
    if problem == 3:
        raise ValueError(f"the patch has {parts} connected pieces, a disk has 1")
    if problem == 4:
        raise ValueError("the patch's boundary touches itself at a vertex (not a disk)")
    return boundary


@numba.njit(cache=True, nogil=True)
def _disk_check(faces, count):
    """The checks of :func:`boundary_loop_vertices` in one pass: ``(problem, euler, parts,
    boundary)``, problem 0 for a disk, else the first check failed (1 non-manifold edge,
    2 Euler characteristic, 3 pieces, 4 boundary touching itself)."""
    sides = len(faces) * 3
    keys = np.empty(sides, dtype=np.int64)
    for f in range(len(faces)):
        for k in range(3):
            a, b = faces[f, k], faces[f, (k + 1) % 3]
            keys[3 * f + k] = min(a, b) * count + max(a, b)
    keys.sort()
    ends = np.zeros(count, dtype=np.int64)
    boundary = np.zeros(count, dtype=np.bool_)
    edges = 0
    widest = 0
    i = 0
    while i < sides:
        j = i
        while j < sides and keys[j] == keys[i]:
            j += 1
        edges += 1
        widest = max(widest, j - i)
        if j - i == 1:
            ends[keys[i] // count] += 1
            ends[keys[i] % count] += 1
        i = j
    if widest > 2:
        return 1, 0, 0, boundary
    euler = count - edges + len(faces)
    if euler != 1:
        return 2, euler, 0, boundary
    parent = np.arange(count)
    for f in range(len(faces)):
        for k in range(3):
            a, b = faces[f, k], faces[f, (k + 1) % 3]
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            if a != b:
                parent[max(a, b)] = min(a, b)
    parts = 0
    for v in range(count):
        if parent[v] == v:
            parts += 1
    if parts != 1:
        return 3, euler, parts, boundary
    for v in range(count):
        if ends[v] > 2:
            return 4, euler, parts, boundary
        boundary[v] = ends[v] > 0
    return 0, euler, parts, boundary


def corner_angles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Interior angle at every face corner, radians ``[F, 3]`` (works for ``[N, 2]`` points
    too)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.shape[1] == 2:
        vertices = np.concatenate([vertices, np.zeros((len(vertices), 1))], axis=1)
    tri = vertices[np.asarray(faces, dtype=np.int64)]
    a = np.roll(tri, -1, axis=1) - tri  # to the next corner
    b = np.roll(tri, 1, axis=1) - tri  # to the previous corner
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=2), np.einsum("fkd,fkd->fk", a, b))


def signed_uv_areas(faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Signed area of every face in the plane ``[F]``: positive counter-clockwise (a face
    with area <= 0 is flipped or degenerate)."""
    tri = np.asarray(uv, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def map_singular_values(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Stretch of the map from each surface triangle to its image in the plane: the singular
    values ``[F, 2]`` (largest first) of the map's Jacobian (Sander et al. 2001). Both are 1
    for an isometric triangle; their ratio is the triangle's conformal distortion. A flipped
    triangle has the same singular values as its mirror image (see :func:`signed_uv_areas`).

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
    uv : array [N, 2]
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    local = _local_triangles(vertices, faces)  # [F, 3] complex
    tri = np.asarray(uv, dtype=np.float64)[faces]
    edges = np.stack([local[:, 1] - local[:, 0], local[:, 2] - local[:, 0]], axis=1)  # [F, 2]
    source = np.stack([edges.real, edges.imag], axis=1)  # [F, 2, 2], columns = edges
    target = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=2)  # [F, 2, 2]
    jacobian = target @ np.linalg.inv(source)
    return np.linalg.svd(jacobian, compute_uv=False)


def angle_distortion(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> float:
    """Root mean square relative error of the corner angles in the plane against the surface's,
    ``sqrt(mean(((alpha - phi) / phi)^2))`` (dimensionless; ABF's energy, Sheffer and de
    Sturler 2001, with the surface's angles as the optimal ones)."""
    phi = corner_angles(vertices, faces)
    relative = (corner_angles(uv, faces) - phi) / np.maximum(phi, 1e-300)
    return float(np.sqrt(np.mean(relative**2)))


def _local_triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each triangle in its own plane as complex corners ``[F, 3]``: corner 0 at 0, corner 1 on
    the positive real axis, corner 2 above it (counter-clockwise)."""
    return _local_triangles_kernel(np.ascontiguousarray(vertices, dtype=np.float64),
                                   np.ascontiguousarray(faces, dtype=np.int64))


@numba.njit(cache=True, nogil=True)
def _local_triangles_kernel(vertices, faces):
    local = np.zeros((faces.shape[0], 3), dtype=np.complex128)
    for f in range(faces.shape[0]):
        p, q, r = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        e1, e2 = q - p, r - p
        length = np.sqrt(e1 @ e1)
        cx = e1[1] * e2[2] - e1[2] * e2[1]
        cy = e1[2] * e2[0] - e1[0] * e2[2]
        cz = e1[0] * e2[1] - e1[1] * e2[0]
        inverse = 1.0 / max(length, 1e-300)
        local[f, 1] = length
        local[f, 2] = (e2 @ e1) * inverse + 1j * np.sqrt(cx * cx + cy * cy + cz * cz) * inverse
    return local


def _triangles_from_angles(angles: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """Complex corners ``[F, 3]`` of triangles with the given angles ``[F, 3]`` and areas
    ``[F]`` (the law of sines: side ``k, k+1`` is proportional to the sine of the angle
    opposite it)."""
    s0, s1, s2 = np.sin(angles[:, 0]), np.sin(angles[:, 1]), np.sin(angles[:, 2])
    scale = np.sqrt(areas / np.maximum(0.5 * s0 * s1 * s2, 1e-300))
    return np.stack(
        [np.zeros(len(angles)), scale * s2 + 0j, scale * s1 * np.exp(1j * angles[:, 0])], axis=1
    )


def _far_boundary_pair(vertices: np.ndarray, boundary: np.ndarray) -> np.ndarray:
    """Two boundary vertices far apart (two farthest-point sweeps)."""
    candidates = np.flatnonzero(boundary)
    points = vertices[candidates]
    first = candidates[np.argmax(np.linalg.norm(points - points[0], axis=1))]
    second = candidates[np.argmax(np.linalg.norm(points - vertices[first], axis=1))]
    return np.array([first, second], dtype=np.int64)


def _conformal_layout(
    faces: np.ndarray, local: np.ndarray, count: int, pinned: np.ndarray, distance: float
) -> np.ndarray:
    """The least-squares conformal layout ``[count, 2]`` of triangles with the given shapes
    (complex corners ``local [F, 3]``), ``pinned[0]`` at the origin and ``pinned[1]`` at
    ``(distance, 0)`` (Lévy et al. 2002, eq. 7)."""
    # sum_j W_j U_j / sqrt(2 area) = 0 holds when the triangle's image is a similarity of it,
    # with W_j = z_{j+2} - z_{j+1} and U_j = u_j + i v_j: the energy sum_T |sum_j w_j U_j|^2 is
    # U^H M U with the Hermitian M summed triangle by triangle (M_jk += conj(w_j) w_k), half
    # the unknowns of the real (u, v) form, the same minimiser
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    local = np.ascontiguousarray(local, dtype=np.complex128)
    is_fixed = np.zeros(count, dtype=bool)
    is_fixed[pinned] = True
    index = np.cumsum(~is_fixed) - 1
    index[pinned] = -1 - np.arange(2)  # -1: the origin, -2: (distance, 0)
    size = count - 2
    solution = np.zeros(count, dtype=np.complex128)
    solution[pinned[1]] = distance
    rows, columns, values, rhs = _conformal_system(faces, local, index, size, float(distance))
    solved = False
    if size <= DENSE_UNKNOWNS:
        # LAPACK's Cholesky solve called directly: scipy.linalg.solve's own checks cost four
        # times the solve on these small systems
        _, dense_solution, info = zposv(_dense(rows, columns, values, size), rhs, lower=False)
        solved = info == 0
        if solved:
            solution[~is_fixed] = dense_solution
        # not positive definite (a degenerate patch): the sparse solve says so as it always did
    if not solved:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MatrixRankWarning)  # singular: NaN, which callers test
            solution[~is_fixed] = spsolve(sp.csc_matrix((values, (rows, columns)), shape=(size, size)), rhs)
    # a nearly singular system solves to a layout millions of times the pins' distance across
    # rather than to NaN: the same failure, so said the same way
    if not np.all(np.abs(solution) <= SINGULAR_SPAN * distance):
        solution[:] = complex(np.nan, np.nan)
    return np.stack([solution.real, solution.imag], axis=1)


@numba.njit(cache=True, nogil=True)
def _triangle_weights(local):
    """The conformality weights ``w_j = (z_{j+2} - z_{j+1}) / sqrt(2 area)`` ``[F, 3]``."""
    weights = np.empty(local.shape, dtype=np.complex128)
    for f in range(local.shape[0]):
        e1, e2 = local[f, 1] - local[f, 0], local[f, 2] - local[f, 0]
        scale = 1.0 / np.sqrt(max(abs((np.conj(e1) * e2).imag), 1e-300))
        for j in range(3):
            weights[f, j] = (local[f, (j + 2) % 3] - local[f, (j + 1) % 3]) * scale
    return weights


@numba.njit(cache=True, nogil=True)
def _conformal_system(faces, local, index, size, distance):
    """The Hermitian system of the free unknowns (``index``: a free vertex's unknown, -1 and -2
    the two pins) as entries (rows, columns, values; duplicates to be summed) and the
    right-hand side."""
    weights = _triangle_weights(local)
    rows = np.empty(9 * faces.shape[0], dtype=np.int64)
    columns = np.empty(9 * faces.shape[0], dtype=np.int64)
    values = np.empty(9 * faces.shape[0], dtype=np.complex128)
    rhs = np.zeros(size, dtype=np.complex128)
    n = 0
    for f in range(faces.shape[0]):
        for j in range(3):
            row = index[faces[f, j]]
            if row < 0:
                continue
            for k in range(3):
                column = index[faces[f, k]]
                value = np.conj(weights[f, j]) * weights[f, k]
                if column >= 0:
                    rows[n], columns[n], values[n] = row, column, value
                    n += 1
                elif column == -2:
                    rhs[row] -= value * distance
    return rows[:n], columns[:n], values[:n], rhs


@numba.njit(cache=True, nogil=True)
def _dense(rows, columns, values, size):
    """The ``[size, size]`` matrix of the entries (duplicates summed)."""
    matrix = np.zeros((size, size), dtype=np.complex128)
    for n in range(len(rows)):
        matrix[rows[n], columns[n]] += values[n]
    return matrix


#: Normal equations of at most this many unknowns are solved dense (a patch of the
#: cross-parameterisation has about 70 vertices: 68 complex unknowns, where a sparse
#: factorisation costs mostly its setting up).
DENSE_UNKNOWNS = 300
#: A layout reaching farther than this many times the pins' distance is a singular solve's.
SINGULAR_SPAN = 1e6


def _pins(vertices, faces, pinned) -> np.ndarray:
    boundary = boundary_loop_vertices(faces, len(vertices))
    if pinned is None:
        return _far_boundary_pair(vertices, boundary)
    pinned = np.asarray(pinned, dtype=np.int64).reshape(-1)
    if len(pinned) != 2 or pinned[0] == pinned[1] or pinned.min() < 0 or pinned.max() >= len(vertices):
        raise ValueError(f"pinned must be two different vertex indices, got {pinned.tolist()}")
    return pinned


def _to_area(uv: np.ndarray, faces: np.ndarray, area: float, pinned: np.ndarray) -> np.ndarray:
    """``uv`` scaled about the first pinned vertex so its total area is ``area``."""
    planar = float(np.abs(signed_uv_areas(faces, uv)).sum())
    if not planar > 0:  # degenerate, or NaN from a singular layout
        return uv
    return uv[pinned[0]] + (uv - uv[pinned[0]]) * np.sqrt(area / planar)


def angles_to_uv(
    vertices: np.ndarray, faces: np.ndarray, angles: np.ndarray, *, pinned=None
) -> np.ndarray:
    """Lay out triangles with the given plane angles: the least-squares layout in which every
    triangle is as close as possible to a similarity of the triangle of its angles (ABF++
    section 5, the LSCM system with the angles' triangles). Scaled so the layout's area equals
    the surface's.

    Parameters
    ----------
    vertices : array [N, 3]
        The patch (for its areas, which weight the triangles, and the default pins).
    faces : int array [F, 3]
    angles : array [F, 3]
        Plane angle at every corner, radians (each triangle's summing to pi).
    pinned : two vertex indices, optional
        Default: two boundary vertices far apart.

    Returns
    -------
    ndarray float64 [N, 2]
    """
    vertices, faces = _check(vertices, faces)
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape != faces.shape:
        raise ValueError(f"angles must have the shape of faces {list(faces.shape)}, got {list(angles.shape)}")
    pins = _pins(vertices, faces, pinned)
    from fourd.geometry.meshes import face_areas

    areas = face_areas(vertices, faces)
    local = _triangles_from_angles(angles, areas)
    distance = float(np.linalg.norm(vertices[pins[1]] - vertices[pins[0]])) or 1.0
    uv = _conformal_layout(faces, local, len(vertices), pins, distance)
    return _to_area(uv, faces, float(areas.sum()), pins)


def lscm(vertices: np.ndarray, faces: np.ndarray, *, pinned=None) -> Flattening:
    """Least squares conformal map of a disk-shaped patch, free boundary (Lévy et al. 2002).

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
        One disk, consistently oriented, every vertex used.
    pinned : two vertex indices, optional
        Held at ``(0, 0)`` and on the positive u axis; default two boundary vertices far apart.

    Returns
    -------
    Flattening
        Scaled so the flattening's area equals the patch's.

    Examples
    --------
    >>> v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 1], [0, 1, 1.]])
    >>> flat = lscm(v, np.array([[0, 1, 2], [0, 2, 3]]))
    >>> bool(np.allclose(map_singular_values(v, np.array([[0, 1, 2], [0, 2, 3]]), flat.uv), 1))
    True
    """
    vertices, faces = _check(vertices, faces)
    pins = _pins(vertices, faces, pinned)
    local = _local_triangles(vertices, faces)
    area = 0.5 * float(np.sum(local[:, 1].real * local[:, 2].imag))
    distance = float(np.linalg.norm(vertices[pins[1]] - vertices[pins[0]])) or 1.0
    uv = _conformal_layout(faces, local, len(vertices), pins, distance)
    return Flattening(_to_area(uv, faces, area, pins), pins)


def _optimal_angles(angles: np.ndarray, faces: np.ndarray, interior: np.ndarray, count: int) -> np.ndarray:
    """The surface's angles, those around an interior vertex scaled to sum to 2 pi (ABF,
    Sheffer and de Sturler 2001, section 3)."""
    sums = np.bincount(faces.ravel(), weights=angles.ravel(), minlength=count)
    scale = np.where(interior, 2.0 * np.pi / np.maximum(sums, 1e-300), 1.0)
    return angles * scale[faces]


def _constraints(alpha: np.ndarray, faces: np.ndarray, interior_index: np.ndarray, interior_count: int):
    """Residuals and sparse Jacobian (rows: the triangles, then the planarity and the wheel
    condition of every interior vertex) of the ABF constraints at angles ``alpha [3F]``."""
    face_count = len(faces)
    corner_vertex = faces.ravel()
    corner = np.arange(3 * face_count)
    triangle = alpha.reshape(-1, 3).sum(axis=1) - np.pi
    rows = [np.repeat(np.arange(face_count), 3)]
    columns = [corner]
    values = [np.ones(3 * face_count)]
    residual = [triangle]
    if interior_count:
        at = interior_index[corner_vertex]
        mine = at >= 0
        c = corner[mine]
        row = at[mine]
        nxt = 3 * (c // 3) + (c % 3 + 1) % 3  # the corner after c in its face
        prv = 3 * (c // 3) + (c % 3 + 2) % 3
        planar = np.bincount(row, weights=alpha[c], minlength=interior_count) - 2.0 * np.pi
        log_sin = np.log(np.sin(alpha))
        wheel = np.bincount(row, weights=log_sin[nxt] - log_sin[prv], minlength=interior_count)
        cot = 1.0 / np.tan(alpha)
        rows += [face_count + row, face_count + interior_count + row, face_count + interior_count + row]
        columns += [c, nxt, prv]
        values += [np.ones(len(c)), cot[nxt], -cot[prv]]
        residual += [planar, wheel]
    jacobian = sp.csr_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
        shape=(face_count + 2 * interior_count, 3 * face_count),
    )
    return np.concatenate(residual), jacobian


def _abf_angles(angles3d, faces, interior, count, options: AbfOptions):
    """ABF++'s angles ``[F, 3]``, Newton steps taken and final KKT residual."""
    face_count = len(faces)
    interior_index = np.full(count, -1, dtype=np.int64)
    interior_index[interior] = np.arange(int(interior.sum()))
    low, high = options.min_angle, np.pi - options.min_angle
    beta = np.clip(_optimal_angles(angles3d, faces, interior, count), low, high).ravel()
    weight = 1.0 / beta**2
    alpha = beta.copy()
    inverse_hessian = 1.0 / (2.0 * weight)  # the energy's Hessian is diagonal, 2 w
    constraint_count = face_count + 2 * int(interior.sum())
    multipliers = np.zeros(constraint_count)
    residual_norm, steps = np.inf, 0
    for steps in range(options.max_iterations + 1):
        residual, jacobian = _constraints(alpha, faces, interior_index, int(interior.sum()))
        gradient = 2.0 * weight * (alpha - beta) + jacobian.T @ multipliers
        residual_norm = float(np.sqrt(gradient @ gradient + residual @ residual))
        if residual_norm < options.tolerance or steps == options.max_iterations:
            break
        # KKT: [H J^T; J 0] [da; dl] = -[g; c] with H diagonal. Eliminating da leaves
        # (J H^-1 J^T) dl = c - J H^-1 g; its triangle block is diagonal (every angle lies in
        # one triangle), so eliminating those multipliers leaves the interior vertices' system.
        rhs = residual - jacobian @ (inverse_hessian * gradient)
        j1, j2 = jacobian[:face_count], jacobian[face_count:]
        block = inverse_hessian.reshape(-1, 3).sum(axis=1)  # J1 H^-1 J1^T, diagonal
        r1, r2 = rhs[:face_count], rhs[face_count:]
        if j2.shape[0]:
            coupling = (j1 @ sp.diags(inverse_hessian) @ j2.T).tocsr()  # [F, 2I]
            schur = (j2 @ sp.diags(inverse_hessian) @ j2.T) - coupling.T @ sp.diags(1.0 / block) @ coupling
            step2 = spsolve(schur.tocsc(), r2 - coupling.T @ (r1 / block))
            step1 = (r1 - coupling @ step2) / block
            step = np.concatenate([step1, np.atleast_1d(step2)])
        else:
            step = r1 / block
        alpha = np.clip(alpha - inverse_hessian * (gradient + jacobian.T @ step), low, high)
        multipliers = multipliers + step
    return alpha.reshape(-1, 3), steps, residual_norm


def abf(
    vertices: np.ndarray, faces: np.ndarray, *, options: AbfOptions | None = None, pinned=None
) -> Flattening:
    """ABF++ flattening of a disk-shaped patch, free boundary (Sheffer et al. 2005).

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
        One disk, consistently oriented, every vertex used.
    options : AbfOptions, optional
    pinned : two vertex indices, optional
        Held during the layout from the angles; default two boundary vertices far apart.

    Returns
    -------
    Flattening
        With the Newton steps taken and the final KKT residual; scaled so the flattening's
        area equals the patch's.
    """
    options = AbfOptions() if options is None else options
    vertices, faces = _check(vertices, faces)
    pins = _pins(vertices, faces, pinned)
    interior = ~boundary_loop_vertices(faces, len(vertices))
    angles, steps, residual = _abf_angles(corner_angles(vertices, faces), faces, interior, len(vertices), options)
    uv = angles_to_uv(vertices, faces, angles, pinned=pins)
    return Flattening(uv, pins, steps, residual, residual < options.tolerance)


def flatten(
    vertices: np.ndarray, faces: np.ndarray, *, method: str = "abf", pinned=None
) -> Flattening:
    """Flatten a disk-shaped patch with ``method`` ``"abf"`` (ABF++, default) or ``"lscm"``."""
    if method == "abf":
        return abf(vertices, faces, pinned=pinned)
    if method == "lscm":
        return lscm(vertices, faces, pinned=pinned)
    raise ValueError(f"method must be 'abf' or 'lscm', got {method!r}")
