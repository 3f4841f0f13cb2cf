"""Method ``kinematic`` (000_00387fefe94cc850.txt): urshape, sliding, the whole pipeline."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.methods import kinematic as K
from fourd.methods import reconstruct
from fourd.methods.kinematic import urshape
from fourd.methods.kinematic.framesurface import FrameSurface
from fourd.methods.kinematic.register import RegisterOptions
from fourd.methods.kinematic.sliding import slide_step
from fourd.sequence import Frame, PointCloudSequence


class MovingBlob:
    """Analytic Field4D: a bumpy blob moving rigidly, ``x(t) = R(t) x0 + c(t)``."""

    def __init__(self, speed=(0.05, 0.0, 0.0), spin=(0.0, 0.08, 0.03)):
        self.speed = np.asarray(speed, float)
        self.spin = np.asarray(spin, float)

    def motion(self, t):
        return Rotation.from_rotvec(self.spin * t).as_matrix(), self.speed * t

    def shape(self, y):
        r = np.linalg.norm(y, axis=1)
        d = y / np.maximum(r, 1e-12)[:, None]
        return r - (1.0 + 0.15 * np.sin(3 * d[:, 0]) * np.cos(2 * d[:, 1]) + 0.1 * d[:, 2] ** 2)

    def _local(self, points, times):
        times = np.broadcast_to(np.asarray(times, float), (len(points),))
        out = np.empty_like(points)
        for t in np.unique(times):
            R, c = self.motion(t)
            sel = times == t
            out[sel] = (points[sel] - c) @ R
        return out

    def value(self, points, times):
        return self.shape(self._local(np.asarray(points, float), times))

    def gradient(self, points, times):
        points = np.asarray(points, float)
        times = np.broadcast_to(np.asarray(times, float), (len(points),))
        h = 1e-6
        g = np.empty((len(points), 4))
        for a in range(3):
            e = np.zeros(3)
            e[a] = h
            g[:, a] = (self.value(points + e, times) - self.value(points - e, times)) / (2 * h)
        g[:, 3] = (self.value(points, times + h) - self.value(points, times - h)) / (2 * h)
        return g

    def surface(self, count, t, seed):
        rng = np.random.default_rng(seed)
        d = rng.normal(size=(count, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        x = d.copy()
        for _ in range(30):  # radial Newton onto the rest shape
            x -= (self.shape(x) / 1.0)[:, None] * d
        R, c = self.motion(t)
        return x @ R.T + c


def _sphere_template(blob, resolution=0.12):
    lo, hi = np.full(3, -1.4), np.full(3, 1.4)
    return K.extract_template(blob, 0.0, bounds=np.array([lo, hi]), cell_size=resolution)


def test_extract_template_lies_on_the_surface_and_is_closed():
    blob = MovingBlob()
    V, F = _sphere_template(blob)
    assert len(F) > 500
    assert np.abs(blob.value(V, 0.0)).max() < 1e-3
    edges = np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed 2-manifold edges
    # outward orientation: positive enclosed volume
    volume = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
    assert volume > 3.0


def test_extract_template_corrects_its_cell_size_towards_the_target_vertex_count():
    blob = MovingBlob()
    bounds = np.array([np.full(3, -1.4), np.full(3, 1.4)])
    first = len(K.extract_template(blob, 0.0, bounds=bounds, cell_size=0.12)[0])
    for target in (int(first * 0.6), int(first * 1.15), int(first * 1.05)):
        count = len(K.extract_template(
            blob, 0.0, bounds=bounds, cell_size=0.12, target_vertices=target
        )[0])
        if abs(first / target - 1.0) <= urshape.VERTEX_TOLERANCE:
            assert count == first  # close enough: no second marching cubes
        else:
            assert abs(count / target - 1.0) < 0.05


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


def _blob_sequence(frames=4, count=2500, noise=0.003, seed=0):
    blob = MovingBlob(speed=(0.04, 0.0, 0.0), spin=(0.0, 0.04, 0.0))
    rng = np.random.default_rng(seed)
    out = []
    for t in range(frames):
        p = blob.surface(count, t, seed + t) + noise * rng.normal(size=(count, 3))
        out.append(Frame(points=p, time=float(t)))
    return blob, PointCloudSequence(out)


def test_frames_prepared_on_threads_are_those_prepared_one_by_one():
    blob, seq = _blob_sequence(frames=5)
    # outliers, so that the cleaning has something to drop
    rng = np.random.default_rng(1)
    frames = [
        Frame(points=np.vstack([f.points, rng.uniform(-3, 3, size=(40, 3))]), time=f.time)
        for f in seq.frames
    ]
    seq = PointCloudSequence(frames)
    options = K.Options()
    points, normals = K.prepare_frames(seq, options)
    assert len(points) == len(normals) == len(seq)
    for frame, p, n in zip(seq.frames, points, normals, strict=True):
        alone_p, alone_n = K._prepare_frame(frame, options)
        assert len(p) < len(frame.points)
        np.testing.assert_array_equal(p, alone_p)
        np.testing.assert_array_equal(n, alone_n)
        # outward normals of the blob
        assert np.mean(np.einsum("ij,ij->i", n, blob.gradient(p, frame.time)[:, :3]) > 0) > 0.99


@pytest.mark.slow
def test_reconstruct_tracks_a_rigid_scan_at_the_noise_level():
    blob, seq = _blob_sequence()
    anim = reconstruct(seq, "kinematic", template_vertices=7000)
    assert isinstance(anim, AnimatedMesh) and anim.rest is not None
    assert anim.vertices.shape[0] == len(seq)
    for t in range(len(seq)):
        R, c = blob.motion(t)
        R0, c0 = blob.motion(0)
        expected = (anim.rest - c0) @ R0 @ R.T + c
        assert np.linalg.norm(anim.vertices[t] - expected, axis=1).mean() < 0.02
        assert np.abs(blob.value(anim.vertices[t], t)).mean() < 0.01
    assert anim.observed.mean() > 0.9


def test_a_still_shape_of_revolution_is_not_spun_by_the_noise():
    """A spheroid held still, scanned with noise: its spin about its axis does not change
    the fit, so only a rigid prediction that ignores such directions keeps the template
    still (measured: 0.003 with it, 0.031 and growing without it at the last frame)."""
    rng = np.random.default_rng(0)
    frames = []
    for t in range(8):
        d = rng.normal(size=(2500, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        points = d * np.array([1.0, 1.3, 1.0]) + 0.003 * rng.normal(size=(2500, 3))
        frames.append(Frame(points=points, time=float(t)))
    anim = reconstruct(PointCloudSequence(frames), "kinematic", template_vertices=2000)
    drift = np.linalg.norm(anim.vertices - anim.vertices[0], axis=2).mean(axis=1)
    assert drift.max() < 0.01, np.round(drift, 4)


@pytest.mark.slow
def test_output_at_fractional_times_lies_between_the_neighbouring_frames():
    blob, seq = _blob_sequence(frames=3)
    anim = reconstruct(seq, "kinematic", template_vertices=2000, times=(0.0, 0.5, 1.0, 1.5, 2.0))
    assert np.allclose(anim.times, [0, 0.5, 1, 1.5, 2])
    x = anim.vertices[..., 0].mean(axis=1)  # the blob moves along +x
    assert x[0] < x[1] < x[2] < x[3] < x[4]
    assert abs(x[1] - 0.5 * (x[0] + x[2])) < 0.25 * (x[2] - x[0])


@pytest.mark.slow
def test_an_open_sheet_stays_open():
    rng = np.random.default_rng(7)
    frames = []
    for t in range(3):
        uv = rng.uniform(-1, 1, size=(3000, 2))
        z = 0.1 * np.sin(2 * uv[:, 0] + 0.3 * t)
        frames.append(
            Frame(points=np.c_[uv, z], time=float(t), sensors=np.array([[0.0, 0.0, 5.0]]))
        )
    anim = reconstruct(PointCloudSequence(frames), "kinematic", template_vertices=1500)
    F = anim.faces
    edges = np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.sum(counts == 1) > 20  # a boundary exists: the sheet was not closed up
    extent = anim.vertices[-1].max(axis=0) - anim.vertices[-1].min(axis=0)
    assert extent[2] < 0.5 and extent[0] > 1.5 and extent[1] > 1.5


def test_options_are_validated():
    with pytest.raises(ValueError):
        K.Options(iterations=0)
    with pytest.raises(ValueError):
        K.Options(time_scale=0.0)
    with pytest.raises(InputError):
        reconstruct(PointCloudSequence([Frame(points=np.zeros((5, 3)))]), "kinematic")
    assert K.MIN_FRAMES == 2


def test_a_global_rigid_motion_fitted_to_a_sample_moves_every_vertex():
    from fourd.methods.kinematic.sliding import rigid_prediction

    rng = np.random.default_rng(3)
    positions = rng.normal(size=(3000, 3))
    axes = np.array([1.0, 0.6, 0.3])  # an ellipsoid: no motion slides it along itself
    positions = positions / np.linalg.norm(positions, axis=1, keepdims=True) * axes
    # point-to-plane residuals of a small rigid motion, measured against its planes
    rotation = Rotation.from_rotvec([0.02, -0.01, 0.015]).as_matrix()
    translation = np.array([0.01, 0.03, -0.02])
    moved = positions @ rotation.T + translation
    normals = (positions / axes**2) @ rotation.T
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    residuals = np.einsum("ij,ij->i", normals, positions - moved)
    sample = np.linspace(0, len(positions) - 1, 400).astype(np.int64)
    predicted = rigid_prediction(
        positions, normals[sample], residuals[sample], sample=sample, regularization=0.0
    )
    full = rigid_prediction(positions, normals, residuals, regularization=0.0)
    # one linearised step: second order in the motion, the same from the sample as from all
    assert np.abs(predicted - moved).max() < 1e-3  # the motion: up to 0.046
    assert np.abs(predicted - full).max() < 2e-4
    with pytest.raises(ValueError):
        rigid_prediction(positions, normals, residuals, sample=sample, neighbours=8)


def test_reduced_solver_gives_the_solution_of_the_saddle_system_5():
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from fourd.methods.kinematic.sliding import ConstrainedSolver

    blob = MovingBlob()
    V, F = _sphere_template(blob, resolution=0.3)
    pre = K.slide_precompute(V, F)
    n = len(V)
    rng = np.random.default_rng(9)
    normals = V / np.linalg.norm(V, axis=1, keepdims=True) + 0.1 * rng.normal(size=(n, 3))
    offsets = rng.normal(scale=0.1, size=n)
    constrained = rng.uniform(size=n) > 0.2
    rhs = rng.normal(size=(n, 3))
    reference = V + 0.01 * rng.normal(size=(n, 3))
    solver = ConstrainedSolver(pre, normals, offsets, constrained, 1e-4)
    P = solver.solve(rhs, reference)
    # the 4n x 4n system (5): [L3 + mu, C^T; C, 0] [p; lambda] = [b + mu p_ref; c], lambda_i = 0 rows
    L3 = solver.L3
    rows = np.repeat(np.arange(n), 3)
    C = sp.csr_matrix((normals.ravel(), (rows, np.arange(3 * n))), shape=(n, 3 * n))
    C = sp.diags(constrained.astype(float)) @ C
    Z = sp.diags((~constrained).astype(float))
    saddle = sp.bmat([[L3, C.T], [C, Z]], format="csc")
    right = np.r_[rhs.ravel() + solver.mu * reference.ravel(), np.where(constrained, offsets, 0.0)]
    solution = spla.spsolve(saddle, right)
    assert np.abs(solution[: 3 * n].reshape(n, 3) - P).max() < 1e-8
    assert np.abs(np.einsum("ij,ij->i", normals, P) - offsets)[constrained].max() < 1e-9


def test_elimination_order_is_a_permutation_that_reduces_fill():
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from fourd.methods.kinematic.sliding import elimination_order

    blob = MovingBlob()
    V, F = _sphere_template(blob, resolution=0.3)
    pre = K.slide_precompute(V, F)
    n = len(V)
    order = elimination_order(pre.laplacian)
    assert np.array_equal(np.sort(order), np.arange(n))
    # a scrambled vertex order, as marching cubes may leave it: the order must undo it
    scrambled = np.random.default_rng(3).permutation(n)
    L = (pre.laplacian + 1e-3 * sp.identity(n)).tocsr()[scrambled][:, scrambled]

    def fill(matrix):
        lu = spla.splu(
            matrix.tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
        return lu.L.nnz

    mine = elimination_order(L)
    assert fill(L[mine][:, mine]) < 0.5 * fill(L)
    assert np.array_equal(elimination_order(sp.identity(4, format="csr")), np.arange(4))


@pytest.mark.slow
def test_output_before_and_beyond_the_input_times():
    blob, seq = _blob_sequence(frames=3)
    anim = reconstruct(seq, "kinematic", template_vertices=2000, times=(-0.5, 0.0, 1.0, 2.5))
    x = anim.vertices[..., 0].mean(axis=1)
    speed = blob.speed[0]
    assert abs((x[1] - x[0]) - 0.5 * speed) < 0.3 * speed
    assert abs((x[3] - x[2]) - 1.5 * speed) < 0.3 * speed


def test_frame_surface_is_the_signed_distance_near_its_points():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    surface = K.FrameSurface(d, d, bandwidth=0.05)  # unit sphere, outward normals
    q = rng.normal(size=(500, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    for offset in (-0.02, 0.0, 0.03):
        value, gradient, coverage = surface.evaluate(q * (1.0 + offset))
        assert np.abs(value - offset).max() < 0.004
        assert np.einsum("ij,ij->i", gradient, q).min() > 0.98
        assert coverage.min() == 1.0
    value, gradient, coverage = surface.evaluate(q * 2.0)  # far from every point
    assert np.all(coverage == 0) and np.all(value == 0) and np.all(gradient == 0)


def test_the_frame_surface_weights_exp_matches_numpy():
    from fourd.methods.kinematic.framesurface import _exp_into

    x = np.r_[0.0, -1e-300, -np.log(2) / 2, -6.25, -np.random.default_rng(0).uniform(0, 6.25, 5000)]
    out, bits = np.full(len(x) + 1, -1.0), np.empty(len(x) + 1, np.int64)
    _exp_into(x, len(x), out, bits)
    np.testing.assert_allclose(out[:-1], np.exp(x), rtol=4e-16, atol=0)
    assert out[-1] == -1.0  # only the first count values are written


def test_frame_surface_ignores_the_far_side_of_a_thin_part():
    rng = np.random.default_rng(4)
    uv = rng.uniform(-1, 1, size=(20000, 2))
    gap = 0.04  # a slab thinner than the kernel (bandwidth 0.03, cut at 0.075)
    top = np.c_[uv[:10000], np.full(10000, gap / 2)]
    bottom = np.c_[uv[10000:], np.full(10000, -gap / 2)]
    normals = np.r_[np.tile([0, 0, 1.0], (10000, 1)), np.tile([0, 0, -1.0], (10000, 1))]
    surface = K.FrameSurface(np.r_[top, bottom], normals, bandwidth=0.03)
    q = np.c_[rng.uniform(-0.5, 0.5, size=(200, 2)), np.full(200, gap / 2 + 0.005)]
    value, gradient, _ = surface.evaluate(q)
    assert np.abs(value - 0.005).max() < 0.002
    assert gradient[:, 2].min() > 0.99


def test_smooth_trajectories_keeps_linear_motion_and_the_end_frames():
    times = np.array([0.0, 1.0, 1.5, 3.0, 4.0])
    rng = np.random.default_rng(5)
    start, velocity = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    linear = start[None] + times[:, None, None] * velocity[None]
    assert np.allclose(K.smooth_trajectories(linear, times, 2), linear)
    noisy = linear + 0.1 * rng.normal(size=linear.shape)
    smoothed = K.smooth_trajectories(noisy, times, 1)
    assert np.array_equal(smoothed[[0, -1]], noisy[[0, -1]])
    inner = slice(1, -1)
    assert (
        np.abs(smoothed[inner] - linear[inner]).mean() < np.abs(noisy[inner] - linear[inner]).mean()
    )
    assert np.array_equal(K.smooth_trajectories(noisy, times, 0), noisy)


def test_smooth_trajectories_with_a_motion_threshold_leaves_an_acceleration_alone():
    # a noisy grid, its last quarter accelerating steadily (a kick): the plain filter cuts
    # the accelerating part's trajectory by a quarter of its second difference, the
    # motion-aware one keeps it there and still takes out the still part's noise
    u, v = np.meshgrid(np.linspace(0.0, 1.0, 24), np.linspace(0.0, 1.0, 24))
    grid = np.c_[u.ravel(), v.ravel(), np.zeros(u.size)]
    times = np.arange(7.0)
    truth = np.repeat(grid[None], len(times), axis=0)
    kicking = grid[:, 0] > 0.75
    truth[:, kicking, 2] = 0.5 * (times[:, None] - 3.0) ** 2
    noisy = truth + 0.01 * np.random.default_rng(6).normal(size=truth.shape)
    threshold = K.Options().smoothing_motion
    plain = K.smooth_trajectories(noisy, times, 1)
    aware = K.smooth_trajectories(noisy, times, 1, motion_threshold=threshold)

    def error(x, mask):
        return np.linalg.norm(x[1:-1, mask] - truth[1:-1, mask], axis=2).mean()

    inside, still = grid[:, 0] > 0.85, grid[:, 0] < 0.6
    assert error(plain, inside) > 0.2
    assert error(aware, inside) < 0.03
    assert error(aware, still) < 0.8 * error(noisy, still)
    assert error(aware, still) < 1.1 * error(plain, still)
    assert np.array_equal(aware[[0, -1]], noisy[[0, -1]])
    # a region jumping off in one frame and back in the next (a glitch) is smoothed as
    # by the plain filter
    glitch = noisy.copy()
    glitch[3, grid[:, 0] < 0.3, 2] += 0.5
    plain = K.smooth_trajectories(glitch, times, 1)
    aware = K.smooth_trajectories(glitch, times, 1, motion_threshold=threshold)
    glitched = grid[:, 0] < 0.2
    worst = [np.abs(x[3, glitched, 2] - truth[3, glitched, 2]).mean() for x in (plain, aware)]
    assert worst[1] < 1.1 * worst[0] < 0.3


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


def _kinematic_on_crane(*, frames: int, step: int, start: int = 0, **options) -> dict:
    """``kinematic`` (with ``options``) on a stretch of the crane capture scanned with the
    standard protocol, evaluated with 10,000 samples; skips without ../shared/data."""
    from fourd import synth
    from fourd.bench import PROTOCOL
    from fourd.metrics import evaluate
    from fourd.synth.data import shared_data_dir

    if shared_data_dir() is None or not (shared_data_dir() / "crane.npz").exists():
        pytest.skip("../shared/data/crane.npz is not available")
    truth = synth.scene("crane", frames=frames, seed=0, start=start, step=step)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    anim = reconstruct(scans, method="kinematic", **options)
    return evaluate(anim, truth, samples=10000, seed=0)


@pytest.mark.slow
def test_held_out_crane_motion_is_tracked():
    """Crane frames 90-100 (every second), a stretch no default was tuned on, scanned with the
    standard protocol: a limb moves up to 15 median edges per frame. Correspondence stays
    near 1% of the diagonal (0.0101 / 0.0123 measured; 0.0205 / 0.0281 before the
    registration started from the carried motion and searched 40 edges)."""
    metrics = _kinematic_on_crane(frames=6, start=90, step=2)
    assert metrics["correspondence_mean"] < 0.015
    assert metrics["correspondence_last"] < 0.02
    assert metrics["chamfer"] < 0.006


@pytest.mark.slow
def test_a_limb_that_starts_to_move_is_registered():
    """Crane frames 140-146 (every second, standard scans): at frame 142 the rigid
    prediction leaves 2.6% of the points unexplained, up from under 1%, below the 3% of
    ``RegisterOptions.threshold``; registering there on the rise keeps the correspondence at
    0.0035 / 0.0049 (0.0044 / 0.0061 measured without: ``follow_threshold=0.03``)."""
    metrics = _kinematic_on_crane(frames=4, start=140, step=2)
    assert metrics["correspondence_mean"] < 0.004
    assert metrics["correspondence_last"] < 0.0055


@pytest.mark.slow
@pytest.mark.parametrize("still_normals", [0.2, 0.0])
def test_a_still_crane_does_not_creep(still_normals):
    """The first crane pose scanned 10 times with the standard protocol (independent noise):
    nothing moves, so the correspondence error must not grow over the frames. With
    constraint normals from each frame's noisy surface everywhere (``still_normals=0``) the
    standing foot creeps up the leg: measured 0.0013 at frame 1, 0.0044 at frame 8 and 0.0061
    at the last; by default 0.0013, 0.0017 and 0.0020."""
    metrics = _kinematic_on_crane(frames=10, step=0, still_normals=still_normals)
    drift = metrics["per_frame"]["correspondence"]
    # the last frame lies at the end of the 4D implicit, whose one-sided fit moves it a little
    growth = drift[-2] - drift[1]
    if still_normals == 0:
        assert growth > 0.001  # the defect this guards against is still there
    else:
        assert growth < 0.0005 and drift[-1] < 0.0025, np.round(drift, 4)


class StretchedBlob(MovingBlob):
    """The blob stretched by ``stretch`` along X and still (a shape that is not an isometry of
    the template extracted from the unstretched blob)."""

    def __init__(self, stretch=1.25):
        super().__init__(speed=(0.0, 0.0, 0.0), spin=(0.0, 0.0, 0.0))
        self.inverse = np.diag([1.0 / stretch, 1.0, 1.0])

    def value(self, points, times):
        return self.shape(np.asarray(points, float) @ self.inverse)


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
