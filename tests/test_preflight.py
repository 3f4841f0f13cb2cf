"""The checks before the work (fourd.preflight): each fires before the method runs, in well
under a second, with a message naming what to change."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

import fourd
import fourd.preflight as preflight
from fourd import Frame, InputError, PointCloudSequence
from fourd.methods import method_module, method_options
from fourd.preflight import (
    available_memory,
    check_frame_sizes,
    check_input,
    check_memory,
    check_result_format,
    check_times,
)


def _sphere(count=400, seed=0, shift=0.0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(count, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True) + shift


def _sequence(counts, names=None):
    frames = tuple(Frame(_sphere(c, seed=t, shift=0.05 * t), time=t) for t, c in enumerate(counts))
    return PointCloudSequence(frames, names or ())


@pytest.fixture
def no_method_runs(monkeypatch):
    """Every registered method's reconstruct fails the test when it is called."""

    def fail(*args, **kwargs):
        raise AssertionError("the method ran before the checks refused")

    for name in ("auto", "kinematic", "flow", "watertight", "perframe"):
        module = method_module(name)
        monkeypatch.setattr(module, "reconstruct", fail)
        if hasattr(module, "reconstruct_with_diagnostics"):
            monkeypatch.setattr(module, "reconstruct_with_diagnostics", fail)


def test_each_frame_with_too_few_points_is_named(caplog):
    seq = _sequence([400, 5, 400, 12], names=["a.ply", "b.ply", "c.ply", "d.ply"])
    with caplog.at_level(logging.WARNING, logger="fourd.preflight"):
        assert check_frame_sizes(seq) == [1, 3]
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2
    assert lines[0].startswith("frame 1 (b.ply, time 1) has 5 points, fewer than the 20")
    assert "frame 3 (d.ply, time 3) has 12 points" in lines[1]
    assert all("shape will come from the other frames" in line for line in lines)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="fourd.preflight"):
        check_frame_sizes(seq, per_frame=True)
    assert "mesh will be empty" in caplog.records[0].getMessage()


def test_many_small_frames_are_summed_up_and_all_small_is_an_error(caplog):
    seq = _sequence([400] + [8] * 15)
    with caplog.at_level(logging.WARNING, logger="fourd.preflight"):
        assert len(check_frame_sizes(seq)) == 15
    assert len(caplog.records) == preflight.LISTED_FRAMES + 1
    assert caplog.records[-1].getMessage().startswith("and 5 more frames with fewer than 20 points")
    with pytest.raises(
        InputError,
        match=r"every frame has fewer than 20 points \(the most, 9, in frame 1, frame_1\)",
    ):
        check_frame_sizes(_sequence([8, 9, 7]))


def test_output_times_outside_the_input_warn_that_they_extrapolate(caplog):
    seq = _sequence([400] * 3)
    options = method_options("kinematic", {"times": "-0.5, 0, 1.5, 2, 4"})
    with caplog.at_level(logging.WARNING, logger="fourd.preflight"):
        assert check_times(seq, options) == [-0.5, 4.0]
    (record,) = caplog.records
    assert "output times -0.5, 4 lie outside the input's time range 0 to 2" in record.getMessage()
    assert "extrapolated" in record.getMessage()
    caplog.clear()
    check_times(seq, method_options("kinematic", {"times": "0, 0.5, 2"}))
    check_times(seq, method_options("perframe"))
    assert not caplog.records


def test_memory_refusal_names_the_option(monkeypatch):
    monkeypatch.setattr(preflight, "available_memory", lambda: 2 * 2**30)
    seq = _sequence([400] * 3)
    module = method_module("flow")
    options = method_options("flow", {"resolution": "1000", "neighbourhood": "27"})
    with pytest.raises(InputError) as info:
        check_memory(seq, "flow", module, options)
    message = str(info.value)
    assert message.startswith("method 'flow' would need about ")
    assert (
        "(resolution=1000, neighbourhood=27, 3 frames; an estimate) but 2.0 GiB is available"
        in message
    )
    assert message.endswith("lower resolution or reconstruct fewer frames")
    assert check_memory(seq, "flow", module, method_options("flow")) < 2 * 2**30
    assert (
        check_memory(seq, "perframe", method_module("perframe"), method_options("perframe")) is None
    )
    monkeypatch.setattr(preflight, "available_memory", lambda: None)
    assert check_memory(seq, "flow", module, options) is None


def test_available_memory_reads_meminfo_a_cgroup_limit_or_psutil(tmp_path, monkeypatch):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal: 100 kB\nMemAvailable:    2048 kB\n")
    monkeypatch.setattr(preflight, "MEMINFO", meminfo)
    monkeypatch.setattr(preflight, "CGROUP", tmp_path / "no-cgroup")
    assert available_memory() == 2048 * 1024
    cgroup = tmp_path / "cgroup"
    cgroup.mkdir()
    (cgroup / "memory.max").write_text("1000000\n")
    (cgroup / "memory.current").write_text("900000\n")
    (cgroup / "memory.stat").write_text("anon 5\ninactive_file 50000\n")
    monkeypatch.setattr(preflight, "CGROUP", cgroup)
    assert available_memory() == 150000
    (cgroup / "memory.max").write_text("max\n")
    assert available_memory() == 2048 * 1024
    monkeypatch.setattr(preflight, "MEMINFO", tmp_path / "missing")
    import sys
    import types

    monkeypatch.setitem(
        sys.modules,
        "psutil",
        types.SimpleNamespace(virtual_memory=lambda: types.SimpleNamespace(available=12345)),
    )
    assert available_memory() == 12345
    monkeypatch.setitem(sys.modules, "psutil", None)  # not installed: no check
    assert available_memory() is None


def test_this_machine_tells_its_memory():
    memory = available_memory()
    assert memory is None or memory > 0


def test_per_frame_meshes_cannot_go_to_a_point_cache():
    for name in ("perframe", "flow"):
        with pytest.raises(InputError) as info:
            check_result_format(name, method_module(name), "pc2", "walk.pc2")
        assert str(info.value) == (
            f"walk.pc2: a .pc2 file holds one mesh connectivity for all frames, but method "
            f"'{name}' gives a mesh per frame, each with its own: use --method auto, kinematic, "
            "surfels, watertight, learned, garment or assembly, or write .npz, .glb, .usd, .abc or a folder"
        )
        for kind in ("npz", "glb", "usd", "abc", "folder"):
            check_result_format(name, method_module(name), kind)
    # the default may give either; its MeshSequence is baked into one connectivity later
    for name in ("auto", "kinematic", "watertight"):
        check_result_format(name, method_module(name), "pc2")


@pytest.mark.usefixtures("no_method_runs")
def test_reconstruct_checks_before_the_method_runs(monkeypatch):
    monkeypatch.setattr(preflight, "available_memory", lambda: 2**30)
    seq = _sequence([400] * 3)
    start = time.perf_counter()
    with pytest.raises(InputError, match="resolution=100000"):
        fourd.reconstruct(seq, method="flow", resolution=100_000)
    with pytest.raises(InputError, match="resolution=100000"):
        fourd.methods.reconstruct_with_diagnostics(seq, method="auto", resolution=100_000)
    with pytest.raises(InputError, match="every frame has fewer than 20 points"):
        fourd.reconstruct(_sequence([10, 10]), method="perframe")
    assert time.perf_counter() - start < 1.0
    # check_memory=False leaves the memory to the method
    with pytest.raises(AssertionError, match="the method ran"):
        fourd.reconstruct(seq, method="flow", resolution=100_000, check_memory=False)


def test_check_input_runs_every_check(monkeypatch, caplog):
    monkeypatch.setattr(preflight, "available_memory", lambda: 2**40)
    seq = _sequence([400, 6, 400])
    module = method_module("kinematic")
    with caplog.at_level(logging.WARNING, logger="fourd.preflight"):
        check_input(seq, "kinematic", module, method_options("kinematic", {"times": "0, 3"}))
    messages = " | ".join(r.getMessage() for r in caplog.records)
    assert "frame 1 (frame_1, time 1) has 6 points" in messages
    assert "output times 3 lie outside" in messages


def test_memory_refusal_suggests_windows_where_they_fit(monkeypatch):
    from fourd.methods import flow

    seq = _sequence([400] * 60)
    options = method_options("flow")
    whole = flow.estimate_peak_bytes(seq, options)
    windowed = flow.estimate_peak_bytes(seq, flow.Options(window=preflight.SUGGESTED_WINDOW))
    assert windowed < 0.5 * whole
    monkeypatch.setattr(preflight, "available_memory", lambda: (whole + windowed) // 2)
    with pytest.raises(InputError) as info:
        check_memory(seq, "flow", method_module("flow"), options)
    assert str(info.value).endswith(
        "reconstruct fewer frames, or run it window by window (--stream, or --set window=20: "
        f"about {preflight._size(windowed)})"
    )
    monkeypatch.setattr(preflight, "available_memory", lambda: windowed // 2)
    with pytest.raises(InputError) as info:
        check_memory(seq, "flow", method_module("flow"), options)
    assert str(info.value).endswith("reconstruct fewer frames")  # windows would not fit either
    # watertight streams its flow in the same windows: the same suggestion
    monkeypatch.setattr(preflight, "available_memory", lambda: (whole + windowed) // 2)
    with pytest.raises(InputError) as info:
        check_memory(seq, "watertight", method_module("watertight"), method_options("watertight"))
    assert str(info.value).endswith(f"--set window=20: about {preflight._size(windowed)})")
