"""The per-frame baseline: every frame meshed on its own, without correspondences.

Each frame goes through :func:`fourd.geometry.frame_surface.frame_surface` (outliers, oriented
normals, an implicit moving-least-squares signed distance on a grid near the data, marching
cubes restricted to cells near the data, small pieces dropped, optional Taubin smoothing).

:func:`reconstruct_frame` is a pure function of one frame and the options, so frames can be
mapped over by any executor.

References
----------
Hoppe, DeRose, Duchamp, McDonald, Stuetzle: Surface reconstruction from unorganized points,
SIGGRAPH 1992 (the pipeline: normals, signed distance, marching cubes, sections 3-4).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from fourd.animation import MeshSequence
from fourd.cache import report_resumed
from fourd.geometry.frame_surface import (  # noqa: F401  (re-exported: the baseline's helpers)
    SurfaceSettings,
    cell_corner_minimum,
    frame_surface,
    frame_surfaces,
    oriented_normals,
    taubin_smooth,
    voxel_average,
)
from fourd.sequence import Frame, PointCloudSequence

log = logging.getLogger("fourd.methods.perframe")

#: The cache entries of the frames' meshes.
STAGE = "perframe"
#: A per-frame method needs a single frame.
MIN_FRAMES = 1
RESULT = MeshSequence
#: The options users change first (``fourd options perframe``; the others under ``--all``).
COMMON_OPTIONS = ("grid_scale", "bandwidth", "clip_distance", "smoothing_iterations", "outlier_z")


@dataclass(frozen=True)
class Options(SurfaceSettings):
    """Options of the per-frame baseline: the settings of
    :func:`fourd.geometry.frame_surface.frame_surface` (described there), and where to keep
    the finished frames. Lengths are in multiples of the frame's point spacing (median
    nearest-neighbour distance) unless noted; on frames so dense that ``max_grid`` caps the
    grid, in multiples of ``cell / grid_scale`` instead.

    Attributes
    ----------
    cache_dir : str or None
        Folder where each finished frame is kept (keyed by the frame's data and these
        options); a rerun after an interruption reuses them (``fourd reconstruct --cache``).
    scheduler : str
        Where the frames are meshed (``fourd reconstruct --scheduler``): ``sync`` one after
        the other here, ``processes`` side by side in local processes, or the address of a
        ``dask.distributed`` scheduler (``tcp://HOST:PORT``) whose workers mesh them; the
        meshes are the same (:func:`fourd.pipeline.map_frames`).
    """

    cache_dir: str | None = None
    scheduler: str = "sync"

    def __post_init__(self):
        from fourd.pipeline import check_scheduler

        super_init = getattr(super(), "__post_init__", None)
        if super_init is not None:
            super_init()
        object.__setattr__(self, "scheduler", check_scheduler(self.scheduler))


def reconstruct_frame(
    frame: Frame, options: Options | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh one frame on its own (:func:`fourd.geometry.frame_surface.frame_surface`).

    Parameters
    ----------
    frame : Frame
    options : Options, optional

    Returns
    -------
    vertices : ndarray float64 [N, 3]
    faces : ndarray int64 [F, 3]
        Outward-wound triangles; empty arrays when the frame has too few points.

    Examples
    --------
    >>> import numpy as np
    >>> from fourd.sequence import Frame
    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(3000, 3)); p /= np.linalg.norm(p, axis=1, keepdims=True)
    >>> v, f = reconstruct_frame(Frame(p))
    >>> bool(np.abs(np.linalg.norm(v, axis=1) - 1).max() < 0.05)
    True
    """
    options = Options() if options is None else options
    return frame_surface(
        frame.points,
        normals=frame.normals,
        sensors=frame.sensors,
        settings=options,
        time=frame.time,
    )


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> MeshSequence:
    """Mesh every frame of ``seq`` independently; one mesh per input frame, same times."""
    options = Options() if options is None else options
    log.info("per-frame meshing of %d frames", len(seq.frames))
    # every frame's points meshed, also where the input frames have faces of their own
    settings = SurfaceSettings(**{f.name: getattr(options, f.name) for f in dataclasses.fields(SurfaceSettings)})
    meshes, found = frame_surfaces(seq.frames, settings, cache_dir=options.cache_dir, stage=STAGE,
                                   desc="perframe", use_faces=False, scheduler=options.scheduler)
    if found:
        report_resumed(log, f"{found} of {len(seq.frames)} frames' meshes")
    return MeshSequence(tuple(meshes), seq.times)
