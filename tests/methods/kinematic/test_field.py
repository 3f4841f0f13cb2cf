"""The space-time field of the kinematic method: real time units, windowed fits."""

import numpy as np
from kinematic_shapes import _hypersphere

from fourd.geometry.field import Field4D
from fourd.methods.kinematic.field import SpaceTimeField
from fourd.methods.kinematic.mpu4d import MPUOptions, fit_mpu4d


def test_space_time_field_is_a_field4d_in_real_time_units():
    points, normals = _hypersphere(3000, 1.0, 5)
    mpu = fit_mpu4d(points, normals, options=MPUOptions(error=1e-3))
    field = SpaceTimeField.single(mpu, time_origin=10.0, time_scale=0.5)
    assert isinstance(field, Field4D)
    x = np.array([[0.0, 0.0, 0.5]])
    t = 10.0 + 0.5 / 0.5  # w = 0.5
    value = field.value(x, t)
    assert abs(value[0] - mpu(np.array([[0, 0, 0.5, 0.5]]))[0]) < 1e-12
    g = field.gradient(x, np.array([t]))
    h = 1e-6
    fd = (field.value(x, t + h) - field.value(x, t - h)) / (2 * h)
    assert abs(fd[0] - g[0, 3]) < 1e-5


def test_windowed_fits_cover_the_sequence_with_bounded_memory():
    from fourd.methods.kinematic.field import fit_windows, space_time_points

    rng = np.random.default_rng(8)
    pts, nrm = [], []
    for t in range(6):
        d = rng.normal(size=(800, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts.append(d + [0.02 * t, 0, 0])
        nrm.append(d)
    times = np.arange(6.0)
    stp = space_time_points(pts, nrm, times, delta=0.08, time_origin=0.0, time_unit=1.0)
    field = fit_windows(
        stp,
        times,
        mpu_options=MPUOptions(error=0.01),
        window=2,
        overlap=1,
        time_origin=0.0,
        time_scale=0.08,
    )
    assert len(field.windows) == 3
    for t in times:
        x = pts[int(t)][:50]
        assert np.abs(field.value(x, t)).max() < 0.02
        assert len(field._cache) <= 2
    assert field.fits >= 3
