"""The renderer's camera."""

import numpy as np

from fourd.viz.camera import fit_camera


def test_fit_camera_keeps_the_whole_box_in_view_and_fills_it():
    bounds = np.array([[-2.0, 0.0, -0.5], [3.0, 1.0, 0.5]])
    corners = np.array(
        [[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]]
    )
    for azimuth in (0.0, 35.0, 90.0, 200.0):
        camera = fit_camera(bounds, azimuth=azimuth)
        xy, depth = camera.project(corners, 300, 300)
        assert np.all(depth > 0)
        assert np.all((xy >= 0) & (xy <= 300))
        extent = (xy.max(axis=0) - xy.min(axis=0)).max()
        assert extent > 0.6 * 300
