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
from fourd.cache import NO_CACHE, StageCache, stage_key
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.grid import one_per_cube
from fourd.geometry.laplacian import uniform_laplacian
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.normals import vertex_normals
from fourd.methods.assembly.frame_fits import fit_frames

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


class ColorFit:
    """The colour fit's state from one frame to the next (module docstring): the first frame's
    colours at the sample vertices, the mesh's Laplacian, and the correction the last fitted
    frame took (the next frame starts from it). :meth:`start` makes it from the first frame;
    :meth:`frame` fits the frames after it, in order."""

    def __init__(self, faces: np.ndarray, sample: np.ndarray, reference: np.ndarray, edge: float, count: int, *,
                 radius: float = 5.0, scale: float = 0.5, smoothness: float = 10.0, iterations: int = 2):
        """The fit of a mesh of ``count`` vertices (``faces``) whose ``sample`` vertices read
        the first frame's log colours ``reference [S, 3]``; ``edge`` its median edge in the
        first frame; the rest as :func:`fit_colors` has them."""
        self.faces, self.sample, self.reference, self.edge = faces, sample, reference, edge
        self.radius, self.scale, self.smoothness, self.iterations = radius, scale, smoothness, iterations
        self.laplacian = uniform_laplacian(count, faces).tocsr()
        self.carried = np.zeros((count, 3))

    @classmethod
    def start(cls, first: np.ndarray, faces: np.ndarray, observed: np.ndarray, mesh, colors, *,
              radius: float = 5.0, scale: float = 0.5, smoothness: float = 10.0,
              iterations: int = 2) -> ColorFit | None:
        """The fit against the first frame: its assembled positions ``first [N, 3]`` (mesh
        ``faces``, ``observed [N]``), its own surface ``mesh`` (vertices, faces) and that
        surface's ``colors`` (or None). None when the first frame gives no colours to fit to
        (none, or too little of it observed); :func:`fit_colors` has the parameters."""
        if colors is None or not len(mesh[1]):
            return None
        edge = median_edge_length(first, faces)
        sample = np.flatnonzero(observed)
        sample = sample[one_per_cube(first[sample], SAMPLE_SPACING * edge)]
        if len(sample) < 8:  # too little of the first frame observed to read its colours
            return None
        reference = _field(*mesh, colors, len(sample)).sample(first[sample])
        return cls(faces, sample, reference, edge, len(first), radius=radius, scale=scale, smoothness=smoothness,
                   iterations=iterations)

    def key(self) -> str:
        """What the fit of a frame depends on besides that frame (for the cache)."""
        return stage_key(self.faces, self.sample, self.reference, self.edge, self.radius, self.scale,
                         self.smoothness, self.iterations, SAMPLE_SPACING, FIELD_POINTS_PER_READ)

    def resume(self, assembled: np.ndarray, fitted: np.ndarray) -> None:
        """Carry on after a frame fitted before (read from the cache): its ``assembled`` and
        ``fitted`` positions ``[N, 3]``."""
        self.carried = fitted - assembled

    def frame(self, assembled: np.ndarray, observed: np.ndarray, mesh, colors) -> np.ndarray | None:
        """The next frame's ``assembled [N, 3]`` positions slid to the first frame's colours
        (``observed [N]`` in that frame; its own surface ``mesh`` and that surface's
        ``colors``); None for a frame without colours, left as assembled."""
        vertices, mesh_faces = mesh
        if colors is None or not len(mesh_faces):
            return None
        faces, sample, edge, count = self.faces, self.sample, self.edge, len(assembled)
        field = _field(vertices, mesh_faces, colors, len(sample))
        x = assembled + self.carried
        for _ in range(self.iterations):
            result = photometric_shift(x[sample], vertex_normals(x, faces)[sample], self.reference, field,
                                       radius=self.radius * edge)
            # a degenerate patch (a sheet's edge, too few neighbours) gives no shift
            usable = observed[sample] & np.isfinite(result.uncertainty) & np.isfinite(result.shift).all(axis=1)
            weight = np.zeros(count)
            weight[sample[usable]] = np.exp(-((result.uncertainty[usable] / (self.scale * edge)) ** 2))
            if weight.sum() < 1.0:
                break
            shift = np.zeros((count, 3))
            shift[sample[usable]] = result.shift[usable]
            system = (sp.diags(weight) + self.smoothness * self.laplacian + 1e-6 * sp.identity(count)).tocsc()
            factor = splu(system, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
            x = x + factor.solve(weight[:, None] * shift)
        x[observed] = closest_points_on_mesh(vertices, mesh_faces, x[observed]).points
        self.carried = x - assembled
        log.debug("colour fit: median correction %.3f edges", float(np.median(np.linalg.norm(self.carried, axis=1))) / edge)
        return x


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
    if colors is None:
        return positions
    fit = ColorFit.start(positions[0], faces, observed[0], meshes[0], colors[0], radius=radius, scale=scale,
                         smoothness=smoothness, iterations=iterations)
    if fit is None:
        return positions
    return fit_frames(fit, positions, lambda t: fit.frame(positions[t], observed[t], meshes[t], colors[t]),
                      stage=STAGE, key=stage_key(fit.key(), positions, observed),
                      inputs=[(meshes[t], colors[t]) for t in range(1, len(positions))], label="colour fit",
                      cache=cache)
