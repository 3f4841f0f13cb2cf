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


def test_every_array_of_a_list_counts_in_full():
    """Two lists of large arrays that differ in the middle of one (where repr would print
    "...") have different keys; so do a tuple and the list of its parts."""
    big = np.zeros(10000)
    other = big.copy()
    other[5000] = 1.0
    assert stage_key([big, None]) != stage_key([other, None])
    assert stage_key(("ab", "c")) != stage_key(("a", "bc"))
    assert stage_key(np.zeros(2)) != stage_key(np.zeros(2, dtype=np.float32))


def test_key_depends_on_the_cache_format(monkeypatch):
    import fourd.cache

    key = stage_key(np.ones(3))
    monkeypatch.setattr(fourd.cache, "CACHE_FORMAT", fourd.cache.CACHE_FORMAT + 1)
    assert stage_key(np.ones(3)) != key


def test_option_values_leave_out_the_cache_folder_and_refuse_unknown_names():
    from fourd.cache import option_values

    assert option_values(Opts(cache_dir="x")) == {"radius": 1.0}
    assert option_values(Opts(), without=("radius",)) == {}
    try:
        option_values(Opts(), without=("radius", "colour"))
    except ValueError as error:
        assert "colour" in str(error)
    else:
        raise AssertionError("an unknown option name was accepted")


def test_a_write_killed_midway_leaves_no_entry(tmp_path, monkeypatch):
    cache = StageCache(tmp_path)

    def half_then_interrupt(path, **arrays):
        with open(path, "wb") as handle:
            handle.write(b"PK\x03\x04 half an npz")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", half_then_interrupt)
    try:
        cache.save("frame", "k", {"a": np.zeros(3)})
    except KeyboardInterrupt:
        pass
    assert list(tmp_path.iterdir()) == []


def test_an_unreadable_entry_is_a_miss(tmp_path):
    cache = StageCache(tmp_path)
    cache.path("frame", "k").write_bytes(b"not an npz")
    assert cache.load("frame", "k") is None


def test_a_chain_keys_each_step_by_the_steps_before_it(tmp_path):
    from fourd.cache import Chain

    cache = StageCache(tmp_path)
    chain = Chain.of(cache, "step", "base", [(1.0,), (2.0,), (3.0,)])
    assert len(set(chain.keys)) == 3
    # another first step changes every later key
    other = Chain.of(cache, "step", "base", [(1.5,), (2.0,), (3.0,)])
    assert all(a != b for a, b in zip(chain.keys, other.keys, strict=True))
    assert chain.prefix() == [] and chain.latest() == (-1, None)
    chain.save(0, {"v": np.array(0)})
    chain.save(1, {"v": np.array(1)})
    assert [int(e["v"]) for e in chain.prefix()] == [0, 1]
    chain.save(2, {"v": np.array(2)}, keep_earlier=False)
    assert chain.prefix() == [] and chain.latest()[0] == 2
    chain.discard()
    assert list(tmp_path.iterdir()) == []


def test_lists_with_missing_arrays_round_trip(tmp_path):
    from fourd.cache import pack_list, unpack_list

    cache = StageCache(tmp_path)
    arrays = [np.arange(3.0), None, np.zeros((0, 3))]
    cache.save("list", "k", pack_list("points", arrays))
    loaded = unpack_list(cache.load("list", "k"), "points")
    assert loaded[1] is None and np.array_equal(loaded[0], arrays[0]) and loaded[2].shape == (0, 3)


def test_resumed_stages_are_logged_and_counted(caplog):
    import logging

    from fourd.cache import counting_resumes, report_resumed

    log = logging.getLogger("cache-test")
    with caplog.at_level(logging.INFO, logger="cache-test"):
        with counting_resumes() as resumed:
            report_resumed(log, "3 of 4 frames")
        report_resumed(log, "outside the block")
    assert resumed == ["3 of 4 frames"]
    assert "resumed: 3 of 4 frames from the cache" in caplog.text
