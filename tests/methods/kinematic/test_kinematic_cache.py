"""Method ``kinematic`` with ``cache_dir``: an interrupted run resumes after its last finished
stage (prepared frames, 4D fit, urshape, slid frames) with the same result, and a changed
option recomputes what it acts on."""

import numpy as np
import pytest

import fourd
from fourd.methods import kinematic as K
from fourd.methods.kinematic import field, frames, sliding

#: Small enough for a couple of seconds per run.
TINY = {"template_vertices": 400}


@pytest.fixture(scope="module")
def scans():
    truth = fourd.synth.scene("squash-ball", frames=4)
    return fourd.synth.scan(truth, resolution=64, seed=0)


@pytest.fixture(scope="module")
def uninterrupted(scans):
    return K.reconstruct(scans, K.Options(**TINY))


class Calls:
    """Counts the calls of the expensive stages; ``fail`` raises KeyboardInterrupt at the
    given call of one of them (the interruption)."""

    def __init__(self, monkeypatch, fail: tuple[str, int] | None = None):
        self.counts = {"prepare": 0, "fit": 0, "slide": 0}
        for name, module, attribute in (
            ("prepare", frames, "_prepare_frame"),
            ("fit", field, "fit_mpu4d"),
            ("slide", sliding, "slide_step"),
        ):
            monkeypatch.setattr(module, attribute, self._counted(name, getattr(module, attribute), fail))

    def _counted(self, name, function, fail):
        def counted(*args, **kwargs):
            self.counts[name] += 1
            if fail == (name, self.counts[name]):
                raise KeyboardInterrupt
            return function(*args, **kwargs)

        return counted


def _same(a, b):
    assert np.array_equal(a.faces, b.faces) and np.array_equal(a.rest, b.rest)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.observed, b.observed)


def _entries(folder, stage):
    return len(list(folder.glob(f"{stage}-*.npz")))


@pytest.mark.slow
def test_a_run_interrupted_while_sliding_resumes_after_the_last_slid_frame(
    scans, uninterrupted, tmp_path, monkeypatch, caplog
):
    options = K.Options(**TINY, cache_dir=str(tmp_path))
    with monkeypatch.context() as patch:
        Calls(patch, fail=("slide", 2))
        with pytest.raises(KeyboardInterrupt):
            K.reconstruct(scans, options)
    assert _entries(tmp_path, "kinematic-prepare") == 4
    assert _entries(tmp_path, "kinematic-fit") == 1 and _entries(tmp_path, "kinematic-urshape") == 1
    assert _entries(tmp_path, "kinematic-slide") == 1
    assert not list(tmp_path.glob(".*part*"))

    calls = Calls(monkeypatch)
    with caplog.at_level("INFO", logger="fourd"):
        resumed = K.reconstruct(scans, options)
    assert calls.counts == {"prepare": 0, "fit": 0, "slide": 2}
    assert "resumed: 4 of 4 frames' preparation from the cache" in caplog.text
    assert "resumed: the 4D fit from the cache" in caplog.text
    assert "resumed: 1 of 3 slid frames from the cache" in caplog.text
    _same(resumed, uninterrupted)


@pytest.mark.slow
def test_a_run_interrupted_while_preparing_prepares_only_the_missing_frames(
    scans, uninterrupted, tmp_path, monkeypatch
):
    options = K.Options(**TINY, cache_dir=str(tmp_path))
    with monkeypatch.context() as patch:
        Calls(patch, fail=("prepare", 3))
        with pytest.raises(KeyboardInterrupt):
            K.reconstruct(scans, options)
    kept = _entries(tmp_path, "kinematic-prepare")
    assert 2 <= kept < 4 and _entries(tmp_path, "kinematic-fit") == 0
    calls = Calls(monkeypatch)
    _same(K.reconstruct(scans, options), uninterrupted)
    assert calls.counts == {"prepare": 4 - kept, "fit": 1, "slide": 3}


@pytest.mark.slow
def test_a_changed_option_recomputes_the_stages_it_acts_on(scans, tmp_path, monkeypatch, caplog):
    folder = str(tmp_path)
    K.reconstruct(scans, K.Options(**TINY, cache_dir=folder))

    # a sliding option: the prepared frames and the fit are reused, every frame slid again
    calls = Calls(monkeypatch)
    changed = K.reconstruct(scans, K.Options(**TINY, iterations=2, cache_dir=folder))
    assert calls.counts == {"prepare": 0, "fit": 0, "slide": 3}
    calls.counts.update(prepare=0, fit=0, slide=0)
    _same(K.reconstruct(scans, K.Options(**TINY, iterations=2)), changed)

    # windows of the 4D fit: each window fitted (and kept) on its own
    calls.counts.update(prepare=0, fit=0, slide=0)
    K.reconstruct(scans, K.Options(**TINY, window=2, cache_dir=folder))
    assert calls.counts["prepare"] == 0 and calls.counts["fit"] == 2
    # the windows are loaded when the sliding needs them (not at all once every frame is
    # kept): without the slid frames, both are loaded, not fitted
    for path in tmp_path.glob("kinematic-slide-*.npz"):
        path.unlink()
    calls.counts.update(prepare=0, fit=0, slide=0)
    with caplog.at_level("INFO", logger="fourd"):
        K.reconstruct(scans, K.Options(**TINY, window=2, cache_dir=folder))
    assert calls.counts == {"prepare": 0, "fit": 0, "slide": 3}
    assert "resumed: the 4D fit of window 1 of 2 from the cache" in caplog.text
    assert "resumed: the 4D fit of window 2 of 2 from the cache" in caplog.text

    # an option of the preparation: everything computed again
    calls.counts.update(prepare=0, fit=0, slide=0)
    K.reconstruct(scans, K.Options(**TINY, outlier_factor=2.5, cache_dir=folder))
    assert calls.counts == {"prepare": 4, "fit": 1, "slide": 3}
