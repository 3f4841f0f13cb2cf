"""Anchor guidance of the sliding (video_anchors): the guide follows the anchors, the solve's
pull draws vertices towards it, and exact anchors cut the drift of a turning sphere."""

import numpy as np
import pytest
import trimesh

from fourd.appearance.guide import anchor_guide
from fourd.methods.kinematic.arap_solve import ConstrainedSolver, slide_precompute


def test_the_guide_is_the_local_mean_motion_and_its_weight_grows_with_support():
    rng = np.random.default_rng(0)
    source = rng.uniform(-1, 1, size=(2000, 3))
    target = source + [0.0, 0.05, 0.0]
    reference = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 5.0]])
    guide = anchor_guide(reference, source, target, np.ones(len(source)), radius=0.2)
    assert guide.vertices.tolist() == [0]  # nothing near the far vertex
    assert np.allclose(guide.positions[0], [0.0, 0.05, 0.0])
    sparse = anchor_guide(reference, source[:20], target[:20], np.full(20, 0.1), radius=0.2)
    assert len(sparse.vertices) == 0 or sparse.weight.max() < guide.weight.max()


def test_the_pull_draws_the_pulled_vertices_towards_the_reference():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    pre = slide_precompute(sphere.vertices, sphere.faces)
    n = len(sphere.vertices)
    normals = np.zeros((n, 3))  # no constraints: free vertices
    constrained = np.zeros(n, dtype=bool)
    reference = sphere.vertices + [0.3, 0.0, 0.0]
    rhs = pre.laplacian @ sphere.vertices  # the rest shape's own Laplacian coordinates
    plain = ConstrainedSolver(pre, normals, np.zeros(n), constrained, 1e-4).solve(rhs, reference)
    pull = np.zeros(n)
    pull[:10] = 1.0
    pulled = ConstrainedSolver(pre, normals, np.zeros(n), constrained, 1e-4, pull).solve(rhs, reference)
    before = np.linalg.norm(plain[:10] - reference[:10], axis=1).mean()
    after = np.linalg.norm(pulled[:10] - reference[:10], axis=1).mean()
    assert after < 0.5 * before


@pytest.mark.slow
def test_exact_anchors_cut_the_drift_of_the_tracking(monkeypatch):
    """With the truth's own correspondences as anchors, kinematic's correspondence error on a
    coloured, filmed scene drops well below the geometry-only figure."""
    import fourd.appearance.anchor_tracks
    from fourd import synth
    from fourd.appearance.anchor_tracks import AnchorPair, Anchors
    from fourd.methods import kinematic
    from fourd.metrics import evaluate

    truth = synth.scene("bending-arm", frames=6)
    scans = synth.scan(truth, resolution=96, seed=0, appearance="cloth", video=True, video_resolution=64)
    pick = np.random.default_rng(0).choice(truth.vertex_count, 3000, replace=False)

    def exact(seq, **_):
        pairs = [
            AnchorPair(k, k + 1, truth.vertices[k][pick], truth.vertices[k + 1][pick],
                       np.full(len(pick), 0.9), np.full(len(pick), 3), pick, {}, 0.0)
            for k in range(len(seq) - 1)
        ]
        return Anchors(tuple(pairs))

    # the methods track through cleaned_anchors, which calls the module's own anchors
    monkeypatch.setattr(fourd.appearance.anchor_tracks, "anchors", exact)
    alone = kinematic.Options(color_guide=False, video_anchors=False)
    plain = evaluate(kinematic.reconstruct(scans, alone), truth, samples=5000)
    anchored = kinematic.Options(color_guide=False, video_anchors=True)
    guided = evaluate(kinematic.reconstruct(scans, anchored), truth, samples=5000)
    assert guided["correspondence_mean"] < 0.7 * plain["correspondence_mean"]
