"""``kinematic`` streamed window by window (issue 56): the same animated mesh as the windowed
run in memory, no jump at the seams, and nothing written when a frame is bad."""

import dataclasses

import numpy as np
import pytest

import fourd
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.meshes import median_edge_length
from fourd.io.npz import read_npz
from fourd.methods import kinematic as K
from fourd.methods.kinematic.stream import reconstruct_streamed

FRAMES, WINDOW = 16, 6


@pytest.fixture(scope="module")
def scans():
    return fourd.synth.scan(fourd.synth.scene("bending-arm", frames=FRAMES), resolution=96, seed=0)


def _streamed(scans, options, path):
    summary = reconstruct_streamed(FrameSource.of(scans), path, options)
    assert summary.frames == FRAMES and summary.windows == int(np.ceil(FRAMES / WINDOW))
    return read_npz(path)


def test_the_sliding_carries_its_state_across_windows(scans, tmp_path):
    # without the trajectory smoothing the streamed run is the in-memory one, step for step
    options = K.Options(template_vertices=800, window=WINDOW, temporal_smoothing=0)
    memory = K.reconstruct(scans, options)
    streamed = _streamed(scans, options, tmp_path / "a.npz")
    np.testing.assert_array_equal(streamed.faces, memory.faces)
    np.testing.assert_allclose(streamed.vertices, memory.vertices, atol=1e-5)  # float32 file
    np.testing.assert_array_equal(streamed.observed, memory.observed)
    np.testing.assert_allclose(streamed.rest, memory.rest, atol=1e-5)


def test_the_smoothing_reaches_across_the_seams(scans, tmp_path):
    options = K.Options(template_vertices=800, window=WINDOW)
    memory = K.reconstruct(scans, options)
    streamed = _streamed(scans, options, tmp_path / "b.npz")
    edge = median_edge_length(memory.rest, memory.faces)
    # only the motion test's scale (a median over the frames at hand) differs
    assert np.linalg.norm(streamed.vertices - memory.vertices, axis=2).max() < 0.1 * edge
    v = streamed.vertices
    second = np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=2).mean(axis=1)  # frames 1..T-2
    seams = np.arange(WINDOW, FRAMES, WINDOW)
    near = np.concatenate([seams - 1, seams - 2])
    assert second[near].max() < 1.5 * np.median(np.delete(second, near))


def test_a_bad_frame_stops_the_run_and_writes_nothing(scans, tmp_path):
    def read(i):
        if i == 9:
            raise InputError("is truncated", tmp_path / "frame_9.ply")
        return scans.frames[i]

    source = FrameSource(scans.times, scans.names, read)
    with pytest.raises(InputError, match="frame_9.ply"):
        reconstruct_streamed(
            source, tmp_path / "c.npz", K.Options(template_vertices=800, window=WINDOW)
        )
    assert list(tmp_path.iterdir()) == []


def test_streamed_runs_refuse_what_they_cannot_write(scans, tmp_path):
    with pytest.raises(InputError, match=r"\.npz"):
        reconstruct_streamed(FrameSource.of(scans), tmp_path / "out.glb")
    with pytest.raises(InputError, match="one frame per input frame"):
        reconstruct_streamed(
            FrameSource.of(scans), tmp_path / "out.npz", K.Options(times=(0.5, 1.5))
        )


def test_an_interrupted_run_resumes_after_its_last_window(scans, tmp_path):
    options = K.Options(template_vertices=800, window=WINDOW, cache_dir=str(tmp_path / "cache"))
    whole = _streamed(
        scans, K.Options(template_vertices=800, window=WINDOW), tmp_path / "whole.npz"
    )

    def read(i):  # the last window's frames cannot be read
        if i == FRAMES - 1:
            raise InputError("is truncated", tmp_path / "frame_15.ply")
        return scans.frames[i]

    with pytest.raises(InputError, match="frame_15.ply"):
        reconstruct_streamed(
            FrameSource(scans.times, scans.names, read), tmp_path / "a.npz", options
        )
    assert not (tmp_path / "a.npz").exists()
    summary = reconstruct_streamed(FrameSource.of(scans), tmp_path / "a.npz", options)
    assert summary.resumed == 2  # windows 0-5 and 6-11 came from the cache
    resumed = read_npz(tmp_path / "a.npz")
    np.testing.assert_array_equal(resumed.vertices, whole.vertices)
    np.testing.assert_array_equal(resumed.observed, whole.observed)
    assert reconstruct_streamed(FrameSource.of(scans), tmp_path / "b.npz", options).resumed == 3


@pytest.mark.slow
def test_windows_use_the_videos_anchors_and_colours_as_the_run_in_memory(tmp_path):
    """With video and points without colours, each window tracks the anchors of its frame
    pairs (the seam's included) and colours its points from the video, with the urshape's
    colours carried from the first window (through the cache too): the streamed run is the
    windowed run in memory, and the video changes it."""
    frames, window = 8, 4
    truth = fourd.synth.scene("bending-arm", frames=frames)
    filmed = fourd.synth.scan(
        truth, resolution=96, seed=0, appearance="cloth", video=True, video_resolution=64
    )
    filmed = dataclasses.replace(
        filmed, frames=tuple(dataclasses.replace(f, colors=None) for f in filmed.frames)
    )
    options = K.Options(template_vertices=800, window=window, temporal_smoothing=0)
    memory = K.reconstruct(filmed, options)
    cached = dataclasses.replace(options, cache_dir=str(tmp_path / "cache"))
    summary = reconstruct_streamed(FrameSource.of(filmed), tmp_path / "v.npz", cached)
    assert summary.windows == 2
    streamed = read_npz(summary.output)
    np.testing.assert_allclose(streamed.vertices, memory.vertices, atol=1e-5)  # float32 file
    np.testing.assert_array_equal(streamed.observed, memory.observed)
    last = max((tmp_path / "cache").iterdir(), key=lambda p: p.stat().st_mtime_ns)
    last.unlink()  # the second window again, after the first from the cache
    again = reconstruct_streamed(FrameSource.of(filmed), tmp_path / "r.npz", cached)
    assert again.resumed == 1
    np.testing.assert_array_equal(read_npz(again.output).vertices, streamed.vertices)
    plain = reconstruct_streamed(
        FrameSource.of(filmed),
        tmp_path / "p.npz",
        dataclasses.replace(options, video_anchors=False, color_guide=False),
    )
    moved = np.linalg.norm(read_npz(plain.output).vertices - streamed.vertices, axis=2)
    assert moved[-1].mean() > 0.01 * median_edge_length(memory.rest, memory.faces)


@pytest.mark.slow
def test_the_colour_guide_streams_with_the_points_own_colours(tmp_path):
    """Coloured points and no video: the urshape's colours come from the first frame's points
    and guide every window as in memory; without them the result differs."""
    truth = fourd.synth.scene("bending-arm", frames=8)
    coloured = fourd.synth.scan(truth, resolution=96, seed=0, appearance="cloth")
    options = K.Options(template_vertices=600, window=4, temporal_smoothing=0)
    memory = K.reconstruct(coloured, options)
    streamed = read_npz(
        reconstruct_streamed(FrameSource.of(coloured), tmp_path / "c.npz", options).output
    )
    np.testing.assert_allclose(streamed.vertices, memory.vertices, atol=1e-5)
    blind = dataclasses.replace(options, color_guide=False)
    plain = read_npz(
        reconstruct_streamed(FrameSource.of(coloured), tmp_path / "p.npz", blind).output
    )
    moved = np.linalg.norm(plain.vertices - streamed.vertices, axis=2)
    assert moved[-1].mean() > 0.1 * median_edge_length(memory.rest, memory.faces)
