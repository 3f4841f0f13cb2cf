"""Anchors that do not come from the geometry: the capture's video or the user's file (thesis
section 5.4.1), one set per pair of consecutive frames.

Each merge of the hierarchy maps the last frame ``t`` of its left block onto the first frame
``t + 1`` of its right block, so the anchors of the frame pair ``(t, t + 1)`` serve exactly
one merge. A guide is a set of material points: where each was in frame ``t`` and where it is
in frame ``t + 1`` (input units). Two sources:

- ``anchors="video"``: the optical-flow anchor tracks of :func:`fourd.appearance.anchors`
  (the thesis' own source: every camera's flow, pruned forward and backward in the image and
  in 3D, the cameras' tracks compared), counting only tracks that start on hue texture (flow
  on skin or a uniform colour follows the shading, see ``kinematic``'s ``anchor_texture``);
- an anchors file (:func:`read_guides`, format below).

In a merge (:func:`guide_anchors`) each guide's frame-``t`` point is matched to the nearest
source vertex and its frame-``t + 1`` point, shifted by the same offset, to the closest point
on the target mesh; a guide whose point lies farther than ``gap`` from either mesh is dropped
(a point of a part the mesh lacks). The matched guides then pull the coarse alignment point
to point (:func:`~fourd.methods.assembly.alignment.geometric_anchors`' ``guides``) and join
its anchors, preferred where the two crowd.

Anchors file format (``.npz``, NumPy's zip of arrays): for the pair of frames ``t`` and
``t + 1`` (0-based, in the sequence's order), either ``source_<t>`` and ``target_<t>``, float
arrays ``[A, 3]``: the same material points in frame ``t`` and in frame ``t + 1`` (input
units); or ``source_vertices_<t>`` and ``target_vertices_<t>``, int arrays ``[A]``: vertex ids
of frame ``t``'s and frame ``t + 1``'s own meshes (mesh input). A pair with no arrays has no
guides (its merge takes its anchors from the geometry alone). For example::

    np.savez("anchors.npz", source_0=points_in_frame_0, target_0=same_points_in_frame_1)
"""

from __future__ import annotations

import logging
import re
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.errors import InputError
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.methods.assembly.anchors import Anchors

log = logging.getLogger("fourd.methods.assembly.guides")

#: The video's tracks start from at most one point per cube of this many point spacings (as
#: ``kinematic``'s): a merge keeps about one anchor per two source edges.
VIDEO_SOURCES = 2.0

_NAME = re.compile(r"^(source|target|source_vertices|target_vertices)_(\d+)$")


class Guide(NamedTuple):
    """The same material points in two consecutive frames.

    source : float64 [A, 3]
        In the earlier frame (input units).
    target : float64 [A, 3]
        In the later frame.
    """

    source: np.ndarray
    target: np.ndarray


def empty_guide() -> Guide:
    """A guide with no points."""
    return Guide(np.zeros((0, 3)), np.zeros((0, 3)))


def video_guides(seq, texture: float) -> list[Guide]:
    """One :class:`Guide` per consecutive frame pair of ``seq`` (which has ``video``) from its
    optical-flow anchor tracks (:func:`fourd.appearance.anchors`), counting only tracks that
    start where the image's hue texture is at least ``texture`` times the noise's (0: all)."""
    from fourd.appearance import anchors as track_anchors

    if getattr(seq, "video", None) is None:
        raise InputError(
            "anchors='video' needs the capture's video: cameras.json and video/<camera>/ beside "
            "the frames (see the README); use anchors='geometry' for scans without it"
        )
    tracks = track_anchors(seq, texture=texture, sources=VIDEO_SOURCES)
    log.info("anchors from the video: %d over %d frame pairs", tracks.total, len(tracks))
    return [Guide(np.asarray(pair.source, np.float64), np.asarray(pair.target, np.float64)) for pair in tracks]


def read_guides(path, seq) -> list[Guide]:
    """The guides of an anchors file (module docstring) for the frames of ``seq``: one per
    consecutive frame pair, empty where the file has none. :class:`InputError` naming the file
    and the problem when it cannot be read or does not fit the sequence."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: anchors file not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: np.asarray(data[name]) for name in data.files}
    except (OSError, ValueError, zipfile.BadZipFile) as error:
        raise InputError(f"{path}: not a NumPy .npz anchors file ({error})") from None
    pairs = len(seq) - 1
    found: dict[int, dict[str, np.ndarray]] = {}
    for name, array in arrays.items():
        match = _NAME.match(name)
        if match is None:
            raise InputError(f"{path}: unexpected array {name!r} (expected source_<t>, target_<t>, "
                             f"source_vertices_<t> or target_vertices_<t>)")
        kind, t = match.group(1), int(match.group(2))
        if t >= pairs:
            raise InputError(f"{path}: {name} is for frames {t} and {t + 1}, but the sequence has "
                             f"{len(seq)} frames")
        found.setdefault(t, {})[kind] = array
    guides = [empty_guide() for _ in range(pairs)]
    for t, kinds in found.items():
        guides[t] = _pair_guide(path, t, kinds, seq)
    log.info("anchors from %s: %d over %d of %d frame pairs", path, sum(len(g.source) for g in guides),
             len(found), pairs)
    return guides


def _pair_guide(path: Path, t: int, kinds: dict[str, np.ndarray], seq) -> Guide:
    """The guide of frames ``t`` and ``t + 1`` from the file's arrays of that pair."""
    if "source" in kinds or "target" in kinds:
        if set(kinds) != {"source", "target"}:
            raise InputError(f"{path}: pair {t} needs both source_{t} and target_{t} (and no vertex ids)")
        source, target = kinds["source"], kinds["target"]
        if source.ndim != 2 or source.shape[1] != 3 or source.shape != target.shape:
            raise InputError(f"{path}: source_{t} and target_{t} must both be [A, 3] points, got "
                             f"{source.shape} and {target.shape}")
        if not (np.issubdtype(source.dtype, np.number) and np.issubdtype(target.dtype, np.number)):
            raise InputError(f"{path}: source_{t} and target_{t} must be numbers")
        source, target = source.astype(np.float64), target.astype(np.float64)
        if not (np.isfinite(source).all() and np.isfinite(target).all()):
            raise InputError(f"{path}: source_{t} or target_{t} holds NaN or infinite values")
        return Guide(source, target)
    if set(kinds) != {"source_vertices", "target_vertices"}:
        raise InputError(f"{path}: pair {t} needs both source_vertices_{t} and target_vertices_{t}")
    ids = []
    for kind, frame in (("source_vertices", t), ("target_vertices", t + 1)):
        array = kinds[kind]
        if array.ndim != 1 or not np.issubdtype(array.dtype, np.integer):
            raise InputError(f"{path}: {kind}_{t} must be a 1-D array of vertex ids, got {array.dtype} "
                             f"{array.shape}")
        count = len(seq.frames[frame].points)
        if len(array) and (array.min() < 0 or array.max() >= count):
            raise InputError(f"{path}: {kind}_{t} holds ids outside frame {frame}'s {count} vertices")
        ids.append(array.astype(np.int64))
    if len(ids[0]) != len(ids[1]):
        raise InputError(f"{path}: source_vertices_{t} and target_vertices_{t} differ in length "
                         f"({len(ids[0])} and {len(ids[1])})")
    return Guide(seq.frames[t].points[ids[0]].astype(np.float64), seq.frames[t + 1].points[ids[1]].astype(np.float64))


class MatchedGuides(NamedTuple):
    """Guides matched to a merge's meshes (:func:`guide_anchors`).

    vertices : int64 [K]
        The source vertex of each.
    points : float64 [K, 3]
        Its point on the target surface.
    anchors : Anchors
        The same as anchors (target triangle and barycentric coordinates).
    """

    vertices: np.ndarray
    points: np.ndarray
    anchors: Anchors


def guide_anchors(guide: Guide, source: np.ndarray, target: np.ndarray, target_faces: np.ndarray,
                  gap: float) -> MatchedGuides:
    """``guide`` matched to a merge's meshes (module docstring): the source vertices ``[N, 3]``
    and the target mesh (``target [M, 3]``, ``target_faces [G, 3]``), a guide dropped when its
    points lie farther than ``gap`` (input units) from them. Where several guides meet at one
    source vertex, the nearest keeps it."""
    empty = MatchedGuides(np.zeros(0, np.int64), np.zeros((0, 3)),
                          Anchors(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))))
    if not len(guide.source) or not len(source) or not len(target_faces):
        return empty
    distance, vertex = cKDTree(source).query(guide.source, workers=-1)
    near = distance <= gap
    order = np.flatnonzero(near)[np.argsort(distance[near], kind="stable")]
    _, first = np.unique(vertex[order], return_index=True)
    chosen = np.sort(order[first])
    if not len(chosen):
        return empty
    vertices = vertex[chosen]
    shifted = guide.target[chosen] + (source[vertices] - guide.source[chosen])
    found = closest_points_on_mesh(target, target_faces, shifted)
    on = found.distances <= gap
    anchors = Anchors(vertices[on], found.triangle[on], found.barycentric[on])
    return MatchedGuides(vertices[on], anchors.target_points(target, target_faces), anchors)
