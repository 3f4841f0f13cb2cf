"""Each assembled frame slid along its own surface to where the first frame's colours are (beyond
the thesis; ``Options.color_fit``).

Frame ``t``'s correspondence is a chain of ``t`` pair maps (5.3), so the small errors of every
map, the video's anchors' included, add up. The colours break the chain: each vertex takes its
colour from the first frame once, and in every later frame a per-vertex Lucas-Kanade on that
frame's coloured surface (:func:`fourd.appearance.photometric.photometric_shift`, the colour
guide of ``kinematic`` and ``garment``) says where along the surface that colour went. Against
the first frame, not the previous one, what it corrects does not add up.

Per frame ``t = 1 .. T - 1``, from the assembled positions moved by frame ``t - 1``'s
correction (the drift grows from frame to frame, so last frame's correction is most of this
one's):

1. the shifts of the vertices observed in frame ``t`` and in the first frame (about one per
   ``SAMPLE_SPACING`` edges), each weighted
   ``exp(-(uncertainty / scale)^2)`` (a patch of one colour, or one stripe, pins nothing);
2. a smooth correction ``d`` of every vertex: ``(W + smoothness L) d = W s`` (``L`` the mesh's
   uniform Laplacian, ``W`` the weights), so vertices without colour information, the filled-in
   ones included, move with their neighbours;
``iterations`` times; then the observed vertices are put back onto the frame's own surface
(closest point of its mesh), so every frame still conforms to its data. Colours come from the points (every frame coloured) or, without, from
the video; without either the frames are left as assembled.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from fourd.appearance.color_guide import colors_of_cleaned
from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import FIELD_POINTS_PER_READ, ColorField, field_for_reads
from fourd.cache import NO_CACHE, Chain, StageCache, report_resumed, stage_key
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.grid import one_per_cube
from fourd.geometry.laplacian import uniform_laplacian
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.normals import vertex_normals
from fourd.progress import progress

log = logging.getLogger("fourd.methods.assembly.color_fit")

#: The cache entries of the colour fit's frames.
STAGE = "assembly-color-fit"

#: The Lucas-Kanade runs at about one vertex per cube of this many edges (those observed in the
#: first frame); the smooth correction carries it to the rest.
SAMPLE_SPACING = 1.5


def frame_colors(seq, meshes) -> list[np.ndarray | None] | None:
    """Per frame, the colours ``[M_t, 3]`` of its mesh's vertices (``meshes``: per frame
    ``(vertices, faces)``): the nearest input point's when every frame's points have colours,
    else from ``seq.video``; None when the input has neither."""
    if all(frame.colors is not None for frame in seq.frames):
        return [colors_of_cleaned(frame.points, frame.colors, vertices) if len(vertices) else None
                for frame, (vertices, _) in zip(seq.frames, meshes, strict=True)]
    if getattr(seq, "video", None) is None:
        return None
    from fourd.appearance.point_colors import colors_from_video

    return [colors_from_video(seq, t, points=vertices, normals=vertex_normals(vertices, faces))
            if len(faces) else None for t, (vertices, faces) in enumerate(meshes)]


def _field(vertices, faces, colors, count: int) -> ColorField:
    return field_for_reads(vertices, vertex_normals(vertices, faces), colors, count)


def fit_colors(positions: np.ndarray, faces: np.ndarray, observed: np.ndarray, meshes, colors, *,
               radius: float = 5.0, scale: float = 0.5, smoothness: float = 10.0,
               iterations: int = 2, cache: StageCache = NO_CACHE) -> np.ndarray:
    """The assembled ``positions [T, N, 3]`` (mesh ``faces``, ``observed [T, N]``) slid along
    each frame's surface to where the first frame's colours are (module docstring).

    Parameters
    ----------
    meshes : list of (vertices [M_t, 3], faces [G_t, 3])
        Every frame's own surface.
    colors : list of (array [M_t, 3] or None)
        Colours in [0, 1] of those surfaces' vertices (:func:`frame_colors`); a frame without
        is left as it is.
    radius, scale : float
        The Lucas-Kanade's patch radius and the uncertainty that weighs a shift ``exp(-1)``,
        in the assembled mesh's median edges (first frame).
    smoothness : float
        Weight of the correction's Laplacian against the shifts' weights.
    iterations : int
        Shift and smooth rounds per frame.
    cache : StageCache
        Where each frame's result is kept (:data:`STAGE`, a :class:`~fourd.cache.Chain`: frame
        ``t``'s entry holds only after the same frames before it), so a stopped run resumes.

    Returns
    -------
    float64 [T, N, 3]
    """
    positions = np.array(positions, dtype=np.float64)
    count = positions.shape[1]
    if colors is None or colors[0] is None or not len(meshes[0][1]):
        return positions
    edge = median_edge_length(positions[0], faces)
    sample = np.flatnonzero(observed[0])
    sample = sample[one_per_cube(positions[0][sample], SAMPLE_SPACING * edge)]
    if len(sample) < 8:  # too little of the first frame observed to read its colours
        return positions
    reference = _field(*meshes[0], colors[0], len(sample)).sample(positions[0][sample])
    laplacian = uniform_laplacian(count, faces).tocsr()
    carried = np.zeros((count, 3))
    chain, done = None, []
    if cache.enabled:  # the keys hash every frame: only when there is a cache
        chain = Chain.of(cache, STAGE, stage_key(positions, faces, observed, meshes[0], colors[0], radius, scale,
                                                 smoothness, iterations, SAMPLE_SPACING, FIELD_POINTS_PER_READ),
                         [(meshes[t], colors[t]) for t in range(1, len(positions))])
        done = chain.prefix()
    for t, entry in enumerate(done, start=1):
        if not entry["skipped"]:
            carried = entry["positions"] - positions[t]
            positions[t] = entry["positions"]
    if done:
        report_resumed(log, f"{len(done)} of {len(positions) - 1} frames' colour fit")
    for t in progress(range(len(done) + 1, len(positions)), desc="assembly colour fit", unit="frame"):
        vertices, mesh_faces = meshes[t]
        if colors[t] is None or not len(mesh_faces):
            if chain is not None:
                chain.save(t - 1, {"positions": np.zeros((0, 3)), "skipped": np.True_})
            continue
        field = _field(vertices, mesh_faces, colors[t], len(sample))
        x = positions[t] + carried
        seen = observed[t]
        for _ in range(iterations):
            result = photometric_shift(x[sample], vertex_normals(x, faces)[sample], reference, field, radius=radius * edge)
            # a degenerate patch (a sheet's edge, too few neighbours) gives no shift
            usable = seen[sample] & np.isfinite(result.uncertainty) & np.isfinite(result.shift).all(axis=1)
            weight = np.zeros(count)
            weight[sample[usable]] = np.exp(-((result.uncertainty[usable] / (scale * edge)) ** 2))
            if weight.sum() < 1.0:
                break
            shift = np.zeros((count, 3))
            shift[sample[usable]] = result.shift[usable]
            system = (sp.diags(weight) + smoothness * laplacian + 1e-6 * sp.identity(count)).tocsc()
            factor = splu(system, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
            x = x + factor.solve(weight[:, None] * shift)
        x[seen] = closest_points_on_mesh(vertices, mesh_faces, x[seen]).points
        carried = x - positions[t]
        positions[t] = x
        if chain is not None:
            chain.save(t - 1, {"positions": x, "skipped": np.False_})
        log.debug("colour fit frame %d: median correction %.3f edges", t,
                  float(np.median(np.linalg.norm(carried, axis=1))) / edge)
    return positions
