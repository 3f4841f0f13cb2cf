"""``surfels`` window by window (:mod:`fourd.methods.surfels.stream`): a merge onto a held
past keeps its frames and its surfels; a turning blob streamed in windows turns with its
scans, without a jump at the seams, and a rerun resumes every window; the colours' guide holds
a sliding sheet window by window; bad settings are refused."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from fourd import synth
from fourd.animation import AnimatedMesh
from fourd.cache import NO_CACHE
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.rotations import procrustes
from fourd.methods import reconstruct
from fourd.methods.surfels import GaussNewtonOptions, Options, reconstruct_streamed
from fourd.methods.surfels.assembly import merge, optimize_model
from fourd.methods.surfels.pipeline import prepare_frames
from fourd.methods.surfels.stream import _with_anchors
from fourd.metrics.scores import evaluate
from fourd.sequence import Frame, PointCloudSequence

QUICK = dict(cg_iterations=50, iterations=3, final_iterations=2)


def test_a_merge_onto_a_held_past_keeps_its_frames_and_all_its_surfels_in_order(
    still_bumpy_scans, quick_seeds
):
    frames = still_bumpy_scans(3, np.random.default_rng(3))
    sampling = 4 * 0.02
    quick = GaussNewtonOptions(iterations=3, cg_tolerance=1e-3, cg_iterations=50)
    seeds, schedule = quick_seeds(frames, sampling, quick)
    past = merge(seeds[0], seeds[1], frames, schedule)
    count = past.state.count
    merged = merge(past, seeds[2], frames, schedule, held=1, kept=count)
    assert merged.state.frames == 3 and merged.state.count >= count
    # the held frame is the past's, exactly, surfel for surfel
    np.testing.assert_array_equal(merged.state.positions[0, :count], past.state.positions[0])
    # (the normals renormalised by each step: to the last bit)
    np.testing.assert_allclose(merged.state.normals[0, :count], past.state.normals[0], atol=1e-12)
    # the free frame stays where the past had it (a still surface), within the noise
    moved = np.linalg.norm(merged.state.positions[1, :count] - past.state.positions[1], axis=1)
    assert np.median(moved) < 0.1 * sampling
    # the new frame's own surfels duplicate the past's and are dropped (measured: 1.14 times;
    # 1.11 with nothing held)
    assert merged.state.count <= 1.3 * count
    with pytest.raises(ValueError, match="held"):
        optimize_model(past, frames, schedule.weights, quick, schedule.match, urshape="rest", held=1)


def test_a_short_window_or_another_reference_is_refused(tmp_path):
    rng = np.random.default_rng(0)
    seq = PointCloudSequence(
        tuple(Frame(rng.normal(size=(300, 3)), time=float(t)) for t in range(4))
    )
    with pytest.raises(InputError, match="at least 3 frames"):
        reconstruct_streamed(FrameSource.of(seq), tmp_path / "a.npz", Options(window=2))
    with pytest.raises(InputError, match="reference"):
        reconstruct_streamed(FrameSource.of(seq), tmp_path / "a.npz", Options(reference=1))
    assert not (tmp_path / "a.npz").exists()


@pytest.mark.slow
def test_a_turning_blob_in_windows_turns_with_its_scans_without_a_jump_and_resumes(
    tmp_path, caplog
):
    """Nine frames of the blob turning 6 degrees a frame, in windows of four: frames 0-1,
    2-5 and 6-8 written by three windows (seams between frames 1|2 and 5|6)."""
    frames = 9
    truth = synth.scene("rigid-turn", frames=frames, angle=6.0 * (frames - 1))
    scans = synth.scan(truth, resolution=64)
    options = dict(
        QUICK, window=4, fit_frames=False, urshape="off", cache_dir=str(tmp_path / "cache")
    )
    anim = reconstruct(scans, method="surfels", **options)
    assert anim.vertices.shape[0] == frames and anim.vertices.shape[1] > 500
    spacing = point_spacing(scans.frames[0].points)
    sampling = Options().sampling * spacing
    for t in range(frames):
        points, vertices = scans.frames[t].points, anim.vertices[t]
        # measured: the mesh 0.70-0.83 point spacings from the scan (mean), the scan 1.46-1.83
        # from the mesh, growing as the turn shows surface that frame 0's mesh lacks (a
        # stream cannot add it to frames already written)
        assert cKDTree(points).query(vertices)[0].mean() <= 1.0 * spacing, t
        assert cKDTree(vertices).query(points)[0].mean() <= 2.2 * spacing, t
    # the known rigid motion carries frame 0 onto frame t (measured: 0.17-0.25 of the
    # motion; in one solve 0.16-0.20)
    for t in range(1, frames):
        fit = procrustes(truth.vertices[0], truth.vertices[t])
        expected = anim.vertices[0] @ fit.rotation.T + fit.translation
        error = np.linalg.norm(anim.vertices[t] - expected, axis=1).mean()
        motion = np.linalg.norm(anim.vertices[0] - expected, axis=1).mean()
        assert error <= 0.3 * motion, t
    # second differences of the positions (the turn's own is about 0.04 eps_sampl): measured
    # 0.03-0.07 inside the windows, 0.13 and 0.10 at the seams (one solve: 0.03-0.04
    # everywhere; without the unwritten frames optimised again, 0.15 at a seam)
    bend = np.linalg.norm(
        anim.vertices[2:] - 2 * anim.vertices[1:-1] + anim.vertices[:-2], axis=2
    ).mean(axis=1) / sampling
    assert bend[[0, 4]].max() <= 0.2 and np.delete(bend, [0, 4]).max() <= 0.1
    assert anim.observed.mean() > 0.9
    with caplog.at_level("INFO", logger="fourd.methods.surfels"):
        again = reconstruct(scans, method="surfels", **options)
    resumed = [r.getMessage() for r in caplog.records if "the window of frames" in r.getMessage()]
    assert len(resumed) == 3
    np.testing.assert_array_equal(again.faces, anim.faces)
    np.testing.assert_allclose(again.vertices, anim.vertices, atol=1e-6)
    # options that act only on the mesh (its holes, its fit to the points) keep the windows
    caplog.clear()
    with caplog.at_level("INFO", logger="fourd.methods.surfels"):
        reconstruct(scans, method="surfels", **{**options, "close_holes": 0.0, "fit_frames": True})
    resumed = [r.getMessage() for r in caplog.records if "the window of frames" in r.getMessage()]
    assert len(resumed) == 3


def test_each_window_tracks_its_pairs_and_the_seams_from_the_past():
    truth = synth.scene("rigid-turn", frames=4, angle=18.0)
    scans = synth.scan(truth, resolution=64, appearance="cloth", video=True, outliers=0)
    source = FrameSource.of(scans)
    spacing = point_spacing(scans.frames[0].points)
    frames, _ = prepare_frames(scans.frames, spacing, Options(), NO_CACHE)
    tail, first = _with_anchors([], frames[:2], source, 0)
    assert tail == [] and first[0].forward is not None and first[1].forward is None
    tail, second = _with_anchors(first, frames[2:], source, 2)
    # the past's last frame gets the seam's pair into frame 2; the window's last has none yet
    assert tail[0] is first[0] and second[-1].forward is None
    seam = tail[1].forward
    assert len(seam.source) > 20
    assert cKDTree(frames[1].points).query(seam.source)[0].max() < 1e-9
    # the anchors follow the known turn (measured: median 0.5 point spacings off)
    fit = procrustes(truth.vertices[1], truth.vertices[2])
    expected = seam.source @ fit.rotation.T + fit.translation
    assert np.median(np.linalg.norm(seam.target - expected, axis=1)) < spacing


@pytest.mark.slow
def test_the_colours_guide_holds_a_sliding_sheet_window_by_window():
    """The first six frames of the waving sheet in printed cloth with the rig's video, in
    windows of three (two windows, one seam), the video's anchors off: geometry alone lets the
    surfels slide along the sheet with the wave; the colours' guide holds them, across the
    seam too, as in memory."""
    truth = synth.scene("waving-sheet", frames=20)
    scans = synth.scan(truth, resolution=64, appearance="cloth", video=True)
    truth = AnimatedMesh(truth.faces, truth.vertices[:6], truth.times[:6])
    scans = PointCloudSequence(scans.frames[:6], scans.names[:6], scans.video.select(slice(0, 6)))
    options = dict(QUICK, window=3, video_anchors=False)
    score = evaluate(reconstruct(scans, method="surfels", **options), truth, samples=20000)
    # measured: Chamfer / correspondence mean / last 0.0032 / 0.0031 / 0.0047; with
    # color_guide=false (not run here, to keep the suite short) 0.0032 / 0.0442 / 0.0875
    assert score["correspondence_mean"] < 0.01
    assert score["correspondence_last"] < 0.015
    assert score["chamfer"] < 0.004
