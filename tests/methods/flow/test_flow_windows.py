"""``flow`` in windows blended over the frames they share (issue 56): the same surfaces as one
solve over the sequence, no jump where one window hands over to the next, a streamed run that
writes what the run in memory gives, and a run that resumes window by window."""

import numpy as np
import pytest
import trimesh
from flow_scenes import _check_closed_manifold
from scipy.spatial import cKDTree

import fourd
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.io.npz import read_npz
from fourd.methods import flow

FRAMES, WINDOW, OVERLAP, RESOLUTION = 6, 4, 2, 14


@pytest.mark.parametrize("count", [2, 5, 20, 21, 24, 37, 40, 101])
@pytest.mark.parametrize(("window", "overlap"), [(20, 4), (5, 2), (6, 3), (2, 1)])
def test_windows_cover_every_frame_in_at_most_two(count, window, overlap):
    ranges = flow.window_ranges(count, window, overlap)
    assert ranges[0][0] == 0 and ranges[-1][1] == count - 1
    assert all(last - first + 1 <= window for first, last in ranges)
    windows_of = np.zeros(count, int)
    for first, last in ranges:
        windows_of[first : last + 1] += 1
    assert windows_of.min() == 1 and windows_of.max() <= 2
    for (a0, a1), (b0, b1) in zip(ranges, ranges[1:], strict=False):
        assert a0 < b0 and b1 > a1 and a1 - b0 + 1 >= overlap


def test_window_settings_are_checked():
    with pytest.raises(ValueError, match="window_overlap"):
        flow.Options(window=4, window_overlap=3)
    with pytest.raises(ValueError, match="window"):
        flow.Options(window=-1)
    scans = fourd.synth.scan(fourd.synth.scene("squash-ball", frames=3), resolution=16)
    with pytest.raises(InputError, match="window 2"):
        flow.run(scans, flow.Options(window=2, window_overlap=1))


@pytest.fixture(scope="module")
def squash():
    truth = fourd.synth.scene("squash-ball", frames=FRAMES)
    scans = fourd.synth.scan(truth, resolution=64, seed=0)
    one = flow.run(scans, flow.Options(resolution=RESOLUTION))
    options = flow.Options(resolution=RESOLUTION, window=WINDOW, window_overlap=OVERLAP)
    windowed = flow.reconstruct_with_diagnostics(scans, options)
    return scans, truth, one, windowed.result, options


def _mean_distance(a, b):
    return 0.5 * (cKDTree(a).query(b)[0].mean() + cKDTree(b).query(a)[0].mean())


@pytest.mark.slow
def test_windows_give_the_surfaces_of_one_solve(squash):
    _, truth, one, windowed, _ = squash
    h = one.grid.h
    true_volume = trimesh.Trimesh(truth.vertices[0], truth.faces).volume
    for (v1, _), (v2, f2) in zip(one.meshes.meshes, windowed.meshes, strict=True):
        _check_closed_manifold(v2, f2)
        distance = cKDTree(v1).query(v2)[0]
        assert np.median(distance) < 0.3 * h and np.percentile(distance, 95) < h
        # the windows enclose one volume (the squash ball's is constant)
        volume = trimesh.Trimesh(v2, f2, process=False).volume
        assert abs(volume - true_volume) < 0.05 * true_volume


@pytest.mark.slow
def test_no_jump_where_one_window_hands_over_to_the_next(squash):
    _, _, one, windowed, _ = squash
    # frames 2 and 3 are shared: the steps into, across and out of them move no farther than
    # the motion one solve follows
    h = one.grid.h
    for t in range(FRAMES - 1):
        step = _mean_distance(windowed.meshes[t][0], windowed.meshes[t + 1][0])
        assert step < _mean_distance(one.meshes.meshes[t][0], one.meshes.meshes[t + 1][0]) + 0.25 * h


@pytest.mark.slow
def test_streamed_resumes_window_by_window_and_writes_what_memory_gives(squash, tmp_path):
    scans, _, _, windowed, options = squash
    options = flow.Options(**{**options.__dict__, "cache_dir": str(tmp_path / "cache")})

    def read(i):
        if i == FRAMES - 1:
            raise InputError("is truncated", tmp_path / f"frame_{i}.ply")
        return scans.frames[i]

    with pytest.raises(InputError, match="truncated"):
        flow.reconstruct_streamed(FrameSource(scans.times, scans.names, read), tmp_path / "a.npz",
                                  options)
    assert not (tmp_path / "a.npz").exists()
    for resumed in (1, 2):  # the first window was kept before the bad frame; then both
        summary = flow.reconstruct_streamed(FrameSource.of(scans), tmp_path / "a.npz", options)
        assert (summary.windows, summary.resumed) == (2, resumed)
        written = read_npz(tmp_path / "a.npz")
        for (v, f), (vm, fm) in zip(written.meshes, windowed.meshes, strict=True):
            np.testing.assert_allclose(v, vm, atol=1e-5)  # float32 file
            np.testing.assert_array_equal(f, fm)
