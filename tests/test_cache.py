from dataclasses import dataclass

import numpy as np

from fourd.cache import StageCache, stage_key


@dataclass(frozen=True)
class Opts:
    radius: float = 1.0
    cache_dir: str | None = None


def test_key_depends_on_data_and_options_but_not_on_the_cache_folder():
    points = np.arange(12.0).reshape(4, 3)
    key = stage_key(points, Opts())
    assert key == stage_key(points.copy(), Opts(cache_dir="elsewhere"))
    assert key != stage_key(points + 1e-9, Opts())
    assert key != stage_key(points, Opts(radius=2.0))


def test_round_trip_and_disabled_cache(tmp_path):
    cache = StageCache(tmp_path / "c")
    assert cache.load("frame", "k") is None
    cache.save("frame", "k", {"vertices": np.ones((3, 3)), "faces": np.zeros((1, 3), int)})
    loaded = cache.load("frame", "k")
    assert np.array_equal(loaded["vertices"], np.ones((3, 3))) and loaded["faces"].shape == (1, 3)
    assert [p.name for p in (tmp_path / "c").iterdir()] == ["frame-k.npz"]
    off = StageCache(None)
    off.save("frame", "k", {"a": np.zeros(1)})
    assert off.load("frame", "k") is None
