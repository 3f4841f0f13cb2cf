"""Method ``flow`` with ``cache_dir``: an interrupted run resumes after its last finished stage
(the labels, each IRLS iteration with the AMG hierarchy the next one reuses, the solve, the
meshes) with the same result, and a changed option recomputes what it acts on."""

import dataclasses

import numpy as np
import pytest

import fourd
from fourd.methods import flow
from fourd.methods.flow import irls, pipeline

#: A grid of a few thousand cells and short MINRES solves: seconds per run.
TINY = {"resolution": 10, "max_outer": 8}


@pytest.fixture(scope="module")
def scans():
    truth = fourd.synth.scene("squash-ball", frames=3)
    return fourd.synth.scan(truth, resolution=64, seed=0)


@pytest.fixture(scope="module")
def uninterrupted(scans):
    return flow.run(scans, flow.Options(**TINY))


class Calls:
    """Counts the calls of the stages; ``fail`` raises KeyboardInterrupt at the given call of
    one of them (the interruption)."""

    def __init__(self, monkeypatch, fail: tuple[str, int] | None = None):
        self.counts = {"labels": 0, "solve": 0, "post": 0}
        for name, module, attribute in (
            ("labels", pipeline, "_labels"),
            ("solve", irls, "solve_saddle"),
            ("post", pipeline, "_post"),
        ):
            monkeypatch.setattr(module, attribute, self._counted(name, getattr(module, attribute), fail))

    def _counted(self, name, function, fail):
        def counted(*args, **kwargs):
            self.counts[name] += 1
            if fail == (name, self.counts[name]):
                raise KeyboardInterrupt
            return function(*args, **kwargs)

        return counted

    def reset(self):
        self.counts.update(labels=0, solve=0, post=0)


def _same(a, b):
    assert np.array_equal(a.x, b.x) and np.array_equal(a.mass, b.mass)
    assert np.array_equal(a.field.values, b.field.values)
    for (va, fa), (vb, fb) in zip(a.meshes.meshes, b.meshes.meshes, strict=True):
        assert np.array_equal(va, vb) and np.array_equal(fa, fb)


def _entries(folder, stage):
    return len(list(folder.glob(f"{stage}-*.npz")))


@pytest.mark.slow
def test_a_solve_interrupted_after_two_iterations_resumes_with_the_third(
    scans, uninterrupted, tmp_path, monkeypatch, caplog
):
    assert uninterrupted.history[-1]["iteration"] == 2  # three solves, all of them needed
    options = flow.Options(**TINY, cache_dir=str(tmp_path))
    with monkeypatch.context() as patch:
        Calls(patch, fail=("solve", 3))
        with pytest.raises(KeyboardInterrupt):
            flow.run(scans, options)
    # the labels, and only the last iteration's state (the earlier ones are dropped)
    assert _entries(tmp_path, "flow-labels") == 1 and _entries(tmp_path, "flow-iteration") == 1
    assert _entries(tmp_path, "flow-irls") == 0 and not list(tmp_path.glob(".*part*"))

    calls = Calls(monkeypatch)
    with caplog.at_level("INFO", logger="fourd"):
        resumed = flow.run(scans, options)
    assert calls.counts == {"labels": 0, "solve": 1, "post": 1}
    assert "resumed: the flow's grid, visual hull and initial labels from the cache" in caplog.text
    assert "resumed: 2 flow iterations from the cache" in caplog.text
    _same(resumed, uninterrupted)
    assert [h["iteration"] for h in resumed.history] == [0, 1, 2]
    # once solved, the iterations' states (with their AMG hierarchies) are removed
    assert _entries(tmp_path, "flow-iteration") == 0 and _entries(tmp_path, "flow-irls") == 1

    calls.reset()
    _same(flow.run(scans, options), uninterrupted)
    assert calls.counts == {"labels": 0, "solve": 0, "post": 0}


@pytest.mark.slow
def test_a_changed_option_recomputes_the_stages_it_acts_on(scans, tmp_path, monkeypatch):
    folder = str(tmp_path)
    flow.run(scans, flow.Options(**TINY, cache_dir=folder))
    calls = Calls(monkeypatch)

    # an option of the meshes only: the solve is reused
    flow.run(scans, flow.Options(**TINY, min_component=0.2, cache_dir=folder))
    assert calls.counts == {"labels": 0, "solve": 0, "post": 1}

    # an option of the solve: the labels are reused, the solve and the meshes recomputed
    calls.reset()
    flow.run(scans, flow.Options(**TINY, clamp=0.1, cache_dir=folder))
    assert calls.counts["labels"] == 0 and calls.counts["solve"] >= 1 and calls.counts["post"] == 1

    # other data (one frame's points): everything recomputed
    calls.reset()
    frames = list(scans.frames)
    frames[1] = dataclasses.replace(frames[1], points=frames[1].points * 1.01)
    flow.run(fourd.PointCloudSequence(frames), flow.Options(**TINY, cache_dir=folder))
    assert calls.counts["labels"] == 1 and calls.counts["solve"] >= 1 and calls.counts["post"] == 1
