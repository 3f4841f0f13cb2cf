"""Scans, systems and checks shared by the ``flow`` tests."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import trimesh

from fourd import PointCloudSequence
from fourd.methods.flow import (
    Options,
    reconstruct,
)
from fourd.methods.flow.grid import (
    build_grid,
)
from fourd.methods.flow.post import (
    implicit_function,
)

# cameras below the object: the top is never seen (a persistent hole), consistently with carving
SENSORS = np.array([[2.5, -1.2, 0.0], [-1.25, -1.2, 2.17], [-1.25, -1.2, -2.17]])


def _ellipsoid_scan(radii, *, count=2500, seed=0, hole=True):
    """Points on an ellipsoid as seen from SENSORS (front-facing samples; with ``hole`` the
    sensors sit below the object so its top is never seen, else a fourth sensor sees it)."""
    rng = np.random.default_rng(seed)
    unit = rng.normal(size=(count * 3, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    points = unit * radii
    normals = unit / radii
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    visible = np.zeros(len(points), bool)
    for s in SENSORS if hole else np.vstack([SENSORS, [[0.0, 3.0, 0.0]]]):
        visible |= np.einsum("ij,ij->i", normals, s - points) > 0.1
    points = points[visible][:count]
    return points + rng.normal(scale=0.002, size=points.shape)


def _squash_sequence(frames=4, *, radius=0.5, hole=True):
    points, volumes = [], []
    for t in range(frames):
        a = np.exp(0.3 * np.sin(2 * np.pi * t / frames))
        radii = radius * np.array([1 / np.sqrt(a), a, 1 / np.sqrt(a)])
        points.append(_ellipsoid_scan(radii, seed=t, hole=hole))
        volumes.append(4 / 3 * np.pi * np.prod(radii))
    sensors = SENSORS if hole else np.vstack([SENSORS, [[0.0, 3.0, 0.0]]])
    return PointCloudSequence.from_arrays(points, sensors=sensors), np.array(volumes)


def _check_closed_manifold(vertices, faces):
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert len(faces) > 0
    assert mesh.is_watertight
    assert np.all(counts == 2), "every edge must be shared by exactly two faces"
    assert mesh.is_winding_consistent
    assert mesh.volume > 0, "faces must wind outwards"
    return mesh


FAST = dict(resolution=16, max_iterations=6, refine=2)


def _saddle_matrix(A, B, softness=0.0):
    """``[[A, B^T], [B, -softness I]]`` assembled by scipy, the reference for the solver."""
    m = B.shape[0]
    lower = -softness * sp.identity(m) if softness else sp.csr_matrix((m, m))
    return sp.bmat([[A, B.T], [B, lower]], format="csr")


def _fast_ball_field(time_weight):
    """The postprocessing's field for a ball 1.5 cells in radius that jumps 8 cells per frame
    (the flow solution is the ball's cells), and the ball's centres, data and radius."""
    grid = build_grid(
        np.array([[-1.0, -0.3, -0.3], [1.0, 0.3, 0.3]]), np.arange(5.0), resolution=40, substeps=1
    )
    radius = 1.5 * grid.h
    centres = [np.array([-0.8 + 0.4 * s, 0.0, 0.0]) for s in range(5)]
    index = np.stack(np.meshgrid(*[np.arange(n) for n in grid.shape], indexing="ij"), axis=-1)
    cell_centres = grid.origin + grid.h * (index + 0.5)
    rng = np.random.default_rng(0)
    x = np.zeros(grid.shape4)
    points, normals = [], []
    for s, centre in enumerate(centres):
        x[s] = np.linalg.norm(cell_centres - centre, axis=-1) < radius
        direction = rng.normal(size=(400, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        points.append(centre + radius * direction)
        normals.append(direction)
    field = implicit_function(grid, x, points, normals, smoothness=0.1, time_weight=time_weight)
    return field, grid, points


def _turning_ball_frames(*, scan_resolution: int, resolution: int):
    """rigid-turn (3 frames) scanned at ``scan_resolution`` by three cameras looking down on
    it, reconstructed at flow ``resolution``: per frame (after checking it closed and
    manifold) the volume against the truth's and the distances of the vertices to the truth,
    in truth diagonals."""
    from fourd.synth import scan, scene

    truth = scene("rigid-turn", frames=3)
    scans = scan(truth, cameras=3, resolution=scan_resolution, noise=0.002, outliers=0.02)
    result = reconstruct(scans, Options(resolution=resolution))
    for i, (v, f) in enumerate(result.meshes):
        mesh = _check_closed_manifold(v, f)
        true_mesh = trimesh.Trimesh(truth.vertices[i], truth.faces, process=False)
        _, distance, _ = trimesh.proximity.closest_point(true_mesh, v)
        diagonal = np.linalg.norm(np.ptp(truth.vertices[i], axis=0))
        yield mesh.volume / true_mesh.volume, distance / diagonal
