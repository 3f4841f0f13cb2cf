"""Anchors from geometry alone: a coarse non-rigid alignment of the source onto the target,
then closest points (the fallback of thesis section 5.4, "without any correspondences,
geometric proximity is the only way to initialize such a parameterization"; the thesis takes
its anchors from optical flow, 5.4.1, which scans without video do not have). Anchors from the
video or the user (:mod:`~fourd.methods.assembly.guides`), when given, pull the non-rigid
alignment point to point and join the anchors.

1. Rigid ICP: the source is moved by the trimmed point-to-plane ICP of
   :func:`fourd.geometry.icp.rigid_icp` (pairs whose normals disagree or that lie beyond the
   85th percentile of the gaps left out), from two starts.
2. Non-rigid ICP (:func:`nonrigid_icp`): as-rigid-as-possible ICP with correspondences both
   ways, mostly point-to-plane so that a surface can slide along itself, and a search radius
   shrinking from far beyond a limb's step, so that a limb that moved several of its widths
   moves as a whole instead of its vertices sliding onto the nearest surface (the recipe of
   ``kinematic``'s large-motion registration, after Sorkine and Alexa 2007 and Li, Sumner and
   Pauly 2008).
3. Anchors: spread source vertices (about one per ``spacing`` source edges) whose aligned
   position lies within ``gap`` edges of the target, each matched to its closest target point
   on the triangles; then the forward-backward check of 5.4.1
   (:func:`~fourd.methods.assembly.anchors.consistent_anchors`), the backward map of a target
   vertex being the source position of the aligned source vertex nearest it, and a final
   :func:`~fourd.methods.assembly.anchors.spread_anchors`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg, splu
from scipy.spatial import cKDTree

from fourd.geometry.boundary_loops import boundary_edges
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.decimation import decimate
from fourd.geometry.icp import rigid_icp as point_to_plane_icp
from fourd.geometry.laplacian import uniform_laplacian
from fourd.geometry.meshes import median_edge_length, mesh_arrays
from fourd.geometry.normals import vertex_normals
from fourd.geometry.projector_sums import projector_sums
from fourd.geometry.rotations import arap_right_hand_side, one_ring_rotations, procrustes
from fourd.methods.assembly.anchors import (
    Anchors,
    consistent_anchors,
    returned_points,
    spread_anchors,
)
from fourd.methods.assembly.guides import MatchedGuides

#: Least cosine between a source and a target normal for their vertices to match.
NORMAL_AGREEMENT = 0.3

#: Relative tolerance of the ARAP-ICP's conjugate gradients (on each step's update).
CG_TOLERANCE = 1e-2

#: The ARAP-ICP's search radius at its first and its last stiff iteration (source edges).
START_RADIUS, END_RADIUS = 40.0, 3.0

#: Sources smaller than this align at their own resolution whatever ``coarse`` says (at 0.75
#: the coarse mesh keeps at least 2,000 vertices; bending-arm's 1,042 at a quarter lost the
#: forearm).
COARSE_VERTICES = 8000

#: The coarse alignment's stiff iterations, per stiff iteration asked for.
COARSE_ITERATIONS = 2

#: Stiff iterations in a row that must move 99% of the vertices less than ``settle`` before
#: the schedule skips to its last this many stiff iterations (:func:`nonrigid_icp`).
SETTLED_ITERATIONS = 3

#: Source points each rigid ICP fit uses at most (about: an even subset). A rigid motion needs
#: few: on crane's and dfaust-hopping's pairs (29,000-35,000 vertices) 5,000 move every vertex
#: within 0.03-0.2 edges of the fit on all of them, in a quarter of the time.
RIGID_POINTS = 5000
#: A rigid start keeps its rotation only when that lowers the rms of a translation alone by
#: more than this fraction (:func:`fourd.geometry.icp.rigid_icp`'s ``rotation_evidence``): a
#: turn the surface does not determine (the spin of a ball, lowering the rms by 0-1%) stays in
#: the correspondences, while a galloping body's real turns of 1-3 degrees lower it by 0-16%.
START_EVIDENCE = 0.02
#: Nor when it turns by more than this many degrees: the two frames of a merge are adjacent
#: frames of a capture, not a twelfth of a turn apart, and such a turn is an ICP minimum a
#: deformation chose (a ball squashing from prolate to oblate matches itself turned on its side).
MAX_START_TURN = 30.0


class Alignment(NamedTuple):
    """The result of :func:`geometric_anchors`.

    anchors : Anchors
    aligned : float64 [N, 3]
        The source vertices after the coarse non-rigid alignment (target's frame).
    edge : float
        The source's median edge length (input units).
    past_rim : bool [N]
        Source vertices whose aligned position lies past a hole of the target: the nearest
        target vertex is on the target's boundary and more than ``gap`` source edges away.
        No map may place them (the target has no surface for them; a patch map near a hole
        pressed them into the rim's triangles, up to 4.6 edges off).
    """

    anchors: Anchors
    aligned: np.ndarray
    edge: float
    past_rim: np.ndarray


def _pairs(points, normals, tree, target_normals):
    """Nearest target vertex of each point, and whether the pair is usable (normals within
    about 70 degrees, gap under three times the median)."""
    gap, nearest = tree.query(points, workers=-1)
    agree = np.einsum("ij,ij->i", normals, target_normals[nearest]) > NORMAL_AGREEMENT
    usable = agree & (gap <= 3.0 * np.median(gap[agree]) + 1e-12) if agree.any() else agree
    return gap, nearest, usable


def rigid_icp(source, source_normals, target, target_normals, *, iterations: int = 10,
              tree: cKDTree | None = None) -> np.ndarray:
    """``source [N, 3]`` moved rigidly onto the target's vertices ``[M, 3]`` (step 1 of the
    module docstring, :func:`fourd.geometry.icp.rigid_icp`); returns the moved points
    ``[N, 3]``. ICP runs twice, from where the source is and with its centroid moved onto the
    target's, and the fit with the smaller median gap wins (a part that moves alone, an arm
    bending, drags the centroid away); a fit whose turn explains less than
    :data:`START_EVIDENCE` of the rms, or turns by more than :data:`MAX_START_TURN`, is a
    translation instead. Each fit uses an even subset of at most about
    :data:`RIGID_POINTS` source points. ``tree``: the target's k-d tree, when the caller has it."""
    tree = cKDTree(target) if tree is None else tree
    best, best_gap = source, np.inf
    every = max(1, len(source) // RIGID_POINTS)
    for start in (source, source - source.mean(axis=0) + target.mean(axis=0)):
        fit = point_to_plane_icp(start[::every], target, target_normals, source_normals=source_normals[::every],
                                 iterations=iterations, rotation_evidence=START_EVIDENCE,
                                 max_turn=MAX_START_TURN)
        moved = start @ fit.rotation.T + fit.translation
        gap, _, usable = _pairs(moved, source_normals @ fit.rotation.T, tree, target_normals)
        median = float(np.median(gap[usable])) if usable.any() else np.inf
        if median < best_gap:
            best, best_gap = moved, median
    return best


def _rim(faces: np.ndarray, count: int) -> np.ndarray:
    """Boundary vertices, bool ``[count]``."""
    rim = np.zeros(count, dtype=bool)
    rim[boundary_edges(faces, count).ravel()] = True
    return rim


def _data_terms(x, normals, target, target_normals, tree, limit, source_rim, point_to_point):
    """Each vertex's data term ``|Q_i^(1/2) (x_i - y_i)|^2`` as ``Q [N, 3, 3]`` and
    ``Q y [N, 3]``: the mean over its nearest target vertex and the target vertices whose
    nearest vertex it is, all within ``limit`` with normals that agree, of
    ``(1 - point_to_point) n n^T + point_to_point I`` (``n`` the target vertex's normal; zero
    for a vertex without pairs). The point-to-plane part lets a surface slide along itself: a
    goal fixed at the projection onto the tangent plane pins the vertex's tangential position,
    and a trunk that rises by a hop then follows only at its top and bottom. A source rim
    vertex's own pair is point-to-point: across a hole there is no plane to slide in (with
    0.03 everywhere a cap pasted into a hole was placed 0.37-0.50 edges off instead of 0.14).
    A target vertex whose nearest vertex is on the source's boundary (``source_rim``, bool
    ``[N]``) does not pull: it lies past a hole of the source, and its pull would drag the
    hole's rim over the target's surface (Turk and Levoy 1994). The other way, leaving out the
    pairs with the target's rim too cost crane's correspondence 0.0077 / 0.0108 -> 0.0092 /
    0.0140 (``benchmarks/METHODS.md``)."""
    count = len(x)
    gap, nearest = tree.query(x, distance_upper_bound=limit, workers=-1)
    found = np.isfinite(gap)
    nearest = np.where(found, nearest, 0)
    found &= np.einsum("ij,ij->i", normals, target_normals[nearest]) > NORMAL_AGREEMENT
    # built every iteration: unbalanced builds in half the time, the same neighbours
    back_gap, back = cKDTree(x, balanced_tree=False).query(target, distance_upper_bound=limit, workers=-1)
    pulls = np.isfinite(back_gap)
    back = np.where(pulls, back, 0)
    pulls &= (np.einsum("ij,ij->i", normals[back], target_normals) > NORMAL_AGREEMENT) & ~source_rim[back]
    owner = np.concatenate([np.flatnonzero(found), back[pulls]])
    paired = np.concatenate([nearest[found], np.flatnonzero(pulls)])
    own_pair = np.arange(len(owner)) < found.sum()  # the vertex's nearest, not a pull back
    share = np.where(source_rim[owner] & own_pair, 1.0, point_to_point)
    sums = projector_sums(owner, target[paired], 1.0, count, directions=target_normals[paired], identity=share,
                          outer=1.0 - share)
    pairs = np.maximum(sums.counts, 1).astype(np.float64)
    return sums.blocks / pairs[:, None, None], sums.right / pairs[:, None]


def nonrigid_icp(
    source: np.ndarray,
    faces: np.ndarray,
    target: np.ndarray,
    target_normals: np.ndarray,
    start: np.ndarray,
    *,
    iterations: int = 50,
    weight: float = 0.001,
    start_radius: float = START_RADIUS,
    end_radius: float = END_RADIUS,
    relaxation: float = 0.8,
    refine_iterations: int = 3,
    refine_weight: float = 0.03,
    point_to_point: float = 0.05,
    settle: float = 0.0,
    tree: cKDTree | None = None,
    pins: tuple[np.ndarray, np.ndarray] | None = None,
    pin_weight: float = 1.0,
) -> np.ndarray:
    """The source ``[N, 3]`` (mesh ``faces``) registered onto the target's vertices ``[M, 3]``
    with unit ``target_normals``, from the positions ``start [N, 3]``: as-rigid-as-possible
    ICP (step 2 of the module docstring). Returns the registered positions ``[N, 3]``.

    Each iteration, with the search radius shrinking geometrically from ``start_radius`` to
    ``end_radius`` (source median edges), every vertex takes the data term of
    :func:`_data_terms` (``point_to_point`` of the squared distance to its pairs, the rest the
    squared distance along their normals: the mix of Li, Sumner and Pauly 2008; at 0.1 a tube
    9 radii long followed 0.69 of a slide along its axis, at 0.05 all of it) and the
    positions minimise ``E_ARAP + w sum_i |Q_i^(1/2) (x_i - y_i)|^2`` (uniform edge weights, the
    rotations of the current positions; conjugate gradients on the ``3N`` unknowns,
    preconditioned by the factorisation of ``L + w I``), over-relaxed by ``relaxation`` (a
    stiff template creeps towards a limb's new place by a near-constant step). ``weight`` is
    ``w`` relative to the Laplacian's mean diagonal: small, so a limb moves as a whole. Then
    ``refine_iterations`` at ``end_radius`` with the softer ``refine_weight`` follow what did
    not move rigidly. Measured in ``benchmarks/METHODS.md`` ("Where the 20-frame crane drifts"
    and "Where dfaust-hopping drifts"). ``settle`` (source edges; 0: never): once
    :data:`SETTLED_ITERATIONS` stiff iterations in a row solved a step (before the
    over-relaxation) of less than this for 99% of the vertices, the template has come to rest, and the schedule goes on with its last
    :data:`SETTLED_ITERATIONS` stiff iterations (the smallest radii: pairs that only a large
    radius finds, across a gap that opened, let go there) and the refining ones. ``tree``:
    the target's k-d tree, when the caller has it. ``pins`` (vertex ids ``[K]``, points
    ``[K, 3]``): vertices with a known place on the target (anchors from the video or the
    user), each pulled towards it point to point with ``pin_weight`` times a full data term,
    every iteration: they give the tangential pull the point-to-plane data lacks.
    """
    count = len(source)
    laplacian = uniform_laplacian(count, faces).tocsr()
    edges = abs(laplacian - sp.diags(laplacian.diagonal())).tocsr()
    scale = float(laplacian.diagonal().mean())
    edge = median_edge_length(source, faces)
    tree = cKDTree(target) if tree is None else tree
    source_rim = _rim(faces, count)
    factors = {}
    schedule = [(start_radius * (end_radius / start_radius) ** (k / max(iterations - 1, 1)), weight, k > 0)
                for k in range(iterations)]
    schedule += [(end_radius, refine_weight, False)] * refine_iterations
    x = np.array(start, dtype=np.float64)
    shape = (3 * count, 3 * count)
    resting = 0
    for index, (radius, relative, relax) in enumerate(schedule):
        if index < iterations - SETTLED_ITERATIONS and resting >= SETTLED_ITERATIONS:
            continue
        w = relative * scale
        if w not in factors:
            factors[w] = splu((laplacian + w * sp.identity(count)).tocsc(), permc_spec="MMD_AT_PLUS_A",
                              diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        quadric, goal = _data_terms(x, vertex_normals(x, faces), target, target_normals, tree, radius * edge,
                                    source_rim, point_to_point)
        if pins is not None and len(pins[0]):
            quadric[pins[0]] += pin_weight * np.eye(3)
            goal[pins[0]] += pin_weight * pins[1]
        rhs = arap_right_hand_side(edges, source, one_ring_rotations(edges, source, x)) + w * goal

        def apply(v, w=w, quadric=quadric):
            v = v.reshape(count, 3)
            return (laplacian @ v + w * np.einsum("nij,nj->ni", quadric, v)).ravel()

        solve = factors[w].solve
        # the update from x, to a tolerance relative to x's residual: the right-hand side is
        # dominated by the rest shape's Laplacian, and a tolerance relative to it would stop
        # before the slow modes (a tube sliding along itself) move at all
        residual = rhs.ravel() - apply(x.ravel())
        update, _ = cg(LinearOperator(shape, matvec=apply, dtype=np.float64), residual, rtol=CG_TOLERANCE,
                       maxiter=100, M=LinearOperator(shape, matvec=lambda v, solve=solve: solve(v.reshape(count, 3)).ravel(),
                                                     dtype=np.float64))
        update = update.reshape(count, 3)
        step = x + update
        x = step + relaxation * (step - x) if relax else step
        if settle > 0.0:
            moved = np.percentile(np.einsum("ij,ij->i", update, update), 99.0)
            resting = resting + 1 if moved < (settle * edge) ** 2 else 0
    return x


def _coarse_then_fine(source, faces, target, target_normals, rigid, tree, edge, reduction, *, iterations, weight,
                      settle=0.0, pins=None, pin_weight=1.0):
    """:func:`nonrigid_icp`'s stiff iterations on the decimated source, its soft ones on the
    source itself, from the rigidly aligned ``rigid`` (:func:`geometric_anchors`' ``coarse``);
    ``pins`` pull in the soft ones only."""
    coarse = decimate(source, faces, reduction)
    fit = procrustes(source, rigid)
    start = coarse.vertices @ fit.rotation.T + fit.translation
    ratio = edge / median_edge_length(coarse.vertices, coarse.faces)
    # uniform edge weights: a bend costs the coarse mesh's ARAP term 1 / ratio^2 times the
    # fine one's against the same data, so the data weight grows by as much (crane: the
    # same weight left the limbs behind, correspondence 0.0062 / 0.0090 -> 0.0075 / 0.0101)
    # and it creeps towards a swung limb by smaller steps: bending-arm's forearm stayed 13
    # edges behind after 50 iterations at half the faces, within 5 after 100, 3.9 after 200
    moved = nonrigid_icp(coarse.vertices, coarse.faces, target, target_normals, start,
                         iterations=COARSE_ITERATIONS * iterations,
                         weight=weight / ratio**2, start_radius=START_RADIUS * ratio, end_radius=END_RADIUS * ratio,
                         refine_iterations=0, settle=settle * ratio, tree=tree)
    # the non-rigid part only: inverse-distance weights reproduce a translation, not a turn
    followed = rigid + coarse.carry(moved - start + coarse.vertices)
    return nonrigid_icp(source, faces, target, target_normals, followed, iterations=0, tree=tree, pins=pins,
                        pin_weight=pin_weight)


def geometric_anchors(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    *,
    spacing: float = 2.0,
    gap: float = 1.0,
    tolerance: float = 1.5,
    rigid_iterations: int = 10,
    iterations: int = 50,
    weight: float = 0.001,
    coarse: float = 0.0,
    settle: float = 0.0,
    seed: int = 0,
    guides: MatchedGuides | None = None,
    guide_pull: float = 16.0,
) -> Alignment:
    """Anchors from the source to the target by a coarse non-rigid alignment (module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
        Both meshes oriented the same way.
    spacing : float
        Anchors about this far apart on the source (source edges; 2: about 9% of the vertices,
        which the patch map needs to reach most vertices without flow anchors, see
        ``benchmarks/METHODS.md``).
    gap : float
        Largest distance from an aligned source vertex to the target for it to become an
        anchor (source edges).
    tolerance : float
        Forward-backward tolerance (source edges).
    rigid_iterations, iterations : int
        Rigid and non-rigid (:func:`nonrigid_icp`) ICP iterations.
    weight : float
        Data weight of the non-rigid ICP's stiff iterations (:func:`nonrigid_icp`).
    coarse : float
        When above 0 (and the source has at least :data:`COARSE_VERTICES` vertices), the
        stiff iterations run on the source decimated by this fraction of its faces
        (:func:`fourd.geometry.decimation.decimate`), :data:`COARSE_ITERATIONS` times as
        many, the search radii kept in the source's own edges and the data weight scaled by
        the squared edge ratio; the fine source follows the coarse one's non-rigid
        displacements, then takes the soft iterations itself.
    settle : float
        :func:`nonrigid_icp`'s ``settle`` (source edges; 0: every stiff iteration runs).
    seed : int
        Seed of the anchors' spreading.
    guides : MatchedGuides, optional
        Anchors from the video or the user (:func:`~fourd.methods.assembly.guides.guide_anchors`):
        they pull the non-rigid alignment (:func:`nonrigid_icp`'s ``pins``, ``guide_pull``
        times a data term), and those the alignment lands within ``tolerance`` of join the
        anchors, kept before the geometric ones where the two crowd.
    guide_pull : float
        Their weight in the alignment.

    Returns
    -------
    Alignment
    """
    source, sfaces = mesh_arrays(source_vertices, source_faces)
    target, tfaces = mesh_arrays(target_vertices, target_faces)
    edge = median_edge_length(source, sfaces)
    target_normals = vertex_normals(target, tfaces)
    source_normals = vertex_normals(source, sfaces)
    tree = cKDTree(target)
    aligned = rigid_icp(source, source_normals, target, target_normals, iterations=rigid_iterations, tree=tree)
    pins = None if guides is None or not len(guides.vertices) else (guides.vertices, guides.points)
    if coarse > 0.0 and len(source) >= COARSE_VERTICES:
        aligned = _coarse_then_fine(source, sfaces, target, target_normals, aligned, tree, edge, coarse,
                                    iterations=iterations, weight=weight, settle=settle, pins=pins,
                                    pin_weight=guide_pull)
    else:
        aligned = nonrigid_icp(source, sfaces, target, target_normals, aligned, iterations=iterations, weight=weight,
                               settle=settle, tree=tree, pins=pins, pin_weight=guide_pull)

    # anchors: near candidates, oversampled, checked, then spread to the final density
    normals = vertex_normals(aligned, sfaces)
    distance, nearest, usable = _pairs(aligned, normals, tree, target_normals)
    past_rim = _rim(tfaces, len(target))[nearest] & (distance > gap * edge)
    candidates = np.flatnonzero(usable & (distance <= gap * edge + edge))
    followed = _followed_guides(guides, aligned, tolerance * edge)
    if len(candidates) < 3:
        return Alignment(followed, aligned, edge, past_rim)
    dense = Anchors(candidates, candidates, np.zeros((len(candidates), 3)))
    candidates = candidates[spread_anchors(dense, source, 0.5 * spacing * edge, priority=-distance[candidates],
                                           seed=seed)]
    triangle, bary, _, exact = closest_points_on_mesh(target, tfaces, aligned[candidates])
    anchors = Anchors(candidates, triangle, bary)
    near = exact <= gap * edge
    _, back = cKDTree(aligned).query(target, workers=-1)
    ok = near & consistent_anchors(anchors, source, returned_points(anchors, tfaces, source[back]), tolerance * edge)
    anchors = Anchors.join(followed, anchors.subset(ok))
    # the guides first, then the geometric anchors nearest the target
    priority = np.r_[np.full(len(followed.source), np.inf), -exact[ok]]
    kept = spread_anchors(anchors, source, spacing * edge, priority=priority, seed=seed)
    return Alignment(anchors.subset(kept), aligned, edge, past_rim)


def _followed_guides(guides: MatchedGuides | None, aligned: np.ndarray, tolerance: float) -> Anchors:
    """The anchors of the ``guides`` whose source vertex the alignment brought within
    ``tolerance`` of its point (the others disagree with the motion around them)."""
    if guides is None or not len(guides.vertices):
        return Anchors(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))
    near = np.linalg.norm(aligned[guides.vertices] - guides.points, axis=1) <= tolerance
    return guides.anchors.subset(near)
