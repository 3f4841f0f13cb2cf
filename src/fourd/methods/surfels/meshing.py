"""The animated mesh of the surfel trajectories (sec. 3.3): one frame meshed from the blended
tangent planes of its surfels, then carried to every frame by the surfels it is bound to.

**One frame.** Each surfel ``(p_i, n_i)`` is a local linear implicit function
``n_i . (x - p_i)``; they are blended with Gaussian windows of standard deviation ``sigma``
(proportional to ``eps_sampl``) [SOS04]:

.. math::

    f(x) = \\frac{\\sum_i w_i(x)\\, n_i \\cdot (x - p_i)}{\\sum_i w_i(x)},
    \\qquad w_i(x) = \\exp\\!\\left(-\\frac{\\lVert x - p_i \\rVert^2}{2 \\sigma^2}\\right)

(:func:`fourd.geometry.implicit.imls_grid`, whose ``bandwidth`` is ``sqrt(2) sigma``), sampled
on a grid and contoured by marching cubes. Border detection [JWB*06]: a triangle is kept only
where the surfels support it, i.e. the weight sum ``W(x) = sum_i w_i(x)`` at each of its
corners is at least ``clip`` times the weight sum the surfels around it have at themselves
(``sum_i w_i(x) W(p_i) / W(x)``, so a sparser stretch of surfels is measured against its own
sampling, not the model's median; never under ``clip_floor`` times that median); an open
surface stays open, and the spurious sheets where the field meets the end of its support are
dropped. A vertex the clipping leaves pinched (two fans of faces meeting at it only) gets a
copy per fan.

**Every frame.** Each vertex ``v`` of the reference frame ``r`` is bound to the surfels
within the support by the renormalised weights ``phi_i = w_i(v) / W(v)`` (a partition of
unity) and by its offset ``d_i = v - p_i^r`` in each surfel's frame; in frame ``t``

.. math::

    v^t = \\sum_i \\phi_i \\left(p_i^t + F_i^t d_i\\right),

with ``F_i^t`` the surfel's rotation from ``r`` to ``t``: the composed local rotations ``A_i``
of eq. (9) (:class:`~.state.SurfelState`), optionally turned by the least rotation that takes
``F_i^t n_i^r`` onto ``n_i^t`` (the normals are estimated from the data, the twist about them
only through the ``A_i``). A rigid motion of the surfels moves the mesh rigidly, exactly.

References
----------
Wand, Jenke, Huang, Bokeloh, Guibas, Schilling: Reconstruction of deforming geometry from
time-varying point clouds, SGP 2007, section 3.3 "Meshing" (``001_3fedd1c3a0ac4198.txt``).
[SOS04] Shen, O'Brien, Shewchuk: Interpolating and approximating implicit surfaces from
polygon soup, SIGGRAPH 2004.
[JWB*06] Jenke, Wand, Bokeloh, Schilling, Strasser: Bayesian point cloud reconstruction,
Eurographics 2006 (the border detection).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.geometry.fans import split_pinches
from fourd.geometry.grid import Grid, fit_grid
from fourd.geometry.implicit import imls_grid
from fourd.geometry.marching import compact, marching_cubes
from fourd.methods.surfels.state import SurfelState, tangent_basis
from fourd.methods.surfels.urshape import Urshape, with_urshape

log = logging.getLogger("fourd.methods.surfels.meshing")

#: The grid's origin is shifted by this fraction of a cell so that axis-aligned flat data
#: (synthetic planes, surfels on a lattice) does not fall exactly on grid points, where the
#: field is exactly zero and marching cubes makes degenerate triangles.
GRID_SHIFT = 0.3183


@dataclass(frozen=True)
class MeshingOptions:
    """Scales of the meshing, in ``eps_sampl`` (the surfels' sampling distance) unless said.

    sigma : float
        Standard deviation of the Gaussian window (sec. 3.3: "proportional to eps_sampl").
        Wider smooths more and moves curved parts outwards by about ``sigma^2 / radius``
        (a unit sphere of surfels ``eps_sampl = 0.1`` apart: 0.04-0.07 ``eps_sampl`` at 0.75,
        0.08-0.12 at 1.0).
    support : float
        Surfels farther than ``support * sigma`` from a point are ignored (the window is
        ``exp(-support^2 / 2)`` there).
    cell : float
        Grid cell edge for marching cubes.
    clip : float
        Border detection: a triangle is dropped when one of its corners has a weight sum below
        ``clip`` times the reference weight sum (``clip_reference``). 0.4 with ``"local"``
        puts the border of a plane sampled ``eps_sampl`` apart where 0.3 with ``"median"``
        did, about ``0.8 eps_sampl`` beyond the last surfels.
    clip_reference : str
        ``"local"``: the weight sums the surfels around the point have at themselves (their
        own weight included), averaged with the point's window weights. Points on a surface
        between surfels get about 1, whatever the surfels' density; ``"median"``: the median
        weight sum at all the surfels, so sparser parts of a model fall under ``clip``.
    clip_floor : float
        With ``"local"``: the reference is at least this times the median weight sum at the
        surfels, so stray surfels (a chain or a few, far sparser than the surface) do not
        support a surface of their own.
    agreement : float
        Cosine: only surfels whose normal agrees this well with the nearest surfel's normal
        contribute to a point (keeps two sheets closer than the support apart; ``-1`` off).
    max_grid : int
        Most grid points along an axis; the cells grow beyond.
    align_normals : bool
        Turn each surfel's composed rotation so that it carries its reference normal onto its
        normal in each frame.
    """

    sigma: float = 0.75
    support: float = 3.5
    cell: float = 0.5
    clip: float = 0.4
    clip_reference: str = "local"
    clip_floor: float = 0.5
    agreement: float = 0.0
    max_grid: int = 256
    align_normals: bool = True

    def __post_init__(self):
        for name in ("sigma", "support", "cell"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value}")
        if not 0 < self.clip < 1:
            raise ValueError(f"clip must lie in (0, 1), got {self.clip}")
        if self.clip_reference not in ("local", "median"):
            raise ValueError(
                f"clip_reference must be 'local' or 'median', got {self.clip_reference!r}"
            )
        if not 0 <= self.clip_floor <= 1:
            raise ValueError(f"clip_floor must lie in [0, 1], got {self.clip_floor}")
        if not -1 <= self.agreement <= 1:
            raise ValueError(f"agreement must lie in [-1, 1], got {self.agreement}")
        if self.max_grid < 8:
            raise ValueError(f"max_grid must be at least 8, got {self.max_grid}")


class FrameMesh(NamedTuple):
    """The mesh of one frame's surfels.

    vertices : float64 [N, 3]
    faces : int64 [F, 3]
        Outward winding (normals point along the surfels' normals).
    support : float64 [N]
        Weight sum ``W`` at each vertex over its reference (``clip_reference``; >= ``clip``).
    grid : Grid
        The grid the field was contoured on.
    """

    vertices: np.ndarray
    faces: np.ndarray
    support: np.ndarray
    grid: Grid


class Binding(NamedTuple):
    """Vertices bound to surfels (sparse, one row per pair ``(vertex, surfel)``).

    vertex, surfel : int64 [K]
    weight : float64 [K]
        ``phi_i(v)``, summing to one over each vertex's rows.
    raw : float64 [K]
        ``w_i(v)`` before renormalisation (for the observed flags).
    offset : float64 [K, 3]
        ``v - p_i^r``, the vertex relative to the surfel in the reference frame.
    reference : float64 [N]
        Each vertex's reference weight sum (the unit of ``clip``, ``clip_reference``).
    count : int
        Number of vertices ``N``.
    """

    vertex: np.ndarray
    surfel: np.ndarray
    weight: np.ndarray
    raw: np.ndarray
    offset: np.ndarray
    reference: np.ndarray
    count: int


def _validate_surfels(positions, normals):
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3 or len(positions) == 0:
        raise ValueError(f"positions must have shape [S >= 1, 3], got {list(positions.shape)}")
    if normals.shape != positions.shape:
        raise ValueError(
            f"normals must have the positions' shape {list(positions.shape)}, "
            f"got {list(normals.shape)}"
        )
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    if not (np.isfinite(positions).all() and np.all(length > 0) and np.isfinite(length).all()):
        raise ValueError("positions must be finite and normals finite and non-zero")
    return positions, np.ascontiguousarray(normals / length)


def _sampling(sampling: float) -> float:
    if not (np.isfinite(sampling) and sampling > 0):
        raise ValueError(f"sampling (eps_sampl) must be positive, got {sampling}")
    return float(sampling)


def _window_pairs(query, positions, normals, sigma, support, agreement, tree):
    """Gaussian window weights of the surfels within ``support`` of each ``query`` point:
    ``(rows, cols, w)``, with the normal-agreement guard of :func:`imls_grid`."""
    query_tree = cKDTree(query)
    pairs = query_tree.sparse_distance_matrix(tree, support, output_type="ndarray")
    rows = pairs["i"].astype(np.int64)
    cols = pairs["j"].astype(np.int64)
    w = np.exp(-0.5 * (pairs["v"] / sigma) ** 2)
    if agreement > -1 and len(rows):
        _, nearest = tree.query(query, workers=-1)
        agree = np.einsum("ij,ij->i", normals[cols], normals[nearest[rows]]) >= agreement
        keep = agree | (cols == nearest[rows])
        rows, cols, w = rows[keep], cols[keep], w[keep]
    return rows, cols, w


def _reference_weights(
    rows, cols, w, total, positions, normals, sigma, support, options, tree
) -> np.ndarray:
    """The reference weight sum of each query point of the window pairs ``(rows, cols, w)``
    whose weight sums are ``total`` [N], by ``options.clip_reference``."""
    own_rows, _, own_w = _window_pairs(
        positions, positions, normals, sigma, support, options.agreement, tree
    )
    at_surfels = np.bincount(own_rows, own_w, minlength=len(positions))
    median = np.median(at_surfels)
    if options.clip_reference == "median":
        return np.full(len(total), median)
    level = np.bincount(rows, w * at_surfels[cols], minlength=len(total))
    return np.maximum(level / np.where(total > 0, total, 1.0), options.clip_floor * median)


def mesh_frame(
    positions: np.ndarray,
    normals: np.ndarray,
    sampling: float,
    *,
    options: MeshingOptions | None = None,
) -> FrameMesh:
    """Mesh one frame's surfels (sec. 3.3): blended tangent planes, marching cubes, border
    clipping.

    Parameters
    ----------
    positions : ndarray [S, 3]
    normals : ndarray [S, 3]
        Outward (normalised here).
    sampling : float
        ``eps_sampl`` (input units); every scale of ``options`` is a multiple of it.
    options : MeshingOptions, optional

    Returns
    -------
    FrameMesh
        Empty arrays when no surface crosses the supported region.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.linspace(-1, 1, 21)
    >>> p = np.stack([*np.meshgrid(g, g, indexing="ij"), np.zeros((21, 21))], -1).reshape(-1, 3)
    >>> mesh = mesh_frame(p, np.tile([0.0, 0.0, 1.0], (len(p), 1)), 0.1)
    >>> bool(np.abs(mesh.vertices[:, 2]).max() < 1e-6)  # marching cubes works in float32
    True
    """
    options = MeshingOptions() if options is None else options
    positions, normals = _validate_surfels(positions, normals)
    sampling = _sampling(sampling)
    sigma = options.sigma * sampling
    support = options.support * sigma
    grid = fit_grid(positions, options.cell * sampling, pad=support, max_size=options.max_grid)
    if grid.spacing > 1.01 * options.cell * sampling:
        log.warning(
            "grid cells grow from %.4g to %.4g to fit max_grid %d: the mesh will be coarser",
            options.cell * sampling,
            grid.spacing,
            options.max_grid,
        )
    grid = Grid(grid.origin - GRID_SHIFT * grid.spacing, grid.spacing, grid.shape)
    field = imls_grid(
        positions,
        normals,
        grid,
        bandwidth=np.sqrt(2.0) * sigma,
        support=support,
        agreement=options.agreement,
    )
    values = field.values  # ours: beyond the support counts as outside
    values[np.isnan(values)] = 4.0 * grid.spacing
    vertices, faces = marching_cubes(values, origin=grid.origin, spacing=grid.spacing)
    empty = FrameMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros(0), grid)
    if len(faces) == 0:
        return empty
    tree = cKDTree(positions)
    rows, cols, w = _window_pairs(
        vertices, positions, normals, sigma, support, options.agreement, tree
    )
    total = np.bincount(rows, w, minlength=len(vertices))
    reference = _reference_weights(
        rows, cols, w, total, positions, normals, sigma, support, options, tree
    )
    weight = np.divide(total, reference, out=np.zeros(len(vertices)), where=reference > 0)
    faces = faces[np.all(weight[faces] >= options.clip, axis=1)]
    if len(faces) == 0:
        return empty
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    vertices, faces = compact(vertices, faces)
    # the clipping leaves faces touching at a vertex only: one copy of it per fan of faces
    faces, source = split_pinches(faces, len(vertices))
    return FrameMesh(vertices[source], faces, weight[used][source], grid)


def bind_vertices(
    vertices: np.ndarray,
    positions: np.ndarray,
    normals: np.ndarray,
    sampling: float,
    *,
    options: MeshingOptions | None = None,
) -> Binding:
    """Bind ``vertices`` [N, 3] to the surfels ``positions``/``normals`` [S, 3] of the same
    frame by their renormalised Gaussian windows (sec. 3.3, the partition of unity).

    Raises ``ValueError`` when a vertex has no surfel within the support."""
    options = MeshingOptions() if options is None else options
    positions, normals = _validate_surfels(positions, normals)
    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    sigma = options.sigma * _sampling(sampling)
    support = options.support * sigma
    tree = cKDTree(positions)
    rows, cols, w = _window_pairs(
        vertices, positions, normals, sigma, support, options.agreement, tree
    )
    total = np.bincount(rows, w, minlength=len(vertices))
    if np.any(total <= 0):
        raise ValueError(f"{int(np.sum(total <= 0))} vertices have no surfel within {support:.4g}")
    return Binding(
        vertex=rows,
        surfel=cols,
        weight=w / total[rows],
        raw=w,
        offset=vertices[rows] - positions[cols],
        reference=_reference_weights(
            rows, cols, w, total, positions, normals, sigma, support, options, tree
        ),
        count=len(vertices),
    )


def _least_rotations(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotations [..., 3, 3] turning unit ``a`` onto unit ``b`` [..., 3] about ``a x b``
    (half a turn about a tangent of ``a`` when they are opposite)."""
    axis = np.cross(a, b)
    cosine = np.einsum("...i,...i->...", a, b)
    k = np.zeros(a.shape + (3,))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k -= np.swapaxes(k, -1, -2)
    opposite = cosine < -1.0 + 1e-12
    scale = 1.0 / np.where(opposite, 1.0, 1.0 + cosine)
    rotations = np.eye(3) + k + (k @ k) * scale[..., None, None]
    if opposite.any():
        u = tangent_basis(a[opposite])[..., 0]
        rotations[opposite] = 2.0 * u[:, :, None] * u[:, None, :] - np.eye(3)
    return rotations


def surfel_frames(state: SurfelState, reference: int, *, align_normals: bool = True) -> np.ndarray:
    """``F_i^t`` [T, S, 3, 3]: each surfel's rotation from frame ``reference`` to frame
    ``t``, composed from the local rotations ``A_i^(t)`` of eq. (9) (identity at the
    reference), then, with ``align_normals``, turned by :func:`align_to_normals`."""
    if not 0 <= reference < state.frames:
        raise ValueError(f"reference {reference} is not a frame of 0..{state.frames - 1}")
    frames = np.empty((state.frames, state.count, 3, 3))
    frames[reference] = np.eye(3)
    for t in range(reference, state.frames - 1):
        frames[t + 1] = state.rotations[t] @ frames[t]
    for t in range(reference, 0, -1):
        frames[t - 1] = np.swapaxes(state.rotations[t - 1], -1, -2) @ frames[t]
    if align_normals:
        frames = align_to_normals(frames, state.normals[reference], state.normals)
    return frames


def align_to_normals(
    frames: np.ndarray, reference_normals: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """``frames`` [T, S, 3, 3] each turned by the least rotation taking ``F n^r`` onto
    ``n^t``: ``reference_normals`` [S, 3] the normals in the reference frame, ``normals``
    [T, S, 3] those of each frame."""
    reference_normals = reference_normals / np.linalg.norm(
        reference_normals, axis=-1, keepdims=True
    )
    normals = normals / np.linalg.norm(normals, axis=-1, keepdims=True)
    turned = np.einsum("tsab,sb->tsa", frames, reference_normals)
    return _least_rotations(turned, normals) @ frames


def carry(
    binding: Binding, state: SurfelState, reference: int, *, align_normals: bool = True
) -> np.ndarray:
    """Vertex positions [T, N, 3] in every frame of ``state``: ``v^t = sum_i phi_i (p_i^t +
    F_i^t d_i)`` (sec. 3.3), for the vertices bound in frame ``reference``
    (:func:`surfel_frames` gives ``F``)."""
    frames = surfel_frames(state, reference, align_normals=align_normals)
    return carry_by(binding, state.positions, frames)


def carry_by(binding: Binding, positions: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Vertex positions [T, N, 3] of :func:`carry` from the surfels' ``positions`` [T, S, 3]
    and rotations ``frames`` [T, S, 3, 3] from the binding's frame."""
    count = binding.count
    out = np.empty((len(positions), count, 3))
    for t in range(len(positions)):
        moved = positions[t, binding.surfel] + np.einsum(
            "kab,kb->ka", frames[t, binding.surfel], binding.offset
        )
        for axis in range(3):
            out[t, :, axis] = np.bincount(
                binding.vertex, binding.weight * moved[:, axis], minlength=count
            )
    return out


def observed_vertices(
    binding: Binding, observed: np.ndarray, clip: float
) -> np.ndarray:
    """Vertices observed [T, N] from surfels ``observed`` [T, S]: the weight of the frame's
    observed surfels at a vertex reaches ``clip`` times the vertex's reference weight."""
    pairs = sp.csr_matrix(
        (binding.raw, (binding.vertex, binding.surfel)),
        shape=(binding.count, observed.shape[1]),
    )
    seen = (pairs @ np.asarray(observed, dtype=np.float64).T).T
    return seen >= clip * (1.0 - 1e-9) * binding.reference


def surfel_mesh(
    state: SurfelState,
    sampling: float,
    *,
    reference: int = 0,
    observed: np.ndarray | None = None,
    urshape: Urshape | None = None,
    times: np.ndarray | None = None,
    options: MeshingOptions | None = None,
) -> AnimatedMesh:
    """The animated mesh of surfel trajectories (sec. 3.3): frame ``reference`` (the urshape)
    meshed by :func:`mesh_frame`, its vertices bound to the surfels (:func:`bind_vertices`) and
    carried to every frame (:func:`carry`); one connectivity throughout.

    Parameters
    ----------
    state : SurfelState
        ``T`` frames of ``S`` surfels.
    sampling : float
        ``eps_sampl`` (input units).
    reference : int
        The frame that is meshed; without ``urshape`` its mesh is the result's ``rest``.
    observed : ndarray bool [T, S], optional
        Surfels with data in each frame (default all). A vertex is observed in frame ``t``
        when the weight of that frame's observed surfels at it reaches the border clipping
        threshold (``clip`` times its reference weight sum, ``clip_reference``).
    urshape : Urshape, optional
        The trajectories' urshape (:mod:`.urshape`): the mesh is carried to it too, and that
        is the result's ``rest``.
    times : ndarray [T], optional
    options : MeshingOptions, optional

    Returns
    -------
    AnimatedMesh
        ``vertices[reference]`` is the reference frame's mesh, exactly; ``rest`` is that mesh
        or, with ``urshape``, the mesh carried to the urshape.
    """
    options = MeshingOptions() if options is None else options
    if not -state.frames <= reference < state.frames:
        raise ValueError(f"reference {reference} is not a frame of 0..{state.frames - 1}")
    reference = reference % state.frames
    if observed is None:
        observed = np.ones((state.frames, state.count), dtype=bool)
    observed = np.asarray(observed)
    if observed.shape != (state.frames, state.count):
        raise ValueError(
            f"observed must have shape [{state.frames}, {state.count}], got {list(observed.shape)}"
        )
    if urshape is not None:
        joined = surfel_mesh(
            with_urshape(state, urshape),
            sampling,
            reference=reference + 1,
            observed=np.concatenate([np.ones((1, state.count), dtype=bool), observed]),
            options=options,
        )
        return AnimatedMesh(
            faces=joined.faces,
            vertices=joined.vertices[1:],
            times=times,
            observed=joined.observed[1:],
            rest=joined.vertices[0],
        )
    positions, normals = state.positions[reference], state.normals[reference]
    mesh = mesh_frame(positions, normals, sampling, options=options)
    if len(mesh.faces) == 0:
        raise ValueError(f"the surfels of frame {reference} give no surface to mesh")
    binding = bind_vertices(mesh.vertices, positions, normals, sampling, options=options)
    vertices = carry(binding, state, reference, align_normals=options.align_normals)
    vertices[reference] = mesh.vertices  # the identity up to rounding
    return AnimatedMesh(
        faces=mesh.faces,
        vertices=vertices,
        times=times,
        observed=observed_vertices(binding, observed, options.clip),
        rest=mesh.vertices,
    )
