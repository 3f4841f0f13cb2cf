"""Whether a ground truth belongs to a result, told before scoring (``fourd evaluate``,
``fourd view --truth``): the same number of frames and bounding boxes that agree. A truth of
another scene, another stretch of the capture or in other units then gives a one-line
refusal instead of figures that mean nothing.

The box rule is tolerant on purpose: a noisy, partial (one-sided scans, holes) but right
reconstruction always passes, and so do a few stray triangles. The boxes are those of all
frames together, ``[2, 3]``, in input units.
"""

from __future__ import annotations

import logging
import os

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError

log = logging.getLogger("fourd.metrics.match")

__all__ = ["CENTRE_TOLERANCE", "DIAGONAL_FACTOR", "check_truth", "truth_at_times", "truth_mismatch"]

#: The boxes' centres may lie this many truth diagonals apart.
CENTRE_TOLERANCE = 0.5
#: The boxes' diagonals may differ by this factor either way.
DIAGONAL_FACTOR = 2.0


def truth_mismatch(result, truth) -> str | None:
    """Why ``truth`` (an AnimatedMesh or MeshSequence) cannot be the ground truth of
    ``result``, in words; None when it can.

    It cannot when the frame counts differ, when the boxes' centres lie more than
    :data:`CENTRE_TOLERANCE` truth diagonals apart, or when one box's diagonal exceeds the
    other's :data:`DIAGONAL_FACTOR` times. A result or truth without any vertex is left to
    the metrics.

    Examples
    --------
    >>> truth = AnimatedMesh(np.zeros((0, 3), int), np.random.default_rng(0).random((2, 50, 3)))
    >>> truth_mismatch(AnimatedMesh(truth.faces, truth.vertices + 0.01), truth) is None
    True
    >>> truth_mismatch(AnimatedMesh(truth.faces, truth.vertices * 1000), truth).split(" (")[0]
    "the result's bounding box"
    """
    if result.frame_count != truth.frame_count:
        return f"the result has {result.frame_count} frames but the truth has {truth.frame_count}"
    ours, theirs = _bounds(result), _bounds(truth)
    if ours is None or theirs is None:
        return None
    centre = np.linalg.norm(ours.mean(axis=0) - theirs.mean(axis=0))
    diagonals = np.linalg.norm(ours[1] - ours[0]), np.linalg.norm(theirs[1] - theirs[0])
    scale = max(diagonals[1], 1e-12)
    if centre <= CENTRE_TOLERANCE * scale and max(diagonals) <= DIAGONAL_FACTOR * max(
        min(diagonals), 1e-12
    ):
        return None
    return (
        f"the result's bounding box (centre {_vector(ours.mean(axis=0))}, diagonal "
        f"{diagonals[0]:.4g}) is not the truth's (centre {_vector(theirs.mean(axis=0))}, "
        f"diagonal {diagonals[1]:.4g})"
    )


def check_truth(
    result,
    truth,
    result_path: str | os.PathLike,
    truth_path: str | os.PathLike,
    *,
    force: bool = False,
):
    """The truth to score ``result`` against: ``truth`` itself when :func:`truth_mismatch`
    finds nothing; else InputError naming both files, or with ``force`` a warning and, where
    the frame counts differ, the truth's frames nearest in time to the result's
    (:func:`truth_at_times`)."""
    problem = truth_mismatch(result, truth)
    if problem is None:
        return truth
    where = f"{os.fspath(truth_path)} does not look like the truth of {os.fspath(result_path)}"
    if not force:
        raise InputError(f"{where}: {problem} (--force goes on anyway)")
    log.warning("%s: %s; going on (--force)", where, problem)
    if result.frame_count != truth.frame_count:
        log.warning("each result frame is compared with the truth frame nearest in time")
        return truth_at_times(truth, result.times)
    return truth


def truth_at_times(truth, times) -> AnimatedMesh | MeshSequence:
    """The frames of ``truth`` nearest to each of ``times`` ([T]), in that order."""
    times = np.asarray(times, float)
    nearest = np.abs(times[:, None] - truth.times[None, :]).argmin(axis=1)
    if isinstance(truth, AnimatedMesh):
        return AnimatedMesh(
            truth.faces, truth.vertices[nearest], times, truth.observed[nearest], truth.rest
        )
    return MeshSequence(tuple(truth.meshes[i] for i in nearest), times)


def _bounds(value) -> np.ndarray | None:
    if isinstance(value, AnimatedMesh):
        return value.bounds()
    present = [v for v, _ in value.meshes if len(v)]
    if not present:
        return None
    return np.stack(
        [
            np.min([v.min(axis=0) for v in present], axis=0),
            np.max([v.max(axis=0) for v in present], axis=0),
        ]
    )


def _vector(values: np.ndarray) -> str:
    return " ".join(f"{v:.4g}" for v in values)
