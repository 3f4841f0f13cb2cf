"""Shapes and image checks shared by the rasteriser and rendering tests."""

import math

import numpy as np
import trimesh

from fourd.animation import AnimatedMesh
from fourd.viz.raster import BACKGROUND

WHITE = np.array(BACKGROUND)


def ink(image):
    """Mask of pixels that are not background."""
    return np.any(image != WHITE, axis=-1)


def rotating_sphere(frames=3, degrees=40.0, subdivisions=3):
    s = trimesh.creation.icosphere(subdivisions)
    out = []
    for t in range(frames):
        a = math.radians(degrees * t)
        rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
        out.append(s.vertices @ rot.T)
    return AnimatedMesh(s.faces, np.stack(out))
