"""Vertex colours of an animated mesh from the coloured points it was reconstructed from.

Each output frame takes, for every vertex, the colour of the nearest input point of the
input frame at (or nearest to) that frame's time. A vertex that was filled in at a frame
(``observed`` False: no input data near it) takes instead the colour it had at the nearest
frame, in time, where it was observed, so holes do not pick up the colour of whatever
surface happens to be closest; a vertex never observed keeps its nearest point's colour.

:func:`frame_vertex_colors` gives the colours of one frame only (the viewer's "carried colour":
frame 0's colours kept on every frame, so that vertices drifting over the surface show as
colours swimming against the input's).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence

__all__ = ["frame_vertex_colors", "nearest_observed_frame", "vertex_colors"]


def vertex_colors(anim: AnimatedMesh, seq: PointCloudSequence) -> np.ndarray:
    """Per-frame vertex colours ``[T, N, 3]`` in [0, 1] (the input's colour space).

    Parameters
    ----------
    anim : AnimatedMesh
        The result (its ``vertices`` in the input's units and axes).
    seq : PointCloudSequence
        The input; frames without ``colors`` are skipped (an output frame then takes the
        nearest coloured frame in time).

    Raises
    ------
    InputError
        No input frame has colours.

    Examples
    --------
    >>> from fourd.sequence import Frame
    >>> seq = PointCloudSequence((Frame(np.eye(3), colors=np.eye(3)),))
    >>> anim = AnimatedMesh(np.zeros((0, 3), int), [[[0.9, 0, 0], [0, 0, 1.1]]])
    >>> vertex_colors(anim, seq).tolist()
    [[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]
    """
    coloured = [k for k, frame in enumerate(seq.frames) if frame.colors is not None]
    if not coloured:
        raise InputError("the input has no colours to carry to the vertices")
    times = np.array([seq.frames[k].time for k in coloured])
    colors = np.empty(anim.vertices.shape)
    trees: dict[int, cKDTree] = {}
    for t in range(anim.frame_count):
        k = coloured[int(np.argmin(np.abs(times - anim.times[t])))]
        if k not in trees:
            trees[k] = cKDTree(seq.frames[k].points)
        _, nearest = trees[k].query(anim.vertices[t])
        colors[t] = seq.frames[k].colors[nearest]
    source = nearest_observed_frame(anim.observed)
    frames = np.where(source >= 0, source, np.arange(anim.frame_count)[:, None])
    return colors[frames, np.arange(anim.vertex_count)[None, :]]


def frame_vertex_colors(anim: AnimatedMesh, seq: PointCloudSequence, frame: int = 0) -> np.ndarray:
    """Vertex colours ``[N, 3]`` in [0, 1] of one frame of ``anim``: row ``frame`` of
    :func:`vertex_colors`, computed from the few frames it needs (``frame`` itself and, for the
    vertices filled in there, the nearest frame where each is observed).

    Parameters
    ----------
    anim : AnimatedMesh
    seq : PointCloudSequence
        The input, with colours on at least one frame.
    frame : int
        Index into ``anim``'s frames (negative counts from the end).

    Raises
    ------
    InputError
        ``frame`` is outside the animation, or no input frame has colours.

    Examples
    --------
    >>> from fourd.sequence import Frame
    >>> seq = PointCloudSequence((Frame(np.eye(3), colors=np.eye(3)),))
    >>> anim = AnimatedMesh(np.zeros((0, 3), int), [[[0.9, 0, 0], [0, 0, 1.1]]] * 2)
    >>> frame_vertex_colors(anim, seq).tolist()
    [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    if not -anim.frame_count <= int(frame) < anim.frame_count:
        raise InputError(f"frame {frame} outside the animation's {anim.frame_count} frames")
    frame = int(frame) % anim.frame_count
    source = nearest_observed_frame(anim.observed)[frame]
    source = np.where(source >= 0, source, frame)  # never observed: its own nearest point
    frames, row = np.unique(source, return_inverse=True)
    needed = AnimatedMesh(anim.faces, anim.vertices[frames], times=anim.times[frames])
    return vertex_colors(needed, seq)[row, np.arange(anim.vertex_count)]


def nearest_observed_frame(observed: np.ndarray) -> np.ndarray:
    """For each frame and vertex, the nearest frame (in index) where the vertex is observed,
    itself when it is; -1 for a vertex never observed. Ties go to the earlier frame.

    Parameters
    ----------
    observed : bool array [T, N]

    Returns
    -------
    int64 array [T, N]

    Examples
    --------
    >>> nearest_observed_frame(np.array([[0, 0], [1, 0], [0, 0], [0, 0], [1, 0]], bool))[:, 0].tolist()
    [1, 1, 1, 4, 4]
    """
    observed = np.asarray(observed, dtype=bool)
    count = len(observed)
    index = np.arange(count)[:, None]
    before = np.maximum.accumulate(np.where(observed, index, -1), axis=0)
    after = np.minimum.accumulate(np.where(observed, index, count)[::-1], axis=0)[::-1]
    use_after = (before < 0) | ((after < count) & (after - index < index - before))
    nearest = np.where(use_after, after, before)
    return np.where(nearest >= count, -1, nearest)
