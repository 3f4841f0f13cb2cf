"""Dynamic wrinkles from video: the space-time deformation of Popa's thesis, section 4.5.

Given a captured garment (one connectivity, every frame) and the anchors the video gives
(:mod:`.wrinkle_anchors`):

1. **Space-time rotation** (4.5.3, eq. 4.1). Every triangle of every frame gets a rotation,
   a convex blend of the anchors' rotations and the identity with weights ``w`` minimising
   ``cs sum_edges |w_i - w_j|^2 + ct sum |w_i^t - w_i^(t-1)|^2 + ci sum_(not anchors) |w|^2 +
   ca sum_anchors |w - I|^2`` (uniform weights, as the thesis: the meshes are fairly uniform).
   Blended in Alexa's algebra (``exp(sum w_a log R_a)``), the blend's rotation vector is the
   same linear functional of the anchors' rotation vectors, so the minimiser is found for the
   rotation vectors directly: three right-hand sides instead of one per anchor, the same
   result. Solved by conjugate gradients over all frames at once, tolerance 1e-3 (the thesis
   staggers windows of ten frames only to save memory).
2. **Vertex positioning** (4.5.4, eq. 4.2). Per frame, positions whose triangles' edges are
   the input's edges turned by the triangles' rotations, in the least-squares sense (the edge
   form of eq. 4.2: three edges fix a triangle up to translation, so the virtual fourth
   vertex adds nothing here); a pull to the input positions fixes the translation (the thesis
   fixes one vertex) and keeps the far side of the garment from drifting as the rotations
   are integrated. The matrix is the same for every frame and iteration: factored once.
3. **Stretch reduction** (4.5.5). The rotations taking each input triangle's normal to its
   positioned normal replace the rotations, and the positions are solved again.
4. **Folds only** (not in the thesis). Of each frame's displacement, only the part finer than
   the folds' wavelength is kept: the anchors' rotations blended over the surface also bend it
   broadly, which is no fold, and moves a garment captured from depth scans off its data.
5. **The data stands** (not in the thesis, :func:`hold_to_data`). The thesis wrinkles surfaces
   from multi-view stereo, too smooth to show folds; a depth scan resolves many of them, and
   there what the video adds is error. An observed vertex is moved only along its data's
   normal toward the data, never off it; a vertex the template completed takes the video's
   folds whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg, splu
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from fourd.geometry.low_pass import low_pass_surface
from fourd.geometry.meshes import face_adjacency
from fourd.geometry.surface_walk import face_unit_normals
from fourd.methods.garment.wrinkle_anchors import (
    AnchorOptions,
    FrameAnchors,
    frame_anchors,
    rotation_between,
)
from fourd.progress import progress

__all__ = ["WrinkleOptions", "WrinkleResult", "hold_to_data", "position_vertices", "positioned_frames", "spacetime_rotations",
           "triangle_stretch", "wrinkle"]


@dataclass(frozen=True)
class WrinkleOptions:
    """The wrinkling step's parameters (thesis 4.5; the defaults are the thesis' own).

    Attributes
    ----------
    smoothness, temporal, identity, anchor : float
        ``cs``, ``ct``, ``ci``, ``ca`` of eq. 4.1: rotation continuity across triangles and
        across frames, the pull to the identity away from the anchors, the anchors' weight.
    stretch_iterations : int
        Stretch-reduction passes (4.5.5; the thesis: one or two; none by default, measured in
        METHODS.md: on meshes a few edges per fold each pass flattens the folds).
    pull : float
        Weight of each vertex's input position in the positioning (4.5.4), in units of one
        triangle edge's term: the thesis fixes one vertex, and rotations integrated over the
        whole garment then drift its far side.
    base_wavelength : float
        The low-pass cutoff (fraction of the garment's bounding-box diagonal) of the surface the
        anchors' angles are measured from (:mod:`.wrinkle_anchors`).
    fold_band : float
        The displacement is kept only finer than this fraction of ``base_wavelength`` (its
        low-pass at that wavelength is taken out; 0: all of it kept, as the thesis).
    anchors : AnchorOptions
        Views, angles and the fold-edge filter.
    """

    smoothness: float = 0.9
    temporal: float = 0.5
    identity: float = 0.1
    anchor: float = 10.0
    stretch_iterations: int = 0
    pull: float = 0.1
    base_wavelength: float = 0.1
    fold_band: float = 1.0
    anchors: AnchorOptions = field(default_factory=AnchorOptions)


class WrinkleResult(NamedTuple):
    """``vertices`` [T, N, 3], the wrinkled garment; ``anchors``: each frame's
    :class:`~.wrinkle_anchors.FrameAnchors`; ``stretch`` [T]: the largest per-triangle stretch
    of each frame after the last pass (1: none)."""

    vertices: np.ndarray
    anchors: list[FrameAnchors]
    stretch: np.ndarray


def spacetime_rotations(
    faces: np.ndarray, frames: int, anchors: list[FrameAnchors], options: WrinkleOptions | None = None
) -> np.ndarray:
    """Rotation vectors [T, F, 3] of every triangle in every frame (eq. 4.1, module docstring)."""
    options = options or WrinkleOptions()
    face_count = len(faces)
    size = frames * face_count
    pairs, _ = face_adjacency(faces)
    adjacency = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(face_count,) * 2)
    adjacency = adjacency + adjacency.T
    space = sp.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
    if frames > 1:
        chain = sp.diags([np.ones(frames - 1), np.ones(frames - 1)], [-1, 1], shape=(frames, frames))
        time = sp.diags(np.asarray(chain.sum(axis=1)).ravel()) - chain
    else:
        time = sp.csr_matrix((1, 1))
    anchored = np.zeros(size, dtype=bool)
    target = np.zeros((size, 3))
    for t, frame in enumerate(anchors):
        index = t * face_count + np.asarray(frame.faces, dtype=np.int64)
        anchored[index] = True
        target[index] = frame.rotations
    if not anchored.any():
        return np.zeros((frames, face_count, 3))
    diagonal = np.where(anchored, options.anchor, options.identity)
    system = (
        options.smoothness * sp.kron(sp.identity(frames), space)
        + options.temporal * sp.kron(time, sp.identity(face_count))
        + sp.diags(diagonal)
    ).tocsr()
    rhs = options.anchor * target
    preconditioner = sp.diags(1.0 / system.diagonal())
    solution = np.empty((size, 3))
    for k in range(3):
        solution[:, k], _ = cg(system, rhs[:, k], rtol=1e-3, maxiter=200, M=preconditioner)
    return solution.reshape(frames, face_count, 3)


def _edge_operator(vertex_count: int, faces: np.ndarray) -> sp.csr_matrix:
    """``D`` [3F, N]: row ``3f + k`` is vertex ``faces[f, (k+1) % 3]`` minus ``faces[f, k]``."""
    rows = np.arange(3 * len(faces))
    heads = faces[:, [1, 2, 0]].ravel()
    tails = faces.ravel()
    return sp.csr_matrix(
        (np.r_[np.ones(len(rows)), -np.ones(len(rows))], (np.r_[rows, rows], np.r_[heads, tails])),
        shape=(len(rows), vertex_count),
    )


def position_vertices(vertices: np.ndarray, faces: np.ndarray, rotations: np.ndarray, *, solver=None,
                      pull: float = 0.1) -> np.ndarray:
    """Vertices [N, 3] whose triangles' edges best match the input's turned by ``rotations``
    [F, 3] (rotation vectors; eq. 4.2 in edge form), with a weak ``pull`` to the input.
    ``solver``: a factorisation from :func:`_positioning_solver` to reuse."""
    faces = np.asarray(faces, dtype=np.int64)
    operator = _edge_operator(len(vertices), faces)
    solve = solver or _positioning_solver(len(vertices), faces, pull)
    edges = (operator @ vertices).reshape(len(faces), 3, 3)
    turned = np.einsum("fij,fkj->fki", Rotation.from_rotvec(rotations).as_matrix(), edges).reshape(-1, 3)
    return solve(operator.T @ turned + pull * vertices)


def _positioning_solver(vertex_count: int, faces: np.ndarray, pull: float):
    operator = _edge_operator(vertex_count, faces)
    return splu((operator.T @ operator + pull * sp.identity(vertex_count)).tocsc()).solve


def triangle_stretch(before: np.ndarray, after: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-triangle stretch [F]: the largest ratio of an edge's length after to before (1: none)."""
    operator = _edge_operator(len(before), faces)
    a = np.linalg.norm((operator @ before).reshape(-1, 3, 3), axis=2)
    b = np.linalg.norm((operator @ after).reshape(-1, 3, 3), axis=2)
    return (b / np.maximum(a, 1e-300)).max(axis=1)


def wrinkle(vertices: np.ndarray, faces: np.ndarray, video, options: WrinkleOptions | None = None) -> WrinkleResult:
    """The garment ``vertices`` [T, N, 3] (one connectivity ``faces`` [F, 3]) wrinkled where the
    ``video`` (:class:`fourd.io.video.Video`, frame ``t`` its image ``t``) shows folds (module
    docstring)."""
    options = options or WrinkleOptions()
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    frames = len(vertices)
    diagonal = float(np.linalg.norm(np.ptp(vertices.reshape(-1, 3), axis=0)))
    cameras = video.cameras
    anchors = []
    for t in progress(range(frames), desc="garment: folds in the video", unit="frame"):
        base = low_pass_surface(vertices[t], faces, options.base_wavelength * diagonal)
        images = [video.image(c, t) for c in range(len(cameras))]
        anchors.append(frame_anchors(vertices[t], faces, base, cameras, images, options.anchors))
    result = positioned_frames(vertices, faces, spacetime_rotations(faces, frames, anchors, options), options)
    if options.fold_band > 0:
        for t in range(frames):
            displacement = result[t] - vertices[t]
            if np.any(displacement):
                broad = low_pass_surface(vertices[t], faces, options.fold_band * options.base_wavelength * diagonal,
                                         values=displacement)
                result[t] -= broad
    stretch = np.array([float(triangle_stretch(vertices[t], result[t], faces).max()) for t in range(frames)])
    return WrinkleResult(result, anchors, stretch)


def hold_to_data(before: np.ndarray, after: np.ndarray, points: np.ndarray, normals: np.ndarray,
                 free: np.ndarray) -> np.ndarray:
    """The wrinkled vertices ``after`` [N, 3] with each held vertex's move along the data's
    normal cut to what brings it toward the data (module docstring, step 5).

    ``before`` [N, 3] the vertices before wrinkling; ``points`` [M, 3] and unit ``normals``
    [M, 3] the frame's data; ``free`` [N] bool: vertices that take the whole move (those no data
    observed). For a held vertex with nearest data point ``p`` and normal ``n``: its offset from
    the data's plane ``s = (before - p) . n`` and its move along the normal ``d = (after -
    before) . n``; the move is kept only where it goes toward the plane (``s d < 0``) and no
    farther than onto it, and its move along the surface is dropped (where the scan observed a
    vertex, the fit placed it along the surface; measured in METHODS.md).
    """
    before = np.asarray(before, dtype=np.float64)
    after = np.asarray(after, dtype=np.float64)
    held = ~np.asarray(free, dtype=bool)
    if not held.any() or not len(points):
        return after.copy()
    _, nearest = cKDTree(points).query(before[held], workers=-1)
    normal = normals[nearest]
    offset = np.einsum("ij,ij->i", before[held] - points[nearest], normal)
    move = np.einsum("ij,ij->i", after[held] - before[held], normal)
    kept = np.where(offset * move < 0, np.sign(move) * np.minimum(np.abs(move), np.abs(offset)), 0.0)
    result = after.copy()
    result[held] = before[held] + kept[:, None] * normal
    return result


def positioned_frames(vertices: np.ndarray, faces: np.ndarray, rotations: np.ndarray,
                      options: WrinkleOptions | None = None) -> np.ndarray:
    """Every frame's vertices [T, N, 3] positioned by its triangles' ``rotations`` [T, F, 3]
    (4.5.4), then ``stretch_iterations`` passes of stretch reduction (4.5.5); a frame without
    rotations stays as it is. One factorisation serves every frame and pass."""
    options = options or WrinkleOptions()
    solve = _positioning_solver(vertices.shape[1], faces, options.pull)
    result = np.array(vertices, dtype=np.float64, copy=True)
    for t in range(len(vertices)):
        if not np.any(rotations[t]):
            continue
        current = position_vertices(vertices[t], faces, rotations[t], solver=solve, pull=options.pull)
        for _ in range(options.stretch_iterations):
            turn = rotation_between(face_unit_normals(vertices[t], faces), face_unit_normals(current, faces))
            current = position_vertices(vertices[t], faces, turn, solver=solve, pull=options.pull)
        result[t] = current
    return result
