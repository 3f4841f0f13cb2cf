"""Hierarchical assembly of a consistent frame sequence (thesis section 5.3, figure 5.2), with
the propagation of section 5.6.

A :class:`Block` is a consistent sub-sequence: one connectivity, positions in each of its
frames. At the bottom level every frame's own mesh is a block of length one; each level merges
consecutive pairs of blocks (lengths 1, 2, 4, ...; an odd last block waits for the next
level), so after ``ceil(log2 T)`` levels one block holds the whole sequence.

:func:`merge_blocks` maps the left block's last frame (the source) onto the right block's
first (the target) with :func:`~fourd.methods.assembly.pair.cross_parameterize_pair`, its
anchors from a coarse non-rigid alignment
(:func:`~fourd.methods.assembly.alignment.geometric_anchors`). The merged block keeps the
left connectivity (the union mesh of 5.6 starts from the source's). A mapped source vertex
lies in a target triangle with barycentric coordinates; since the right block is already
consistent, the same triangle and coordinates give its position in every right frame. The
vertices the map cannot place (geometry only the source has) are placed in each right frame
by the source's Laplacian coordinates with the mapped vertices held
(:func:`~fourd.methods.assembly.registration.register_by_laplacian`, [LSA+05]) and marked
unobserved there. A connected piece with no mapped vertex at all follows the rigid motion
that best fits the mapped vertices (also unobserved).

With ``correct`` on, the map is first analysed (5.5,
:func:`~fourd.methods.assembly.analysis.inconsistent_regions`) and the vertices of its
inconsistent regions unmapped, so the registration places them from the source's geometry
(the thesis' first scenario, the source region pasted into the target). A region whose
placement fails the stretch test (:func:`~fourd.methods.assembly.analysis.passes_stretch_test`)
is deleted from the union, so the target's geometry there is pasted in its place (below; the
second scenario), kept if the pasted patch passes the same test from the target frame to the
source frame, else removed too: the region is then deleted from both. Off by default, see
``benchmarks/METHODS.md``.

With ``paste`` on, geometry only the target has (a hole of the source's scan) is glued into
the union mesh (the second half of 5.6, :mod:`~fourd.methods.assembly.completion`): its
positions in the right frames are the right block's own, in the left frames placed by the
Laplacian coordinates of the union in the target frame, unobserved.

Merges of one level are independent (5.3) and run side by side in processes
(``Options.workers``; by default one per core for frames big enough to pay for it). A merge is
its pair map (:func:`map_pair`, nearly all the work), which needs only the left block's last
frame and the right block's first, then the join (:func:`join_blocks`). Each map starts as
soon as its frames are there: with ``paste`` and ``correct`` off a block's first frame is its
first frame's own mesh, so the map of the last merge runs beside the last merge of its right
half instead of alone after it (:func:`_merge_as_ready`).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.cache import StageCache, report_resumed
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.rotations import procrustes
from fourd.methods.assembly.alignment import geometric_anchors
from fourd.methods.assembly.analysis import inconsistent_regions, passes_stretch_test
from fourd.methods.assembly.completion import Paste, paste_target_only, place_pasted
from fourd.methods.assembly.guides import Guide, guide_anchors
from fourd.methods.assembly.merge_map import MergeMap, load_map, map_key, save_map
from fourd.methods.assembly.options import Options
from fourd.methods.assembly.pair import cross_parameterize_pair
from fourd.methods.assembly.registration import register_by_laplacian
from fourd.pipeline.merge_tree import merge_tree
from fourd.pipeline.worker_threads import one_blas_thread, threads_per_worker

log = logging.getLogger("fourd.methods.assembly.hierarchy")


class Block(NamedTuple):
    """A consistent sub-sequence.

    faces : int64 [F, 3]
    vertices : float64 [T, N, 3]
        Positions in each of its frames (input units).
    observed : bool [T, N]
        False where a vertex was placed by registration rather than found on that frame's
        surface.
    """

    faces: np.ndarray
    vertices: np.ndarray
    observed: np.ndarray


class MergeReport(NamedTuple):
    """Figures of one merge.

    anchors : int
        Geometric anchors the pair map started from.
    mapped : float
        Fraction of the source's vertices the pair map placed on the target.
    rigid : float
        Fraction left to the rigid fallback (pieces with no mapped vertex).
    flagged : int
        Mapped vertices unmapped by the analysis (``correct``).
    pasted : int
        Vertices of target-only geometry glued into the union mesh (``paste``), replacements
        of inconsistent regions included.
    regions : int
        Inconsistent regions the analysis found (``correct``).
    replaced : int
        Of those, regions whose source geometry failed the stretch test and whose target
        geometry, pasted in their place, passed it.
    deleted : int
        Regions where neither passed: deleted from both.
    """

    anchors: int
    mapped: float
    rigid: float
    flagged: int = 0
    pasted: int = 0
    regions: int = 0
    replaced: int = 0
    deleted: int = 0


def _closest_map(aligned, target_vertices, target_faces):
    """Target triangle and barycentric coordinates of the point closest to each of
    ``aligned [N, 3]`` (the fallback map when the pair map places almost nothing)."""
    found = closest_points_on_mesh(target_vertices, target_faces, aligned)
    return found.triangle, found.barycentric


@one_blas_thread()
def map_pair(source: np.ndarray, faces: np.ndarray, target: np.ndarray, target_faces: np.ndarray,
             options: Options | None = None, guide: Guide | None = None) -> MergeMap:
    """The first half of a merge (module docstring): the source frame ``[N, 3]`` (mesh
    ``faces``) mapped onto the target frame ``[M, 3]`` (mesh ``target_faces``) by anchors from
    the coarse alignment and the pair's cross-parameterisation, with the map analysed and its
    inconsistent regions unmapped when ``correct`` is on. It needs only those two frames, so a
    merge's map can be made while the right block is still being assembled (when its first
    frame is final, :func:`_merge_as_ready`). ``guide``: anchors of this frame pair from the
    video or the user (:mod:`~fourd.methods.assembly.guides`), which pull the alignment and
    join its anchors. BLAS runs one thread here, so that a map is the same whichever process
    made it (:mod:`fourd.pipeline.worker_threads`)."""
    options = Options() if options is None else options
    matched = None
    if guide is not None and len(guide.source):
        gap = options.anchor_gap * median_edge_length(source, faces)
        matched = guide_anchors(guide, source, target, target_faces, gap)
    alignment = geometric_anchors(
        source, faces, target, target_faces,
        spacing=options.anchor_spacing, gap=options.anchor_gap, tolerance=options.anchor_tolerance,
        iterations=options.alignment_iterations, weight=options.alignment_weight,
        coarse=options.alignment_coarse, settle=options.alignment_settle, seed=options.seed,
        guides=matched, guide_pull=options.guide_pull,
    )
    count = len(source)
    if len(alignment.anchors.source) >= 3:
        pair = cross_parameterize_pair(source, faces, target, target_faces, alignment.anchors, options.pair_options())
        map_faces, bary = pair.faces, pair.barycentric
    else:
        map_faces, bary = np.full(count, -1), np.zeros((count, 3))
    mapped = (map_faces >= 0) & ~alignment.past_rim
    image = np.einsum("nk,nkd->nd", bary[mapped], target[target_faces[map_faces[mapped]]])
    mapped[mapped] = np.linalg.norm(image - alignment.aligned[mapped], axis=1) <= options.map_agreement * alignment.edge
    analysis = None
    if options.correct and mapped.sum() >= 3:
        points = np.full((count, 3), np.nan)
        points[mapped] = np.einsum("nk,nkd->nd", bary[mapped], target[target_faces[map_faces[mapped]]])
        analysis = inconsistent_regions(source, faces, points, mapped, stretch=options.correct_stretch,
                                        motion=options.correct_motion)
        mapped &= ~analysis.flagged
    if mapped.sum() < 3:
        log.warning("pair map placed %d of %d vertices: closest points of the coarse alignment instead",
                    int(mapped.sum()), count)
        map_faces, bary = _closest_map(alignment.aligned, target, target_faces)
        mapped = np.ones(count, dtype=bool)
    return MergeMap(len(alignment.anchors.source), map_faces, bary, mapped, analysis)


def _map_or_resume(source, faces, target, target_faces, options: Options, guide: Guide | None):
    """:func:`map_pair`, read from ``options.cache_dir`` when it holds this map and stored there
    when not (:mod:`~fourd.methods.assembly.merge_map`): ``(map, whether it was read)``."""
    if options.cache_dir is None:
        return map_pair(source, faces, target, target_faces, options, guide), False
    cache, key = StageCache(options.cache_dir), map_key(source, faces, target, target_faces, options, guide)
    stored = load_map(cache, key)
    if stored is not None:
        return stored, True
    pair = map_pair(source, faces, target, target_faces, options, guide)
    save_map(cache, key, pair)
    return pair, False


def merge_blocks(left: Block, right: Block, options: Options | None = None,
                 guide: Guide | None = None) -> tuple[Block, MergeReport]:
    """Merge two consecutive blocks into one (module docstring): :func:`map_pair` of the
    left block's last frame onto the right block's first, then :func:`join_blocks`.

    Parameters
    ----------
    left, right : Block
        ``left``'s last frame comes just before ``right``'s first.
    options : Options, optional
    guide : Guide, optional
        Anchors of that frame pair from the video or the user (:func:`map_pair`).

    Returns
    -------
    Block
        ``left.faces`` (the pasted patches' faces after them), with ``len(left) + len(right)``
        frames of positions.
    MergeReport
    """
    options = Options() if options is None else options
    pair = map_pair(left.vertices[-1], left.faces, right.vertices[0], right.faces, options, guide)
    return join_blocks(left, right, pair, options)


def join_blocks(left: Block, right: Block, pair: MergeMap, options: Options | None = None) -> tuple[Block, MergeReport]:
    """The second half of a merge (module docstring): ``pair``, the map of ``left``'s last
    frame onto ``right``'s first (:func:`map_pair`), carried through every frame of
    ``right``, the unmapped vertices placed by registration, and the union mesh of the two
    blocks (with the inconsistent regions' replacements and the pasted patches when on).
    Returns what :func:`merge_blocks` returns."""
    options = Options() if options is None else options
    source, faces = left.vertices[-1], left.faces
    target, target_faces = right.vertices[0], right.faces
    count = len(source)
    map_faces, bary, mapped, analysis = pair.faces, pair.barycentric, pair.mapped, pair.analysis
    flagged = int(analysis.flagged.sum()) if analysis is not None else 0
    corners = right.faces[map_faces[mapped]]  # [K, 3]
    carried = np.einsum("kc,tkcd->tkd", bary[mapped], right.vertices[:, corners])
    frames = len(right.vertices)
    vertices = np.empty((frames, count, 3))
    observed = np.zeros((frames, count), dtype=bool)
    observed[:, mapped] = right.observed[:, corners].all(axis=2)
    rigid = np.zeros(count, dtype=bool)
    vertices[:] = 0.0
    vertices[:, mapped] = carried
    if not mapped.all():
        vertices = register_by_laplacian(source, faces, mapped, vertices, iterations=options.registration_iterations)
    for t in range(frames):
        lost = np.isnan(vertices[t]).any(axis=1)
        if lost.any():
            fit = procrustes(source[mapped], vertices[t, mapped])
            vertices[t, lost] = source[lost] @ fit.rotation.T + fit.translation
            rigid |= lost
    union = _Union(faces, left.vertices, left.observed, vertices, observed)
    drop = np.zeros(count, dtype=bool)
    regions = 0
    if analysis is not None and analysis.regions:
        # scenario 1 of 5.5: the source's region placed in the target frame (the registration)
        regions = analysis.regions
        for r in range(regions):
            region = analysis.region == r
            if not passes_stretch_test(source, faces, vertices[0], region):
                drop |= region
        union = _keep(union, ~drop)
    pasted = replaced = 0
    if options.paste:
        union, paste = _paste(union, target, target_faces, right, options)
        if drop.any():
            union, paste, replaced = _test_replacements(union, paste, vertices[0], analysis.region, drop, options)
        pasted = len(paste.target)
    deleted = len(np.unique(analysis.region[drop])) - replaced if drop.any() else 0
    merged = Block(union.faces, np.concatenate([union.left_vertices, union.right_vertices]),
                   np.concatenate([union.left_observed, union.right_observed]))
    return merged, MergeReport(pair.anchors, float(mapped.mean()), float(rigid.mean()), flagged,
                               pasted, regions, replaced, deleted)


class _Union(NamedTuple):
    """The union mesh of a merge: its faces and its positions (and observed flags) in the left
    block's frames and in the right block's."""

    faces: np.ndarray
    left_vertices: np.ndarray
    left_observed: np.ndarray
    right_vertices: np.ndarray
    right_observed: np.ndarray


def _keep(union: _Union, keep: np.ndarray) -> _Union:
    """``union`` without the vertices not in ``keep`` (nor those no kept face uses)."""
    faces = union.faces[keep[union.faces].all(axis=1)]
    used = np.zeros(len(keep), dtype=bool)
    used[faces.ravel()] = True
    index = np.cumsum(used) - 1
    return _Union(index[faces], union.left_vertices[:, used], union.left_observed[:, used],
                  union.right_vertices[:, used], union.right_observed[:, used])


def _paste(union: _Union, target, target_faces, right: Block, options: Options) -> tuple[_Union, Paste]:
    """``union`` with the target-only patches glued in (:func:`paste_target_only`): the right
    block's own positions in its frames, Laplacian placements in the left block's."""
    paste = paste_target_only(union.right_vertices[0], union.faces, target, target_faces, gap=options.paste_gap)
    added = len(paste.target)
    if not added:
        return union, paste
    count = union.right_vertices.shape[1]
    right_vertices = np.concatenate([union.right_vertices, right.vertices[:, paste.target]], axis=1)
    known = np.arange(count + added) < count
    frames = len(union.left_vertices)
    left_vertices = place_pasted(right_vertices[0], paste.faces, known,
                                 np.concatenate([union.left_vertices, np.zeros((frames, added, 3))], axis=1),
                                 iterations=options.registration_iterations)
    log.debug("pasted %d target-only vertices in %d patches (%d left out)", added, paste.patches, paste.skipped)
    return _Union(
        paste.faces, left_vertices,
        np.concatenate([union.left_observed, np.zeros((frames, added), dtype=bool)], axis=1),
        right_vertices, np.concatenate([union.right_observed, right.observed[:, paste.target]], axis=1),
    ), paste


def _test_replacements(union: _Union, paste: Paste, placed, region, drop, options: Options):
    """Scenario 2 of 5.5 for the dropped regions (their source geometry failed the stretch
    test): the target's patch pasted in their place kept when it passes the stretch test from
    the target frame to the source frame, else removed, so the region is deleted from both.
    Returns the union, the paste without the removed patches and the regions replaced."""
    count = union.right_vertices.shape[1] - len(paste.target)
    if not len(paste.target):
        return union, paste, 0
    edge = median_edge_length(union.right_vertices[0], union.faces)
    distance, owner = cKDTree(placed[drop]).query(union.right_vertices[0, count:])
    near = distance < (options.paste_gap + 2.0) * edge
    dropped_region = region[drop]
    keep = np.ones(count + len(paste.target), dtype=bool)
    replaced = set()
    for patch in np.unique(paste.patch[near]):
        members = count + np.flatnonzero(paste.patch == patch)
        in_patch = np.zeros(len(keep), dtype=bool)
        in_patch[members] = True
        if passes_stretch_test(union.right_vertices[0], union.faces, union.left_vertices[-1], in_patch):
            replaced.update(dropped_region[owner[members - count]].tolist())
        else:
            keep[members] = False
    if keep.all():
        return union, paste, len(replaced)
    kept_new = keep[count:]
    return _keep(union, keep), paste._replace(target=paste.target[kept_new], patch=paste.patch[kept_new]), len(replaced)


def _merge_as_ready(blocks: list[Block], options: Options, pool: MergePool | None, on_merge,
                    guides: list[Guide] | None = None, onto: bool = False):
    """The merges of :func:`merge_tree`, each in two steps (:func:`merge_blocks`): the pair map
    (:func:`map_pair`), run in ``pool`` once its left block is there and its target frame is
    known, then the join (:func:`join_blocks`, here) once the right block is there too.

    The target frame is the right block's first, which merges leave as its first base block's
    mesh unless ``paste`` or ``correct`` changes the union, so by default a merge's map can run
    while its right block is still being assembled. Of the maps that can run, those with the
    longest chain of maps still to follow them go first (:func:`_chains`): the blocks the last
    merges' sources come from are made first, and the rest fill the cores beside the last
    maps. A map that is alone (nothing else running or ready), and every one without a pool,
    runs here, with this process's thread pools. The same maps of the same frames as merging
    level by level. ``guides[t]``: the anchors of base blocks ``t`` and ``t + 1``, for the
    merge whose source is block ``t``'s last frame. Returns the last block and the reports in
    merge order."""
    count = len(blocks)
    merges = merge_tree(count, onto=onto)
    if not merges:
        return blocks[0], []
    last = count + len(merges) - 1
    first = list(range(count))  # the base block of each node's first frame
    for a, _ in merges:
        first.append(first[a])
    chain = _chains(merges, count)
    known_first = not (options.paste or options.correct)
    base = list(blocks)
    ready = dict(enumerate(blocks))
    pending = {count + k: pair for k, pair in enumerate(merges)}  # no map yet
    maps, running, reports = {}, {}, [None] * len(merges)
    resumed = 0

    def map_inputs(node):
        """The arguments of map_pair for merge ``node``, None while its two frames are not there."""
        a, b = merges[node - count]
        right = ready.get(b, base[first[b]] if known_first else None)
        if a not in ready or right is None:
            return None
        guide = None if guides is None else guides[first[b] - 1]
        return ready[a].vertices[-1], ready[a].faces, right.vertices[0], right.faces, options, guide

    def startable() -> list[int]:
        return sorted((node for node in pending if map_inputs(node) is not None), key=lambda node: (-chain[node], node))

    def take(node):
        inputs = map_inputs(node)
        del pending[node]
        base[first[merges[node - count][1]]] = None  # its frame is in the inputs: let it go once joined
        return inputs

    def fill():
        for node in startable()[:max(pool.workers - len(running), 0)]:
            running[pool.submit(_map_or_resume, *take(node))] = node

    while last not in ready:
        joinable = [node for node in maps if merges[node - count][1] in ready]
        for node in joinable:
            a, b = merges[node - count]
            ready[node], reports[node - count] = join_blocks(ready.pop(a), ready.pop(b), maps.pop(node), options)
            if on_merge:
                on_merge()
        now = startable()
        if not (now or running or joinable):
            raise RuntimeError("the assembly's merges stalled: no map can start")  # a bug, not the input
        if pool is None or (len(now) == 1 and not running):
            for node in now if pool is None else now[:1]:
                maps[node], read = _map_or_resume(*take(node))
                resumed += read
            continue
        fill()
        if running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                maps[running.pop(future)], read = future.result()
                resumed += read
            fill()  # before the joins, which take a while here
    if resumed:
        report_resumed(log, f"{resumed} of {len(merges)} merges' maps")
    return ready[last], reports


def _chains(merges: list[tuple[int, int]], count: int) -> dict[int, int]:
    """For each merge node, the most maps that must run one after another after its own: a
    block is the next merge's source when it is its left block (that map follows), and only
    joined when it is the right one (what follows that merge follows it).

    >>> _chains(merge_tree(5), 5)
    {5: 2, 6: 1, 7: 1, 8: 0}
    """
    chain = {count + len(merges) - 1: 0}
    for k in range(len(merges) - 1, -1, -1):
        a, b = merges[k]
        after = chain[count + k]
        chain[a], chain[b] = after + 1, after
    return {node: chain[node] for node in range(count, count + len(merges))}


class MergePool(NamedTuple):
    """Worker processes for the merges (:func:`merge_pool`)."""

    executor: ProcessPoolExecutor
    workers: int

    def submit(self, function, *args):
        """``executor.submit``, a worker started for it inheriting thread pools sized to share
        the cores; this process keeps its own environment (numba refuses to compile here once
        its threads run if the environment asks another count)."""
        with threads_per_worker(self.workers):
            return self.executor.submit(function, *args)


@contextlib.contextmanager
def merge_pool(workers: int):
    """A :class:`MergePool` of ``workers`` processes while inside, shut down on leaving;
    ``None`` for one worker, or inside a daemonic process (a Dask worker's), which may not
    start others. Spawned, not forked: a fork after OpenMP (numba, BLAS) has started aborts
    the child."""
    if workers > 1 and multiprocessing.current_process().daemon:
        log.info("merging in this process: a daemonic process (a Dask worker's) may not start others")
        workers = 1
    if workers <= 1:
        yield None
        return
    executor = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        yield MergePool(executor, workers)
    finally:
        executor.shutdown()


def assemble(blocks: list[Block], options: Options | None = None, *, on_merge=None,
             pool: MergePool | None = None, guides: list[Guide] | None = None,
             onto: bool = False) -> tuple[Block, list[MergeReport]]:
    """Merge ``blocks`` (consecutive, usually one frame each) level by level into one block
    (module docstring, :func:`merge_tree`); ``options.window`` plays no part here (windows
    are :mod:`~fourd.methods.assembly.stream`'s).

    Parameters
    ----------
    blocks : list of Block
    options : Options, optional
        Its :meth:`~Options.merge_workers` > 1 runs the merges in that many processes, each
        as soon as its two blocks are there.
    on_merge : callable, optional
        Called with no argument after each merge (progress).
    pool : MergePool, optional
        Processes to run the merges in (:func:`merge_pool`), instead of a pool of
        :meth:`~Options.merge_workers` started here.
    guides : list of Guide, optional
        ``len(blocks) - 1`` anchor sets from the video or the user
        (:mod:`~fourd.methods.assembly.guides`), ``guides[t]`` for the merge whose source is
        block ``t``'s last frame and whose target is block ``t + 1``'s first.
    onto : bool
        ``blocks[0]`` is a result made before (a streamed run's frames so far, or its last
        frame alone): the others are assembled and merged onto it last.

    Returns
    -------
    Block
        The whole sequence, with the first block's connectivity and the patches pasted in.
    list of MergeReport
        One per merge, level by level.
    """
    options = Options() if options is None else options
    if not blocks:
        raise ValueError("nothing to assemble")
    blocks = list(blocks)
    if guides is not None and len(guides) != len(blocks) - 1:
        raise ValueError(f"{len(guides)} guides for {len(blocks)} blocks (one per consecutive pair)")
    if pool is not None:
        return _merge_as_ready(blocks, options, pool, on_merge, guides, onto)
    with merge_pool(options.merge_workers(blocks[0].vertices.shape[1])) as started:
        return _merge_as_ready(blocks, options, started, on_merge, guides, onto)
