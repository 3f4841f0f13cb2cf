"""A merge's map in the cache: stored and read back whole, keyed by what acts on it."""

from __future__ import annotations

import numpy as np

from fourd.cache import StageCache
from fourd.methods.assembly import Options
from fourd.methods.assembly.analysis import Analysis
from fourd.methods.assembly.guides import Guide
from fourd.methods.assembly.merge_map import MergeMap, load_map, map_key, save_map


def test_a_map_with_its_analysis_is_read_back_as_stored(tmp_path):
    rng = np.random.default_rng(0)
    analysis = Analysis(rng.uniform(size=6) > 0.5, np.array([0, -1, 1, 1, -1, 0]), 2, 3, 1)
    pair = MergeMap(7, np.arange(6), rng.uniform(size=(6, 3)), rng.uniform(size=6) > 0.3, analysis)
    cache = StageCache(tmp_path)
    assert load_map(cache, "k") is None
    save_map(cache, "k", pair)
    save_map(cache, "plain", pair._replace(analysis=None))
    read = load_map(cache, "k")
    assert read.anchors == 7 and load_map(cache, "plain").analysis is None
    for name in ("faces", "barycentric", "mapped"):
        np.testing.assert_array_equal(getattr(read, name), getattr(pair, name))
    np.testing.assert_array_equal(read.analysis.flagged, analysis.flagged)
    np.testing.assert_array_equal(read.analysis.region, analysis.region)
    assert read.analysis[2:] == (2, 3, 1)


def test_the_key_follows_the_frames_the_map_options_and_the_anchors():
    rng = np.random.default_rng(1)
    source, target, faces = rng.uniform(size=(5, 3)), rng.uniform(size=(5, 3)), np.array([[0, 1, 2], [2, 3, 4]])
    guide = Guide(rng.uniform(size=(3, 3)), rng.uniform(size=(3, 3)))
    key = map_key(source, faces, target, faces, Options(), guide)
    assert key == map_key(source.copy(), faces, target, faces, Options(close_holes=0.5, color_fit=False), guide)
    assert key != map_key(source, faces, target + 1e-9, faces, Options(), guide)
    assert key != map_key(source, faces, target, faces, Options(relax_sweeps=3), guide)
    assert key != map_key(source, faces, target, faces, Options(), None)
    assert key != map_key(source, faces, target, faces, Options(), Guide(guide.source, guide.target + 1e-9))
