"""Every frame's surface (fourd.geometry.frame_surface.frame_surfaces): made here or by the
caller's workers, the same surfaces in frame order, each cached."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from fourd import synth
from fourd.geometry.frame_surface import SurfaceSettings, frame_surfaces


def test_frames_made_by_the_callers_workers_are_those_made_here_in_order_and_cached(tmp_path):
    scans = synth.scan(synth.scene("squash-ball", frames=4), resolution=48)
    here, found = frame_surfaces(scans.frames, SurfaceSettings())
    assert found == 0
    with ThreadPoolExecutor(2) as pool:
        there, found = frame_surfaces(scans.frames, SurfaceSettings(), cache_dir=str(tmp_path), submit=pool.submit)
    assert found == 0
    assert len(there) == len(here) == 4
    for (v0, f0), (v1, f1) in zip(here, there, strict=True):
        assert len(f0) > 50
        assert np.array_equal(f0, f1)
        assert np.allclose(v0, v1, atol=1e-12)
    again, found = frame_surfaces(scans.frames, SurfaceSettings(), cache_dir=str(tmp_path))
    assert found == 4
    assert all(np.array_equal(f0, f1) for (_, f0), (_, f1) in zip(here, again, strict=True))
