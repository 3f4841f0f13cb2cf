"""The command line end to end, as a user runs it: synth -> reconstruct -> evaluate -> view."""

import json

import numpy as np
import pytest
import trimesh

from fourd.cli import main
from fourd.io.ply import write_ply
from fourd.synth.data import shared_data_dir


@pytest.mark.slow
def test_dfaust_frames_written_as_ply_reconstruct_with_perframe(tmp_path):
    if shared_data_dir() is None or not (shared_data_dir() / "dfaust-hopping.npz").exists():
        pytest.skip("../shared/data/dfaust-hopping.npz is not available")
    from fourd.synth.data import load_shared

    truth = load_shared("dfaust-hopping")
    rng = np.random.default_rng(0)
    folder = tmp_path / "dfaust"
    folder.mkdir()
    for t in range(2):
        keep = rng.choice(truth.vertex_count, 30000, replace=False)
        write_ply(folder / f"frame_{t}.ply", truth.vertices[t, keep].astype(np.float32))
    out = tmp_path / "meshes"
    assert main(["reconstruct", str(folder), "-o", str(out), "--method", "perframe", "--quiet"]) == 0
    meshes = sorted(out.glob("frame_*.obj"))
    assert len(meshes) == 2
    mesh = trimesh.load(meshes[1], process=False)
    # Every output vertex lies near the scanned body (noise-free input: within a few spacings).
    distances, _ = __import__("scipy.spatial", fromlist=["cKDTree"]).cKDTree(truth.vertices[1]).query(mesh.vertices)
    diagonal = np.linalg.norm(np.ptp(truth.vertices[1], axis=0))
    assert np.percentile(distances, 95) < 0.01 * diagonal


@pytest.mark.slow
def test_synth_reconstruct_evaluate_view(tmp_path, capsys):
    scans = tmp_path / "scans"
    assert main(["synth", "squash-ball", str(scans), "--frames", "3", "--resolution", "96", "--quiet"]) == 0
    assert (scans / "truth.npz").exists() and (scans / "sensors.json").exists()
    result = tmp_path / "ball.npz"
    assert main(["reconstruct", str(scans), "-o", str(result), "--method", "perframe", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(result), str(scans / "truth.npz"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["chamfer"] < 0.01
    assert main(["evaluate", str(result), str(scans / "truth.npz")]) == 0
    assert "chamfer" in capsys.readouterr().out.lower()
    view = tmp_path / "view"
    assert main(["view", str(result), "--truth", str(scans / "truth.npz"), "--input", str(scans), "-o", str(view)]) == 0
    assert (view / "index.html").stat().st_size > 100_000
