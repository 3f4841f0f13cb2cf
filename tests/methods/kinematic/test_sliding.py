"""Sliding the urshape along the space-time surface (000_00387fefe94cc850.txt section 5)."""

import numpy as np
import pytest
from kinematic_shapes import MovingBlob, StretchedBlob, _sphere_template

from fourd.methods import kinematic as K
from fourd.methods.kinematic.framesurface import FrameSurface
from fourd.methods.kinematic.register import RegisterOptions
from fourd.methods.kinematic.sliding import slide_step


def test_a_rigidly_moving_shape_is_tracked_with_near_zero_arap_energy():
    blob = MovingBlob()
    V, F = _sphere_template(blob)
    times = np.arange(6, dtype=float)
    result = K.slide(V, F, blob, times, options=K.SlideOptions(iterations=4), return_steps=True)
    anim = result.animation
    pre = K.slide_precompute(V, F)
    for t in times:
        R, c = blob.motion(t)
        expected = V @ R.T + c
        error = np.linalg.norm(anim.vertices[int(t)] - expected, axis=1)
        assert error.mean() < 0.01  # the blob's diameter is about 2.2
        assert K.arap_energy(pre, anim.vertices[int(t)]) < 1e-3
        assert np.abs(blob.value(anim.vertices[int(t)], t)).max() < 1e-3
    assert anim.observed.all()
    assert np.allclose(anim.vertices[0], V) and np.allclose(anim.rest, V)


def test_vertices_without_data_are_unconstrained_and_not_observed():
    blob = MovingBlob()
    V, F = _sphere_template(blob)
    data = [blob.surface(3000, t, t) for t in range(3)]
    data = [d[d[:, 1] < 0.3] for d in data]  # the top is never seen
    anim = K.slide(V, F, blob, np.arange(3.0), data=data)
    top = V[:, 1] > 0.6
    assert not anim.observed[1:, top].any()
    bottom = V[:, 1] < 0.0
    assert anim.observed[1:, bottom].mean() > 0.95
    # unconstrained vertices still move along as rigidly as possible
    R, c = blob.motion(2.0)
    assert np.linalg.norm(anim.vertices[2][top] - (V[top] @ R.T + c), axis=1).mean() < 0.05


class BlobAndPlate:
    """Analytic Field4D: a static :class:`MovingBlob` and, 0.6 beyond its +x pole, the
    half-space ``x > 1.6`` (union: the smaller of the two fields)."""

    def __init__(self):
        self.blob = MovingBlob(speed=(0.0, 0.0, 0.0), spin=(0.0, 0.0, 0.0))

    def value(self, points, times):
        return np.minimum(self.blob.value(points, times), 1.6 - np.asarray(points)[:, 0])

    def gradient(self, points, times):
        points = np.asarray(points, float)
        gradient = self.blob.gradient(points, times)
        plate = 1.6 - points[:, 0] < self.blob.value(points, times)
        gradient[plate] = [-1.0, 0.0, 0.0, 0.0]
        return gradient


class AcceptingRegistration:
    """Stands in for the large-motion registration: runs at every step, returns its seed
    unchanged and reports that it explains more of the frame, so the step counts as
    registered (``give_up`` 1: never weighed against the projection)."""

    options = RegisterOptions(threshold=0.0, give_up=1.0)

    def __init__(self):
        self.calls = 0

    def unexplained(self, vertices, points):
        self.calls += 1
        return 1.0 / self.calls

    def register_frame(self, seed, points, normals, previous=None):
        return seed.copy(), self.unexplained(seed, points)


def test_after_a_registration_a_vertex_off_the_surface_is_not_snapped_onto_another_one():
    """A cap of the template left 0.35 outwards lies nearer the plate than its own blob: the
    projection of 5.1 would move it onto the plate, more than 1.5 edges. After a registration
    the projection limit leaves it unconstrained and ARAP brings it back onto the blob;
    without one (a step the prediction explains, or a rejected registration) the paper's
    projection stands."""
    field = BlobAndPlate()
    V, F = _sphere_template(field.blob)
    pre = K.slide_precompute(V, F)
    cap = V[:, 0] > 0.9
    start = V.copy()
    start[cap] += 0.35 * V[cap] / np.linalg.norm(V[cap], axis=1, keepdims=True)
    points = field.blob.surface(4000, 0.0, 0)
    normals = field.blob.gradient(points, 0.0)[:, :3]
    surface = FrameSurface(points, normals / np.linalg.norm(normals, axis=1)[:, None], 0.05)

    def step(limit, registration):
        options = K.SlideOptions(rigid_guess=False, projection_limit=limit)
        out, constrained, _ = slide_step(
            pre, field, start, 0.0, 1.0, options=options, surface=surface,
            registration=registration,
        )
        return out, constrained

    for limit, registration in [(0.0, AcceptingRegistration()), (1.5, None)]:
        snapped, constrained = step(limit, registration)
        assert constrained.all()
        assert np.linalg.norm(snapped[cap] - V[cap], axis=1).mean() > 0.3  # on the plate
    kept, constrained = step(1.5, AcceptingRegistration())
    assert not constrained[cap].any() and constrained[~cap].all()
    assert np.linalg.norm(kept[cap] - V[cap], axis=1).mean() < 0.1
    assert np.abs(field.blob.value(kept[cap], 1.0)).max() < 0.1


def test_slide_rejects_bad_input():
    blob = MovingBlob()
    V, F = _sphere_template(blob, resolution=0.3)
    with pytest.raises(ValueError):
        K.slide(V, F, blob, [0.0, 0.0])
    with pytest.raises(ValueError):
        K.slide(V, F, blob, [0.0, 1.0], data=[V])
    with pytest.raises(ValueError):
        K.SlideOptions(iterations=0)
    with pytest.raises(ValueError):
        K.SlideOptions(projection_limit=-1.0)


def _lagging_field_and_frames(frames=5, lag=0.7):
    """A blob turning about y, its 4D field lagging behind (posed at ``lag * t``), and frame
    surfaces of the true positions: the data term must pull the sliding onto the data."""
    truth = MovingBlob(speed=(0.0, 0.0, 0.0), spin=(0.0, 0.12, 0.0))
    lagging = MovingBlob(speed=(0.0, 0.0, 0.0), spin=(0.0, 0.12 * lag, 0.0))
    surfaces, data = [], []
    for t in range(frames):
        p = truth.surface(6000, t, t)
        g = truth.gradient(p, float(t))[:, :3]
        surfaces.append(K.FrameSurface(p, g / np.linalg.norm(g, axis=1, keepdims=True), 0.06))
        data.append(p)
    return truth, lagging, surfaces, data


def test_the_data_term_removes_the_pose_bias_of_the_implicit():
    truth, lagging, surfaces, data = _lagging_field_and_frames()
    V, F = _sphere_template(truth)
    times = np.arange(len(data), dtype=float)
    with_data = K.slide(V, F, lagging, times, data=data, surfaces=[None] + surfaces[1:])
    without = K.slide(V, F, lagging, times, data=data)
    for t in times[1:]:
        R, c = truth.motion(t)
        expected = V @ R.T + c
        error = np.linalg.norm(with_data.vertices[int(t)] - expected, axis=1).mean()
        lagged = np.linalg.norm(without.vertices[int(t)] - expected, axis=1).mean()
        assert error < 0.01  # the blob's diameter is about 2.2
        assert lagged > 5 * error  # the lagging implicit alone is posed off the data
    with pytest.raises(ValueError):
        K.slide(V, F, lagging, times, surfaces=surfaces[:2])


def test_the_previous_shape_in_the_sliding_keeps_a_stretch_that_the_rest_shape_would_undo():
    """Vertices on a still, stretched surface: the rest shape's ARAP slides them along it
    towards its own proportions; with most of the previous positions' shape in the term they
    stay nearly where they are, on the surface either way."""
    blob = MovingBlob()
    V, F = _sphere_template(blob, resolution=0.15)
    pre = K.slide_precompute(V, F)
    field = StretchedBlob()
    previous = V @ np.diag([1.25, 1.0, 1.0])
    assert np.abs(field.value(previous, 0.0)).max() < 1e-3

    def moved(b):
        options = K.SlideOptions(rigid_guess=False, register=None, previous_shape=b)
        out, _, _ = slide_step(pre, field, previous, 0.0, 1.0, options=options)
        assert np.abs(field.value(out, 1.0)).max() < 0.01
        return np.linalg.norm(out - previous, axis=1).mean()

    rest_only, remembering = moved(0.0), moved(0.8)  # measured 0.38 and 0.08 edges
    assert rest_only > 0.2 * pre.edge_length
    assert remembering < 0.4 * rest_only
    with pytest.raises(ValueError, match="previous_shape"):
        K.SlideOptions(previous_shape=1.0)
    with pytest.raises(ValueError, match="slide_memory"):
        K.Options(slide_memory=-0.1)
