"""The map of a merge's source frame onto its target frame, and its entry in the cache.

A merge's map (:func:`~fourd.methods.assembly.hierarchy.map_pair`, nearly all of a merge's
work) depends on its two frames' meshes, the options that act on it and the frame pair's
anchors from the video or a file, nothing else; with ``Options.cache_dir`` each map is kept
as ``assembly-map-<key>.npz`` (:mod:`fourd.cache`), so a run stopped in its 150th merge
resumes there: the maps before are read, and the joins, which are cheap, are made again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fourd.cache import StageCache, option_values, stage_key
from fourd.methods.assembly.analysis import Analysis

#: The cache entries of the merges' maps.
STAGE = "assembly-map"

#: Options that do not act on a map: the joins', the rest fit's, the colour fit's, the holes',
#: where it runs, and where the anchors come from (the anchors themselves are in the key).
NOT_IN_MAP = ("anchors", "anchor_texture", "color_fit", "color_radius", "color_scale", "rest_fit", "rest_weight",
              "paste", "paste_gap", "close_holes", "close_smoothness", "open_handles", "window", "workers", "scheduler")


class MergeMap(NamedTuple):
    """The map of a merge's source frame onto its target frame (``map_pair``).

    anchors : int
        Geometric anchors the pair map started from.
    faces : int64 [N]
        Target triangle of each source vertex (meaningful where ``mapped``).
    barycentric : float64 [N, 3]
    mapped : bool [N]
        Source vertices the map places (the rest are filled in by registration).
    analysis : Analysis or None
        The inconsistent regions (``correct``), their vertices already unmapped.
    """

    anchors: int
    faces: np.ndarray
    barycentric: np.ndarray
    mapped: np.ndarray
    analysis: Analysis | None = None


def map_key(source, faces, target, target_faces, options, guide) -> str:
    """The cache key of ``map_pair(source, faces, target, target_faces, options, guide)``."""
    anchors = None if guide is None else (np.asarray(guide.source), np.asarray(guide.target))
    return stage_key(STAGE, np.asarray(source), np.asarray(faces), np.asarray(target), np.asarray(target_faces),
                     option_values(options, without=NOT_IN_MAP), anchors)


def save_map(cache: StageCache, key: str, pair: MergeMap) -> None:
    """Store ``pair`` under ``key``."""
    arrays = {"anchors": np.int64(pair.anchors), "faces": pair.faces, "barycentric": pair.barycentric,
              "mapped": pair.mapped}
    if pair.analysis is not None:
        arrays |= {f"analysis_{name}": np.asarray(value) for name, value in pair.analysis._asdict().items()}
    cache.save(STAGE, key, arrays)


def load_map(cache: StageCache, key: str) -> MergeMap | None:
    """The map stored under ``key``, or None."""
    entry = cache.load(STAGE, key)
    if entry is None:
        return None
    analysis = None
    if "analysis_flagged" in entry:
        analysis = Analysis(entry["analysis_flagged"], entry["analysis_region"], int(entry["analysis_regions"]),
                            int(entry["analysis_stretched"]), int(entry["analysis_moved"]))
    return MergeMap(int(entry["anchors"]), entry["faces"], entry["barycentric"], entry["mapped"], analysis)
