"""The bench suite: named scenes (held-out stretches, a held pose, a clean scan) and method specs."""

from __future__ import annotations

import pytest

from fourd.bench import report, suite
from fourd.errors import InputError


def test_held_out_stretches_of_a_capture_are_named_scenes():
    """``crane-90``: the crane capture from frame 90, same length and step as the standard
    crane scene, selectable by its label and not run by default."""
    (chosen,) = suite.select_scenes(["crane-90"], quick=False)
    standard = {s.key: s for s in suite.STANDARD_SCENES}["crane"]
    assert chosen.key == "crane-90" and chosen.name == "crane"
    assert chosen.options == {**standard.options, "start": 90}
    assert chosen.frames == standard.frames and chosen.resolution == standard.resolution
    assert "crane-90" not in {s.key for s in suite.select_scenes(None, quick=False)}
    assert "From frame 90 on." in report._describe("crane", chosen.options)


def test_a_held_still_pose_is_a_named_scene():
    """``crane-still``: the first crane pose 20 times (each frame scanned anew), not run by
    default."""
    (chosen,) = suite.select_scenes(["crane-still"], quick=False)
    assert chosen.name == "crane" and chosen.options == {"start": 0, "step": 0}
    assert "crane-still" not in {s.key for s in suite.select_scenes(None, quick=False)}
    assert "held still" in report._describe("crane", chosen.options)


def test_method_specs_carry_options():
    assert suite.parse_method_spec("flow:coherent=true, resolution=40") == (
        "flow",
        {"coherent": "true", "resolution": "40"},
    )
    assert suite.parse_method_spec("perframe") == ("perframe", {})
    with pytest.raises(InputError, match="expected key=value"):
        suite.parse_method_spec("flow:coherent")
    with pytest.raises(InputError, match="valid keys"):
        suite.select_methods(["perframe:no_such_option=1"], quick=False)
    with pytest.raises(InputError, match="unknown method"):
        suite.select_methods(["nope:x=1"], quick=False)


def test_a_method_spec_takes_list_values_as_set_does():
    """``flow:missing_frames=1,2`` (issue 49): a comma not followed by ``key=`` continues the
    value before it, so a spec takes every value ``--set`` takes."""
    from fourd.options import parse_assignments

    name, values = suite.parse_method_spec("flow:missing_frames=1,2,resolution=64")
    assert (name, values) == ("flow", {"missing_frames": "1,2", "resolution": "64"})
    assert values == parse_assignments(["missing_frames=1,2", "resolution=64"])
    assert suite.parse_method_spec("flow:resolution=64, missing_frames=1, 2 ,3") == (
        "flow",
        {"resolution": "64", "missing_frames": "1, 2 ,3"},
    )
    assert suite.parse_method_spec("flow:missing_frames=1,2,")[1] == {"missing_frames": "1,2"}
    with pytest.raises(InputError, match="expected key=value, got '1'"):
        suite.parse_method_spec("flow:1,missing_frames=2")


def test_a_method_spec_with_a_list_value_is_a_valid_bench_row():
    from fourd.methods import method_options

    spec = "flow:missing_frames=1,2,resolution=64"
    assert suite.select_methods([spec], quick=False) == [spec]
    options = method_options("flow", suite.parse_method_spec(spec)[1])
    assert options.missing_frames == (1, 2) and options.resolution == 64


def test_a_scene_may_carry_an_appearance_and_video():
    assert suite.BenchScene("squash-ball").appearance is None
    assert suite.BenchScene("squash-ball", appearance="skin").appearance == "skin"
    filmed = suite.BenchScene("squash-ball", video=True)
    assert filmed.appearance == "cloth" and filmed.video  # video films a printed surface
    with pytest.raises(InputError, match="unknown appearance"):
        suite.BenchScene("squash-ball", appearance="velvet")


def test_the_whole_crane_capture_is_a_bench_scene_at_three_densities():
    dense, mid, sparse = suite.select_scenes(["crane-full", "crane-full-mid", "crane-full-sparse"], quick=False)
    assert dense.frames == mid.frames == sparse.frames == 175 and dense.options == {"start": 0, "step": 1}
    assert sparse.resolution < mid.resolution < dense.resolution
    assert "crane-full" not in {s.key for s in suite.STANDARD_SCENES}  # run on request only
