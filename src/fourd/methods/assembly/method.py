"""The assembly method's pipeline (thesis chapter 5): per-frame meshes, then the hierarchical
assembly of :mod:`~fourd.methods.assembly.hierarchy`.

1. Each frame's mesh: a frame that is a mesh (``Frame.faces``) is used as it is (its
   unreferenced points dropped); a point cloud is meshed on its own
   (:func:`fourd.geometry.frame_surface.frame_surface`, the ``perframe`` baseline's meshing),
   cached per frame when ``cache_dir`` is set. A frame whose mesh comes out empty (too few
   points) takes the nearest non-empty frame's mesh, every vertex unobserved.
2. The binary hierarchy merges consecutive sub-sequences into one consistent sequence with the
   first frame's connectivity, grown by the geometry only later frames have (5.3, 5.6); each
   merge's anchors come from the geometry, and with ``anchors`` from the capture's video or a
   file too (:mod:`~fourd.methods.assembly.guides`); each merge's map is cached when
   ``cache_dir`` is set (:mod:`~fourd.methods.assembly.merge_map`). With ``window`` (by
   default over a long sequence, :meth:`Options.window_for`), a streamed run's loop in memory
   (:mod:`~fourd.methods.assembly.stream`): one hierarchy per window of frames merged onto the
   frames before it, each window fitted (step 3) and closed (step 4) before the next, whose
   seam starts from its last frame as fitted.
3. Every frame slid along its own surface towards the shape most as-rigid-as-possible to the
   first frame's (``rest_fit``, :mod:`~fourd.methods.assembly.rest_fit`); then, with colours
   in the input, to where the first frame's colours are (``color_fit``,
   :mod:`~fourd.methods.assembly.color_fit`).
4. The holes no frame filled are closed by the membrane of 3.6.2 (``close_holes``), and the
   small handles the first frame's mesh grew are cut out and closed the same way
   (``open_handles``), placed in every frame from that frame's rim, unobserved
   (:func:`~fourd.geometry.hole_closing.close_small_holes`).
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.cache import StageCache, report_resumed
from fourd.errors import InputError
from fourd.geometry.frame_surface import SurfaceSettings, frame_surfaces
from fourd.geometry.hole_closing import close_small_holes
from fourd.methods.assembly.color_fit import fit_colors, frame_colors
from fourd.methods.assembly.guides import Guide, read_guides, video_guides
from fourd.methods.assembly.hierarchy import Block, MergePool, assemble, merge_pool
from fourd.methods.assembly.options import ANCHOR_SOURCES, Options
from fourd.methods.assembly.rest_fit import fit_rest
from fourd.methods.base import Reconstruction
from fourd.progress import progress
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.assembly")

#: A sequence method: at least two frames.
MIN_FRAMES = 2
RESULT = AnimatedMesh
#: The options users change first (``fourd options assembly``; the others under ``--all``).
COMMON_OPTIONS = ("anchors", "anchor_spacing", "max_radius", "relax_sweeps", "close_holes", "workers")
#: The cache entries of the frames' meshes.
STAGE = "assembly-surface"
#: Fewest faces a frame's mesh needs to take part.
MIN_FACES = 4


@dataclasses.dataclass(frozen=True)
class AssemblyDiagnostics:
    """Figures of an assembly run.

    mapped_fraction : float
        Mean over the merges of the fraction of source vertices the pair map placed.
    observed_fraction : float
        Fraction of the output's vertex positions (all frames) found on a frame's surface
        rather than filled in.
    """

    mapped_fraction: float
    observed_fraction: float


def frame_meshes(seq: PointCloudSequence, options: Options, pool: MergePool | None = None,
                 frames: slice = slice(None)) -> list[tuple[np.ndarray, np.ndarray]]:
    """The mesh of each of the ``frames`` (step 1 of the module docstring), empty ones
    included: its own faces when it has them, else
    :func:`~fourd.geometry.frame_surface.frame_surface` (cached), made in ``pool``'s processes
    when given."""
    meshes, found = _frame_meshes(seq, options, pool, frames)
    if found:
        report_resumed(log, f"{found} of {len(meshes)} frames' meshes")
    return meshes


def _frame_meshes(seq: PointCloudSequence, options: Options, pool: MergePool | None = None,
                  frames: slice = slice(None)) -> tuple[list[tuple[np.ndarray, np.ndarray]], int]:
    """:func:`frame_meshes` of the ``frames``, made in ``pool``'s processes when given (and
    ``scheduler`` is ``sync``), and how many came from the cache."""
    settings = SurfaceSettings(**{f.name: getattr(options, f.name) for f in dataclasses.fields(SurfaceSettings)})
    return frame_surfaces(seq.frames[frames], settings, cache_dir=options.cache_dir, stage=STAGE,
                          desc="assembly meshes", scheduler=options.scheduler,
                          submit=None if pool is None else pool.submit)


def base_blocks(seq: PointCloudSequence, meshes) -> list[Block]:
    """One block per frame of ``seq`` (``meshes``: their meshes); an empty frame borrows the
    nearest non-empty frame's mesh, all of it unobserved. :class:`InputError` when every
    frame is empty."""
    usable = [i for i, (_, faces) in enumerate(meshes) if len(faces) >= MIN_FACES]
    if not usable:
        raise InputError(
            f"no frame of {seq.names[0]} .. {seq.names[-1]} gives a surface to assemble (each has "
            f"fewer than {MIN_FACES} faces, or "
            f"too few points to mesh): the assembly method needs per-frame meshes or denser scans"
        )
    blocks = []
    for i, (vertices, faces) in enumerate(meshes):
        seen = len(faces) >= MIN_FACES
        if not seen:
            j = min(usable, key=lambda k: (abs(k - i), k))
            log.warning("frame %d (%s) has no surface: it takes frame %d's, unobserved", i, seq.names[i], j)
            vertices, faces = meshes[j]
        blocks.append(Block(np.asarray(faces, dtype=np.int64), np.asarray(vertices, dtype=np.float64)[None],
                            np.full((1, len(vertices)), seen)))
    return blocks


def takes_video_anchors(options: Options, video: bool) -> bool:
    """Whether the merges' anchors come from the capture's video (``video``: the input has
    one): ``anchors='video'``, or ``auto`` with video and ``color_fit`` off."""
    return options.anchors == "video" or (options.anchors == "auto" and video and not options.color_fit)


def frame_pair_guides(seq: PointCloudSequence, options: Options) -> list[Guide] | None:
    """The anchors of every consecutive frame pair from ``options.anchors``' source (the
    video or a file, :mod:`~fourd.methods.assembly.guides`); None for ``geometry``, and for
    ``auto`` unless the input has video and ``color_fit`` is off (the colour fit reads the
    same video against the first frame, where the anchors' errors add up along the chain)."""
    if options.anchors in ANCHOR_SOURCES:
        if not takes_video_anchors(options, getattr(seq, "video", None) is not None):
            return None
        return video_guides(seq, options.anchor_texture)
    return read_guides(options.anchors, seq)


def _fit_colors(seq: PointCloudSequence, meshes, block: Block, options: Options) -> Block:
    """``block`` slid to the first frame's colours (:mod:`~fourd.methods.assembly.color_fit`)
    when the input has colours, else as it is."""
    colors = frame_colors(seq, meshes)
    if colors is None:
        return block
    vertices = fit_colors(block.vertices, block.faces, block.observed, meshes, colors, radius=options.color_radius,
                          scale=options.color_scale, cache=StageCache(options.cache_dir))
    return Block(block.faces, vertices, block.observed)


def reconstruct_with_diagnostics(seq: PointCloudSequence, options: Options | None = None) -> Reconstruction:
    """:func:`reconstruct`, with an :class:`AssemblyDiagnostics`."""
    options = Options() if options is None else options
    if len(seq) < 2:
        raise InputError(f"the assembly method needs at least 2 frames, the input has {len(seq)}")
    window = options.window_for(len(seq))
    if window > 0:
        # a streamed run's loop, kept in memory (stream builds on this module)
        from fourd.methods.assembly.stream import assemble_in_windows

        block, reports = assemble_in_windows(seq, dataclasses.replace(options, window=window))
        return _reconstruction(seq, block, reports)
    # the first frame's mesh here decides the merge processes (its size, as assemble does);
    # they make the other frames' meshes before the merges
    meshes, found = _frame_meshes(seq, options, frames=slice(0, 1))
    size = len(meshes[0][0]) or max(len(frame.points) for frame in seq.frames)
    with merge_pool(options.merge_workers(size)) as pool:
        others, found_others = _frame_meshes(seq, options, pool, frames=slice(1, None))
        meshes, found = meshes + others, found + found_others
        if found:
            report_resumed(log, f"{found} of {len(seq.frames)} frames' meshes")
        blocks = base_blocks(seq, meshes)
        guides = frame_pair_guides(seq, options)
        log.info("assembling %d frames (%d merges)", len(blocks), len(blocks) - 1)
        with progress(total=len(blocks) - 1, desc="assembly merges", unit="merge") as bar:
            block, reports = assemble(blocks, options, on_merge=lambda: bar.update(1), pool=pool, guides=guides)
    if options.rest_fit:
        block = Block(block.faces, fit_rest(block.vertices, block.faces, block.observed, meshes,
                                            iterations=options.rest_fit, weight=options.rest_weight,
                                            cache=StageCache(options.cache_dir)), block.observed)
    if options.color_fit:
        block = _fit_colors(seq, meshes, block, options)
    if options.close_holes > 0:
        block = Block(*close_small_holes(block.faces, block.vertices, block.observed, options.close_holes,
                                         options.close_smoothness, options.open_handles))
    return _reconstruction(seq, block, reports)


def _reconstruction(seq: PointCloudSequence, block: Block, reports) -> Reconstruction:
    result = AnimatedMesh(block.faces, block.vertices, seq.times, block.observed, rest=block.vertices[0])
    mapped = float(np.mean([r.mapped for r in reports])) if reports else 1.0
    for level_report in reports:
        log.debug("merge: %d anchors, %.3f mapped, %.3f rigid, %d flagged", *level_report)
    return Reconstruction(result, AssemblyDiagnostics(mapped, float(block.observed.mean())))


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """Assemble ``seq`` into one animated mesh (module docstring); one output frame per input
    frame, the first frame's connectivity grown by what only later frames have.

    Parameters
    ----------
    seq : PointCloudSequence
        Per-frame meshes (frames with ``faces``) or point clouds, at least 2 frames.
    options : Options, optional

    Returns
    -------
    AnimatedMesh
        ``observed`` False where a vertex was filled in rather than found on that frame's
        surface (the registration's vertices, the membranes closing holes no frame fills).
    """
    return reconstruct_with_diagnostics(seq, options).result
