"""The registered method ``surfels`` end to end on a small scan: one connectivity, every
frame on its own input, a rigid motion recovered, the fit to the frames closer to the truth;
and its checks on the input."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial import cKDTree

from fourd import synth
from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.rotations import procrustes
from fourd.methods import method_module, reconstruct
from fourd.methods.base import check_method_module
from fourd.methods.surfels import Options
from fourd.metrics.scores import evaluate
from fourd.sequence import Frame, PointCloudSequence

#: A coarse, quick run: the rigidly turning blob, 6 degrees a frame, 64 rays per camera side.
QUICK = dict(cg_iterations=50, iterations=3, final_iterations=2)


def test_the_method_keeps_the_contract():
    module = method_module("surfels")
    assert check_method_module(module) == []
    assert module.RESULT is AnimatedMesh and module.MIN_FRAMES == 2


def test_options_refuse_bad_values():
    with pytest.raises(ValueError, match="sampling"):
        Options(sampling=0)
    with pytest.raises(ValueError, match="rigid"):
        Options(rigid=-1)
    for workers in (-1, 1.5):
        with pytest.raises(ValueError, match="workers"):
            Options(workers=workers)


def test_merges_of_another_revision_are_not_resumed(tmp_path, monkeypatch):
    from fourd.cache import StageCache
    from fourd.methods.surfels import pipeline

    cache = StageCache(str(tmp_path))
    before = pipeline.merge_keys(["frame"], Options(), cache)
    assert pipeline.merge_keys(["frame"], Options(), cache) == before
    monkeypatch.setattr(pipeline, "MERGES_REVISION", pipeline.MERGES_REVISION + 1)
    assert pipeline.merge_keys(["frame"], Options(), cache) != before


@pytest.mark.parametrize(
    "options, optimised",
    [
        ({}, False),  # the defaults: 4 final steps stand in for the last merge's 4
        ({"final_iterations": 2}, True),  # a shorter final pass does not
        ({"final_iterations": 0}, True),  # nor does none
        ({"last_merge_optimised": True}, True),  # the paper's way
    ],
)
def test_the_final_pass_stands_in_for_the_last_merges_optimisation_only_when_as_long(
    monkeypatch, options, optimised
):
    from fourd.methods.surfels import pipeline

    class Assembled(Exception):
        pass

    def assemble(*args, optimise_last, **kwargs):
        raise Assembled(optimise_last)

    monkeypatch.setattr(pipeline, "assemble", assemble)
    scans = synth.scan(synth.scene("rigid-turn", frames=2), resolution=32)
    with pytest.raises(Assembled) as caught:
        pipeline.reconstruct(scans, Options(**options))
    assert caught.value.args == (optimised,)


def test_the_lower_merges_keys_do_not_depend_on_the_last_merges_way(tmp_path):
    """Only the last merge depends on ``last_merge_optimised`` (its key is salted in
    ``assemble``), so switching it resumes every lower merge."""
    from fourd.cache import StageCache
    from fourd.methods.surfels import pipeline

    cache = StageCache(str(tmp_path))
    keys = [pipeline.merge_keys(["frame"], Options(**o), cache) for o in
            ({}, {"last_merge_optimised": True}, {"final_iterations": 2}, {"iterations": 2})]
    assert keys[0] == keys[1] == keys[2] != keys[3]


def test_frames_side_by_side_are_prepared_and_seeded_as_one_after_another():
    """The per-frame stages on two threads give each frame's result to the last bit, in the
    frames' order, and a frame without a surface still names itself."""
    from fourd.cache import NO_CACHE
    from fourd.methods.surfels import pipeline
    from fourd.pipeline.worker_threads import concurrent_kernels_safe

    scans = synth.scan(synth.scene("rigid-turn", frames=4, angle=12.0), resolution=48)
    spacing = point_spacing(scans.frames[0].points)
    runs = []
    for workers in (1, 2):
        options = Options(workers=workers, **QUICK)
        frames, keys = pipeline.prepare_frames(scans.frames, spacing, options, NO_CACHE)
        schedule = pipeline.assembly_schedule(options, spacing, options.sampling * spacing)
        seeds = pipeline.seed_models(frames, range(4), options.sampling * spacing, schedule, options)
        runs.append((frames, seeds))
    assert concurrent_kernels_safe()  # so the second run's threads ran
    (frames_one, seeds_one), (frames_two, seeds_two) = runs
    for frame_a, seed_a, frame_b, seed_b in zip(frames_one, seeds_one, frames_two, seeds_two, strict=True):
        np.testing.assert_array_equal(frame_a.points, frame_b.points)
        np.testing.assert_array_equal(frame_a.normals, frame_b.normals)
        assert seed_a.start == seed_b.start
        np.testing.assert_array_equal(seed_a.state.positions, seed_b.state.positions)
        np.testing.assert_array_equal(seed_a.topology.edges, seed_b.topology.edges)
    assert [seed.start for seed in seeds_two] == [0, 1, 2, 3]
    empty = Frame(np.random.default_rng(0).uniform(-1, 1, (40, 3)))  # no surface, only noise
    with pytest.raises(InputError, match="frame 2 has no smooth surface"):
        pipeline.prepare_frames([*scans.frames[:2], empty, scans.frames[3]], spacing,
                                Options(workers=2), NO_CACHE)


def test_one_frame_or_a_frame_outside_is_refused():
    rng = np.random.default_rng(0)
    frame = Frame(rng.normal(size=(500, 3)))
    with pytest.raises(InputError, match="at least 2 frames"):
        reconstruct(PointCloudSequence((frame,)), method="surfels")
    with pytest.raises(InputError, match="reference"):
        method_module("surfels").reconstruct(
            PointCloudSequence((frame, Frame(frame.points, time=1.0))), Options(reference=5)
        )


@pytest.mark.slow
def test_a_turning_blob_comes_out_on_its_scans_and_turning_with_them():
    frames = 3
    truth = synth.scene("rigid-turn", frames=frames, angle=6.0 * (frames - 1))
    scans = synth.scan(truth, resolution=64)
    # the paper's mesh: the fit to the frames would move each frame onto its own noise, off
    # the urshape (that fit's own test is below)
    anim = reconstruct(scans, method="surfels", fit_frames=False, **QUICK)
    assert isinstance(anim, AnimatedMesh)
    assert anim.vertices.shape[0] == frames and anim.vertices.shape[1] > 500
    spacing = point_spacing(scans.frames[0].points)
    sampling = Options().sampling * spacing
    # the rest is the urshape: the mesh carried to it, the shape of every frame
    assert not np.allclose(anim.rest, anim.vertices[0])
    for t in range(frames):
        fit = procrustes(anim.rest, anim.vertices[t])
        gap = np.linalg.norm(
            anim.rest @ fit.rotation.T + fit.translation - anim.vertices[t], axis=1
        )
        # measured: 0.007-0.009 eps_sampl mean, 95th percentile 0.017
        assert gap.mean() < 0.03 * sampling
    for t in range(frames):
        points, vertices = scans.frames[t].points, anim.vertices[t]
        chamfer = 0.5 * (
            cKDTree(points).query(vertices)[0].mean() + cKDTree(vertices).query(points)[0].mean()
        )
        # measured: 1.04-1.06 point spacings (the mesh ends a little short of the scan's
        # borders, the surfels are 4 spacings apart)
        assert chamfer <= 1.3 * spacing
    # the known rigid motion carries frame 0 of the result onto its frame t
    for t in range(1, frames):
        fit = procrustes(truth.vertices[0], truth.vertices[t])
        expected = anim.vertices[0] @ fit.rotation.T + fit.translation
        error = np.linalg.norm(anim.vertices[t] - expected, axis=1).mean()
        motion = np.linalg.norm(anim.vertices[0] - expected, axis=1).mean()
        # measured: 0.15 of the motion at frames 1 and 2 (0.12 eps_sampl); 0.10 with the
        # paper's 85th-percentile cutoff in the alignment (align_percentile), which at 64 rays
        # drops the surface the turn brings into view at the border; no difference at the
        # bench's 256 rays (benchmarks/METHODS.md)
        assert error <= 0.2 * motion and error <= 0.15 * sampling
    assert anim.observed.mean() > 0.9


@pytest.mark.slow
def test_surface_seen_only_later_is_in_the_first_frame_not_observed_there():
    rng = np.random.default_rng(4)

    def sheet(count, x_max):
        x = rng.uniform(-1, x_max, count)
        y = rng.uniform(-0.6, 0.6, count)
        z = 0.1 * np.sin(2 * x) * np.cos(2 * y) + rng.normal(scale=0.003, size=count)
        return np.c_[x, y, z]

    sensors = np.array([[0.0, 0.0, 3.0]])
    frames = (
        Frame(sheet(800, 0.0), time=0.0, sensors=sensors),  # the left half only
        Frame(sheet(1600, 1.0), time=1.0, sensors=sensors),
        Frame(sheet(1600, 1.0), time=2.0, sensors=sensors),
    )
    anim = reconstruct(PointCloudSequence(frames), method="surfels", **QUICK)
    first = anim.vertices[0]
    right = first[:, 0] > 0.3
    # the right half, seen from frame 1 on, is in frame 0's mesh ...
    assert right.sum() > 0.2 * len(first) and first[:, 0].max() > 0.8
    # ... filled in there, observed where frame 0 had points
    assert anim.observed[0, right].mean() < 0.1
    assert anim.observed[0, first[:, 0] < -0.3].mean() > 0.9
    assert anim.observed[1:, right].mean() > 0.9


@pytest.mark.slow
def test_a_rerun_with_a_cache_resumes_every_stage_and_gives_the_same_result(tmp_path, caplog):
    truth = synth.scene("rigid-turn", frames=3, angle=12.0)
    scans = synth.scan(truth, resolution=48)
    options = dict(QUICK, cache_dir=str(tmp_path / "cache"))
    first = reconstruct(scans, method="surfels", **options)
    with caplog.at_level("INFO", logger="fourd.methods.surfels"):
        again = reconstruct(scans, method="surfels", **options)
    resumed = [r.getMessage() for r in caplog.records if r.getMessage().startswith("resumed")]
    assert sum("preprocessing" in line for line in resumed) == 3
    assert sum("merge" in line for line in resumed) == 2
    assert np.array_equal(first.faces, again.faces)
    assert np.allclose(first.vertices, again.vertices)


def test_the_merges_are_kept_for_the_points_colours_they_were_guided_by(tmp_path, caplog):
    """The colours' guide acts in the merges, so a rerun resumes them for the same colours and
    merges again for others."""
    truth = synth.scene("rigid-turn", frames=3, angle=12.0)
    scans = synth.scan(truth, resolution=48, appearance="cloth")
    options = dict(QUICK, cache_dir=str(tmp_path / "cache"))

    def resumed_merges(seq):
        caplog.clear()
        with caplog.at_level("INFO", logger="fourd.methods.surfels"):
            reconstruct(seq, method="surfels", **options)
        return sum(r.getMessage().startswith("resumed") and "merge" in r.getMessage()
                   for r in caplog.records)

    recoloured = PointCloudSequence(
        [dataclasses.replace(f, colors=1.0 - f.colors) for f in scans.frames], scans.names
    )
    assert resumed_merges(scans) == 0
    assert resumed_merges(scans) == 2
    assert resumed_merges(recoloured) == 0
    assert resumed_merges(scans) == 2


@pytest.mark.slow
def test_touching_spheres_are_not_glued_in_any_frame():
    from fourd.geometry.meshes import vertex_components

    # the spheres 0.3 apart in frames 0 and 2 (beyond eps_top, 0.2 at this scan), touching at
    # frame 1: each moves 0.15 a frame. The scene's default gap of 0.7 moves them 0.35 a frame
    # (70% of their radius) at 3 frames, a motion the alignment loses: there a fifth of the
    # surfels ended more than 0.14 off the truth and the two pieces hung on which of them the
    # clipping kept (experiments/surfels_line_search.py)
    # 4 final steps, at least the merges' 3: the final pass then stands in for the last
    # merge's optimisation (last_merge_optimised false). 2 steps from the unoptimised merge
    # left the spheres one piece (2,356 of its 7,324 vertices on the other sphere), which is
    # why a shorter final pass keeps the last merge's optimisation
    truth = synth.scene("touching-spheres", frames=3, gap=0.3)
    scans = synth.scan(truth, resolution=128)
    anim = reconstruct(scans, method="surfels", **{**QUICK, "final_iterations": 4})
    for t in range(len(scans)):
        _, truth_labels = vertex_components(truth.faces, len(truth.vertices[t]))
        _, labels = vertex_components(anim.faces, len(anim.vertices[t]))
        sizes = np.bincount(labels)
        big = np.argsort(sizes)[::-1][:2]
        # two large pieces hold nearly everything (at this coarse scan a crumb of the meshing
        # remains: measured 3,315 + 1,755 vertices and a crumb of 37; the bench's standard
        # scan has exactly two components in every frame)
        assert sizes[big].min() > 0.2 * len(labels) and sizes[big].sum() > 0.9 * len(labels), (
            t,
            sizes,
        )
        # each lies on one sphere: none bridges the contact (a flap of one piece lies on the
        # other sphere: 6-11 of its 3,315 vertices measured)
        nearest = truth_labels[cKDTree(truth.vertices[t]).query(anim.vertices[t])[1]]
        sides = [np.bincount(nearest[labels == piece], minlength=2) for piece in big]
        assert all(side.max() >= 0.98 * side.sum() for side in sides)
        assert np.argmax(sides[0]) != np.argmax(sides[1])


def test_the_fit_to_the_frames_brings_the_surface_onto_the_truth(tmp_path):
    truth = synth.scene("rigid-turn", frames=2, angle=6.0)
    scans = synth.scan(truth, resolution=64)
    cache = str(tmp_path)  # the second run resumes the merges
    # the holes left open: which of them are small enough to close is measured on the moved
    # vertices (with 99bf033's alignment one more closed without the fit: 2,400 faces against
    # 2,394; 2,387 either way now)
    options = dict(QUICK, cache_dir=cache, close_holes=0.0)
    plain = reconstruct(scans, method="surfels", fit_frames=False, **options)
    fitted = reconstruct(scans, method="surfels", **options)
    # the fit moves the vertices only
    np.testing.assert_array_equal(fitted.faces, plain.faces)
    spacing = point_spacing(scans.frames[0].points)
    for t in range(2):
        off = [
            closest_points_on_mesh(truth.vertices[t], truth.faces, anim.vertices[t]).distances
            for anim in (plain, fitted)
        ]
        # measured: 0.62 -> 0.14 point spacings off the truth on average (the noise's level)
        assert np.mean(off[1]) < 0.4 * np.mean(off[0]) and np.mean(off[1]) < 0.3 * spacing


@pytest.mark.slow
def test_a_cap_no_frame_sees_is_closed_in_every_frame_unobserved():
    """A bumpy ball moving rigidly over 3 frames whose cap above z = 0.7 no frame sees: with
    the default ``close_holes`` the result is one closed manifold of genus 0, the cap's
    vertices never observed and near the moving truth in every frame (the C1 membrane over a
    convex cap); with ``close_holes=0`` the hole stays open."""
    from scipy.spatial.transform import Rotation

    from fourd.metrics.topology import topology

    rng = np.random.default_rng(0)
    motions = [
        (Rotation.from_rotvec([0.0, 0.0, 0.05 * t]).as_matrix(), np.array([0.03 * t, 0, 0]))
        for t in range(3)
    ]

    def ball(turn, shift):
        directions = rng.normal(size=(6000, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        directions = directions[directions[:, 2] < 0.7]
        points = directions * (1 + 0.1 * np.sin(3 * directions[:, 0]))[:, None]
        return (points + rng.normal(scale=0.004, size=points.shape)) @ turn.T + shift

    def off_the_ball(vertices, turn, shift):
        local = (vertices - shift) @ turn
        radius = np.linalg.norm(local, axis=1)
        return np.abs(radius - (1 + 0.1 * np.sin(3 * local[:, 0] / radius)))

    seq = PointCloudSequence(
        [Frame(ball(*motion), time=float(t)) for t, motion in enumerate(motions)]
    )
    anim = reconstruct(seq, method="surfels", **QUICK)
    found = topology(anim.faces, anim.vertices.shape[1])
    assert found.closed_manifold and found.components == 1 and found.euler == 2
    cap = anim.vertices[0][:, 2] > 0.85  # the rim is bumpy, up to z = 0.77
    assert cap.sum() > 300 and not anim.observed[:, cap].any()
    for t, motion in enumerate(motions):
        gap = off_the_ball(anim.vertices[t][cap], *motion)
        # measured: 0.039 median, 0.097 at most, in each frame; a flat membrane would sit up
        # to 0.3 under the top
        assert np.median(gap) < 0.06 and gap.max() < 0.15
    kept = reconstruct(seq, method="surfels", close_holes=0.0, **QUICK)
    assert topology(kept.faces, kept.vertices.shape[1]).boundary_loops > 0


@pytest.mark.slow
def test_the_videos_anchors_and_colours_stop_a_sheet_sliding_along_itself():
    """The first three frames of the waving sheet in printed cloth with the rig's video: the
    travelling wave slides the surfels along the featureless sheet; the anchors hold them, and
    so does the colours' guide on its own."""
    truth = synth.scene("waving-sheet", frames=20)
    scans = synth.scan(truth, resolution=64, appearance="cloth", video=True)
    truth = AnimatedMesh(truth.faces, truth.vertices[:3], truth.times[:3])
    scans = PointCloudSequence(scans.frames[:3], scans.names[:3], scans.video.select(slice(0, 3)))
    runs = {
        "plain": dict(video_anchors=False, color_guide=False),
        "anchors": dict(color_guide=False),
        "colours": dict(video_anchors=False),
        "both": {},
    }
    scores = {
        name: evaluate(reconstruct(scans, method="surfels", **settings), truth, samples=20000)
        for name, settings in runs.items()
    }
    without = scores["plain"]
    # measured: Chamfer / correspondence mean / last 0.0033 / 0.0185 / 0.0362 without; with
    # the anchors 0.0030 / 0.0041 / 0.0076, the colours 0.0035 / 0.0030 / 0.0044, both 0.0031 /
    # 0.0023 / 0.0034
    for name in ("anchors", "colours", "both"):
        assert scores[name]["correspondence_last"] < 0.4 * without["correspondence_last"], name
        assert scores[name]["correspondence_mean"] < 0.4 * without["correspondence_mean"], name
        assert scores[name]["chamfer"] < 1.1 * without["chamfer"], name
