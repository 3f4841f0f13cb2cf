"""Each assembled frame slid along its own surface towards the shape most as-rigid-as-possible
to the first frame's (beyond the thesis; ``Options.rest_fit``).

Frame ``t``'s correspondence is a chain of ``t`` pair maps (5.3). Each map's relaxation (5.4.3)
keeps the Laplacian coordinates of its source, frame ``t - 1`` as assembled, so whatever a map
slid or distorted is the next map's reference: nothing pulls it back, the maps' errors add up
and the mesh wears (its edges shrink and stretch along the chain, ``benchmarks/METHODS.md``).
This pass measures every frame against the first instead: a slide along the surface that
distorts the mesh away from the first frame's shape costs energy in every later frame, as the
template's deformation does in ``kinematic``.

Per frame ``t = 1 .. T - 1``, from the assembled positions moved by frame ``t - 1``'s
correction (the correction grows with the chain's drift, so the last frame's is most of this
one's), up to ``iterations`` rounds of ARAP-ICP (fewer once a round moves 90% of the vertices
less than :data:`SETTLED` edges) with the first frame as the rest shape (Sorkine and
Alexa 2007):

1. each vertex's rotation of its one-ring from the first frame to the current positions
   (:func:`fourd.geometry.rotations.one_ring_rotations`);
2. the positions solved from ``(L + w I) x = b + w p``: ``L`` the first frame's cotangent
   Laplacian (negative weights clamped), ``b`` the rotated rest edges
   (:func:`fourd.geometry.rotations.arap_right_hand_side`), ``p`` the closest point of the
   frame's own surface for the vertices observed in it and the current position for the
   others (a proximal term, so one factorisation serves every frame); ``w`` is ``weight``
   times ``L``'s median diagonal (not its mean: one sliver triangle's cotangent can be
   10^11). A small ``w`` lets the vertices slide along the surface (the closest point follows
   them) while the surface still holds them;

then the observed vertices are put back onto the frame's own surface (closest point of its
mesh), so every frame still conforms to its data.

References
----------
O. Sorkine, M. Alexa, "As-rigid-as-possible surface modeling", SGP 2007.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from fourd.cache import NO_CACHE, StageCache, stage_key
from fourd.geometry.closest_point import MeshLocator
from fourd.geometry.factors import (
    TriangularFactors,
    elimination_order,
    solve_ordered,
    unpermuted_factors,
)
from fourd.geometry.laplacian import cotangent_weights, weights_laplacian
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.rotations import arap_right_hand_side, one_ring_rotations
from fourd.methods.assembly.frame_fits import fit_frames

log = logging.getLogger("fourd.methods.assembly.rest_fit")

#: The cache entries of the rest fit's frames.
STAGE = "assembly-rest-fit"

#: Triangles (nearest centroids) each vertex tests for its closest point on the frame's surface:
#: the vertices lie within a fraction of an edge of it, where four find the closest triangle
#: (the same scores as sixteen on the 40 first crane frames at the sparse rig).
CANDIDATES = 4

#: A vertex's candidate triangles are searched again once it moved this many median edges of the
#: first frame since they were found.
REQUERY = 0.25

#: A frame's rounds stop once a round moved :data:`SETTLED_PERCENTILE` percent of the vertices
#: less than this many median edges of the first frame (the fit has settled; a hard frame takes
#: the rounds up to ``iterations``).
SETTLED = 0.01
#: The share of the vertices (percent) that :data:`SETTLED` is asked of. Not the median: a part
#: that still slides (crane's torso after a kick, a third of the vertices) kept sliding while
#: the rest had settled (``benchmarks/METHODS.md``, "The rest fit settles when 90% of the
#: vertices do").
SETTLED_PERCENTILE = 90.0


class RestFit:
    """The rest fit's state from one frame to the next (module docstring): the first frame's
    shape, its factorised ARAP system, and the correction the last fitted frame took (the next
    frame starts from it). :meth:`frame` fits the frames after the first, in order."""

    def __init__(
        self,
        first: np.ndarray,
        faces: np.ndarray,
        *,
        iterations: int = 16,
        weight: float = 0.03,
        settled: float = SETTLED,
    ):
        """The fit of the mesh ``faces`` to the shape ``first [N, 3]`` (the first frame as
        assembled); ``iterations``, ``weight`` and ``settled`` as :func:`fit_rest` has them."""
        self.first = np.ascontiguousarray(first, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.iterations, self.weight, self.settled = int(iterations), float(weight), float(settled)
        self.edge = median_edge_length(self.first, self.faces)
        self.edges = cotangent_weights(self.first, self.faces, clamp_negative=True).tocsr()
        laplacian = weights_laplacian(self.edges)
        diagonal = laplacian.diagonal()
        # the median over the vertices with edges (a vertex of no face has none)
        self.pull = self.weight * (
            float(np.median(diagonal[diagonal > 0])) if (diagonal > 0).any() else 1.0
        )
        system = (laplacian + self.pull * sp.identity(len(self.first))).tocsr()
        # nested-dissection order, no pivoting (symmetric positive definite), the three
        # coordinates back-substituted at once (fourd.geometry.factors)
        self.order = elimination_order(system)
        lu = splu(
            system[self.order][:, self.order].tocsc(),
            permc_spec="NATURAL",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
        self.factor = unpermuted_factors(lu) or lu
        self.carried = np.zeros_like(self.first)

    def key(self) -> str:
        """What the fit of a frame depends on besides that frame (for the cache)."""
        return stage_key(
            self.first, self.faces, self.iterations, self.weight, self.settled, SETTLED_PERCENTILE,
            CANDIDATES,
        )

    def resume(self, assembled: np.ndarray, fitted: np.ndarray) -> None:
        """Carry on after a frame fitted before (read from the cache): its ``assembled`` and
        ``fitted`` positions ``[N, 3]``."""
        self.carried = fitted - assembled

    def _solve(self, right: np.ndarray) -> np.ndarray:
        if isinstance(self.factor, TriangularFactors):
            return solve_ordered(self.factor, right, self.order)
        solved = np.empty_like(right)
        solved[self.order] = self.factor.solve(np.ascontiguousarray(right[self.order]))
        return solved

    def frame(self, assembled: np.ndarray, observed: np.ndarray, mesh) -> np.ndarray:
        """The next frame's ``assembled [N, 3]`` positions slid along its own surface ``mesh``
        (vertices, faces) towards the first frame's shape; ``observed [N]`` in that frame. A
        frame without a surface is left as assembled (moved by the last correction)."""
        x = np.asarray(assembled, dtype=np.float64) + self.carried
        vertices, mesh_faces = mesh
        seen = np.asarray(observed, dtype=bool)
        if len(mesh_faces) and seen.any():
            surface = MeshLocator(vertices, mesh_faces, CANDIDATES)
            # each vertex's candidate triangles, searched again once it moved REQUERY edges
            queried = x[seen]
            near = surface.nearest_triangles(queried)
            for _ in range(self.iterations):
                rotations = one_ring_rotations(self.edges, self.first, x)
                right = arap_right_hand_side(self.edges, self.first, rotations)
                on = x[seen]
                stale = np.linalg.norm(on - queried, axis=1) > REQUERY * self.edge
                if stale.any():
                    queried[stale] = on[stale]
                    near[stale] = surface.nearest_triangles(queried[stale])
                target = x.copy()
                target[seen] = surface.closest(on, near).points
                moved, x = x, self._solve(right + self.pull * target)
                if np.percentile(np.linalg.norm(x - moved, axis=1), SETTLED_PERCENTILE) < self.settled * self.edge:
                    break
            x[seen] = surface.closest(x[seen]).points
        self.carried = x - assembled
        return x


def fit_rest(
    positions: np.ndarray,
    faces: np.ndarray,
    observed: np.ndarray,
    meshes,
    *,
    iterations: int = 16,
    weight: float = 0.03,
    settled: float = SETTLED,
    cache: StageCache = NO_CACHE,
) -> np.ndarray:
    """The assembled ``positions [T, N, 3]`` (mesh ``faces``, ``observed [T, N]``) slid along
    each frame's surface towards the first frame's shape (module docstring).

    Parameters
    ----------
    meshes : list of (vertices [M_t, 3], faces [G_t, 3])
        Every frame's own surface.
    iterations : int
        ARAP-ICP rounds per frame at most (0: the positions as they are).
    weight : float
        The surface's pull against the ARAP energy, relative to the first frame's cotangent
        Laplacian's median diagonal: smaller lets the vertices slide further per round.
    settled : float
        A frame's rounds stop once one moved :data:`SETTLED_PERCENTILE` percent of the
        vertices less than this many median edges of the first frame.
    cache : StageCache
        Where each frame's result is kept (:data:`STAGE`, a :class:`~fourd.cache.Chain`: frame
        ``t``'s entry holds only after the same frames before it), so a stopped run resumes.

    Returns
    -------
    float64 [T, N, 3]
    """
    positions = np.array(positions, dtype=np.float64)
    if iterations <= 0 or len(positions) < 2:
        return positions
    fit = RestFit(positions[0], faces, iterations=iterations, weight=weight, settled=settled)
    return fit_frames(
        fit,
        positions,
        lambda t: fit.frame(positions[t], observed[t], meshes[t]),
        stage=STAGE,
        key=stage_key(fit.key(), positions, observed),
        inputs=[meshes[t] for t in range(1, len(positions))],
        label="rest fit",
        cache=cache,
    )
