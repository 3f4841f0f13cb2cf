"""The Open3D / NICP peers of BASELINES.md (skipped without open3d, an optional extra)."""

from __future__ import annotations

import pytest

from fourd import AnimatedMesh, MeshSequence, synth
from fourd.metrics import evaluate

pytest.importorskip("open3d", reason="the peers need the optional extra 'baselines' (open3d)")

from fourd.bench.peers import poisson_per_frame, template_nicp  # noqa: E402


@pytest.mark.slow
def test_poisson_per_frame_meshes_a_scanned_ball():
    truth = synth.scene("squash-ball", frames=1)
    scans = synth.scan(truth, resolution=96)
    result = poisson_per_frame(scans)
    assert isinstance(result, MeshSequence) and len(result) == 1
    report = evaluate(result, truth, samples=10000)
    assert report["accuracy"] < 0.01 and report["completeness"] < 0.02


@pytest.mark.slow
def test_template_nicp_follows_the_ball():
    truth = synth.scene("squash-ball", frames=2)
    scans = synth.scan(truth, resolution=96)
    result = template_nicp(scans)
    assert isinstance(result, AnimatedMesh) and result.frame_count == 2
    assert len(result.faces) <= 9000
    report = evaluate(result, truth, samples=10000)
    assert report["correspondence_last"] < 0.03 and report["accuracy"] < 0.02
