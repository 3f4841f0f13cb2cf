"""Preprocessing (sec. 3.2 "Initial estimation of recoverable 3D topology"): each frame's
points in locally smooth regions (tensor voting, which also drops isolated outliers), their
oriented normals, and a seed model of one frame: surfels sampled ``eps_sampl`` apart on those
points, connected within ``eps_top``, optimised by the 3D part of the energy (data and
smoothness).

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from fourd.geometry.normals import estimate_normals
from fourd.geometry.outliers import remove_outliers
from fourd.geometry.tensor_voting import tensor_voting
from fourd.methods.surfels.anchors import Forward
from fourd.methods.surfels.energy import Weights
from fourd.methods.surfels.match import MatchOptions, frame_data
from fourd.methods.surfels.model import Model, observed_surfels
from fourd.methods.surfels.optimizer import GaussNewtonOptions, gauss_newton
from fourd.methods.surfels.state import surfel_state
from fourd.methods.surfels.topology import build_topology, sample_surfels


class FramePoints(NamedTuple):
    """One frame's data after preprocessing.

    points : float64 [P, 3]
        Points in locally smooth regions (tensor voting kept them).
    normals : float64 [P, 3]
        Oriented unit normals (the input's, else PCA oriented by the sensors or by
        propagation).
    forward : Forward or None
        The video's anchors from this frame into the next (:mod:`.anchors`); None: none.
    colors : float64 [P, 3] or None
        The points' colours in [0, 1] for the colours' guide (:mod:`.color_guide`); None: none.
    """

    points: np.ndarray
    normals: np.ndarray
    forward: Forward | None = None
    colors: np.ndarray | None = None


def prepare_frame(
    points: np.ndarray,
    normals: np.ndarray | None,
    sensors: np.ndarray | None,
    *,
    spacing: float,
    max_ratio: float = 0.8,
    k: int = 16,
) -> FramePoints:
    """Outlier removal, tensor voting (keep points with eigenvalue ratio at most
    ``max_ratio``, the paper's 0.8) and oriented normals of one frame [P, 3]; a pure function
    of the frame (sec. 3.2)."""
    points = np.asarray(points, dtype=np.float64)
    inliers = remove_outliers(points, spacing=spacing).inliers
    if np.count_nonzero(inliers) < 3:  # nothing left to vote on; the pipeline names the frame
        kept = points[inliers]
        return FramePoints(kept, np.zeros_like(kept))
    votes = tensor_voting(points[inliers], spacing=spacing, max_ratio=max_ratio)
    keep = np.flatnonzero(inliers)[votes.keep]
    if len(keep) < 3:
        keep = np.flatnonzero(inliers)
    kept = points[keep]
    if normals is not None:
        oriented = np.asarray(normals, dtype=np.float64)[keep]
    else:
        oriented = estimate_normals(kept, k=k, sensors=sensors).normals
    return FramePoints(kept, oriented)


def seed_model(
    frame: FramePoints,
    index: int,
    *,
    sampling: float,
    weights: Weights,
    gauss_newton_options: GaussNewtonOptions,
    match: MatchOptions | None = None,
    geodesic: bool = True,
) -> Model:
    """The seed model of frame ``index``: surfels ``sampling`` (``eps_sampl``) apart on its
    points, edges within ``2 eps_sampl`` (the smoothness's along the surface with
    ``geodesic``, :func:`.topology.build_topology`), positions and normals optimised by the
    data and smoothness terms only (the 3D part of eq. 3), data associated by ``match``."""
    chosen = sample_surfels(frame.points, sampling)
    state = surfel_state(frame.points[chosen], frame.normals[chosen])
    topology = build_topology(
        state.positions,
        2.0 * sampling,
        max_stretch=None,
        normals=state.normals if geodesic else None,
    )
    data = frame_data([frame.points], weight=1.0, normals=[frame.normals])
    spatial = replace(weights, rigid=0.0, rigid_normal=0.0, accel=0.0, accel_normal=0.0)
    result = gauss_newton(state, topology, data, spatial, match, gauss_newton_options)
    return Model(
        result.state, topology, index, observed_surfels(result.state, data, topology.radius)
    )
