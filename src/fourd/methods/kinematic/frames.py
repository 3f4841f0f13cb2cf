"""Per-frame preparation of the input: outlier removal and oriented normals (a pure
function of one frame and the options).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba

from fourd.geometry.neighbors import knn, neighbours_among
from fourd.geometry.normals import estimate_normals
from fourd.geometry.outliers import distance_ratio_inliers
from fourd.methods.kinematic.options import OUTLIER_NEIGHBOURS, PREPARE_THREADS, Options
from fourd.sequence import PointCloudSequence


def prepare_frames(seq: PointCloudSequence, options: Options):
    """Per-frame cleaning and normals: returns ``(points, normals)`` lists (pure per frame).

    Frames are prepared two at a time on two threads (their compiled kernels release the GIL)
    when numba's threading layer allows concurrent parallel kernels; the result is the same
    as one after the other."""
    frames = list(seq.frames)
    if not frames:
        return [], []
    first = _prepare_frame(frames[0], options)
    if len(frames) == 1 or not _concurrent_kernels_safe():
        rest = [_prepare_frame(frame, options) for frame in frames[1:]]
    else:
        with ThreadPoolExecutor(max_workers=PREPARE_THREADS) as pool:
            rest = list(pool.map(lambda frame: _prepare_frame(frame, options), frames[1:]))
    prepared = [first] + rest
    return [p for p, _ in prepared], [n for _, n in prepared]


def _concurrent_kernels_safe() -> bool:
    """Whether numba's threading layer (chosen at the first parallel kernel) lets two threads
    run parallel kernels at once: ``tbb`` and ``omp`` do, ``workqueue`` aborts the process."""
    try:
        return numba.threading_layer() in ("tbb", "omp")
    except ValueError:  # no parallel kernel has run yet
        return False


def _prepare_frame(frame, options: Options):
    """One frame's kept points [P', 3] and their oriented normals [P', 3]."""
    # one neighbour query per frame serves the outlier test (8 neighbours) and the normals
    # of the kept points (a margin of 4 for the dropped ones; rows that keep fewer are
    # queried again)
    distances = indices = None
    if frame.normals is None:
        k = max(OUTLIER_NEIGHBOURS, options.normals_k) + 4
        distances, indices = knn(frame.points, min(k, len(frame.points) - 1))
    elif options.outlier_factor > 0 and len(frame.points) > OUTLIER_NEIGHBOURS + 1:
        distances, _ = knn(frame.points, OUTLIER_NEIGHBOURS)
    keep = distance_ratio_inliers(
        frame.points,
        k=OUTLIER_NEIGHBOURS,
        factor=options.outlier_factor,
        statistic="mean",
        distances=distances,
    )
    p = frame.points[keep]
    if frame.normals is not None:
        return p, frame.normals[keep]
    neighbours = neighbours_among(frame.points, indices, keep, options.normals_k)
    n = estimate_normals(p, k=options.normals_k, sensors=frame.sensors, indices=neighbours).normals
    return p, n
