"""Analytic shapes and sequences shared by the ``kinematic`` tests."""

import numpy as np
from scipy.spatial.transform import Rotation

from fourd.methods import kinematic as K
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


def _blob_sequence(frames=4, count=2500, noise=0.003, seed=0):
    blob = MovingBlob(speed=(0.04, 0.0, 0.0), spin=(0.0, 0.04, 0.0))
    rng = np.random.default_rng(seed)
    out = []
    for t in range(frames):
        p = blob.surface(count, t, seed + t) + noise * rng.normal(size=(count, 3))
        out.append(Frame(points=p, time=float(t)))
    return blob, PointCloudSequence(out)


class StretchedBlob(MovingBlob):
    """The blob stretched by ``stretch`` along X and still (a shape that is not an isometry of
    the template extracted from the unstretched blob)."""

    def __init__(self, stretch=1.25):
        super().__init__(speed=(0.0, 0.0, 0.0), spin=(0.0, 0.0, 0.0))
        self.inverse = np.diag([1.0 / stretch, 1.0, 1.0])

    def value(self, points, times):
        return self.shape(np.asarray(points, float) @ self.inverse)
def _hypersphere(count, radius, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 4))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return radius * d, d


def _moving_sphere(rng, *, frames, count, shift, time_step, bump=0.0):
    """4D points [frames * count, 4] and normals of a unit sphere (radius modulated by
    ``bump * sin(3 x)``) moving ``shift`` along x per frame, frame ``t`` at time
    ``t * time_step``; directions drawn from ``rng``."""
    points, normals = [], []
    for t in range(frames):
        d = rng.normal(size=(count, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        shape = d * (1 + bump * np.sin(3 * d[:, :1]))
        points.append(np.c_[shape + [shift * t, 0.0, 0.0], np.full(count, time_step * t)])
        normals.append(np.c_[d, np.zeros(count)])
    return np.concatenate(points), np.concatenate(normals)
