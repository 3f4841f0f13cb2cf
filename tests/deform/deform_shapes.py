"""Meshes shared by the deform tests."""

import numpy as np


def tube(length=4.0, rings=41, around=12, radius=0.5):
    """A closed tube along x from 0 to ``length``: ``rings`` rings of ``around`` vertices and a
    centre vertex at each end. Returns ``(vertices, faces, start_cap, end_cap)`` with the cap
    faces' indices."""
    x = np.linspace(0.0, length, rings)
    angle = 2 * np.pi * np.arange(around) / around
    ring = np.stack([np.zeros(around), radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    vertices = np.concatenate([ring + [xi, 0, 0] for xi in x] + [[[0.0, 0, 0]], [[length, 0, 0]]])
    faces = []
    for r in range(rings - 1):
        for a in range(around):
            p, q = r * around + a, r * around + (a + 1) % around
            faces += [[p, p + around, q], [q, p + around, q + around]]
    side = len(faces)
    first, last = rings * around, rings * around + 1
    start = [[first, (a + 1) % around, a] for a in range(around)]
    end = [[last, (rings - 1) * around + a, (rings - 1) * around + (a + 1) % around] for a in range(around)]
    faces = np.array(faces + start + end)
    return vertices, faces, np.arange(side, side + around), np.arange(side + around, side + 2 * around)
