"""Colour guides: where a template's colours say each vertex went, for coloured points.

Without video, the colours of the points play the role of the video's anchors (issue 52, part
4: "a photometric term on the points (coloured ICP, Park, Zhou and Koltun, ICCV 2017)"). Each
vertex of the template takes its colour from the first frame's points once; at every later
input frame, after the step's rigid prediction, a per-vertex Lucas-Kanade on that frame's
coloured points (:func:`fourd.appearance.photometric.photometric_shift`) moves each vertex
along the surface to where its patch's colours match; ``kinematic``'s sliding step and
``garment``'s template fit pull towards it as they do towards the video's anchors
(:mod:`fourd.appearance.guide`). The reference is the first frame, not the previous one, so
what the colours correct does not accumulate.
"""

from __future__ import annotations

import logging
import time as _time
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from fourd.appearance.guide import Guide
from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import ColorField, field_for_reads
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals

__all__ = ["PhotometricGuides", "colors_of_cleaned", "frame_colors_from_video", "guide_colors"]

log = logging.getLogger("fourd.appearance.color_guide")


def colors_of_cleaned(raw_points, raw_colors, cleaned) -> np.ndarray | None:
    """Colours ``[P, 3]`` of the ``cleaned`` points [P, 3] of a frame: those of the nearest of its
    ``raw_points`` (a cleaned point is one of them); None when the frame has no colours."""
    if raw_colors is None or len(cleaned) == 0:
        return None
    _, nearest = cKDTree(np.asarray(raw_points, dtype=np.float64)).query(cleaned, workers=-1)
    return np.asarray(raw_colors, dtype=np.float64)[nearest]


class PhotometricGuides(Sequence):
    """Per sliding time, a function ``start [N, 3] -> Guide`` (None where the time has no
    coloured input frame): ``kinematic``'s colour guide
    (:func:`fourd.methods.kinematic.sliding.slide`), ``garment``'s too.

    Parameters
    ----------
    template : float64 [N, 3]
        The urshape at the first time (on frame ``frames[0]``'s points).
    faces : int [F, 3]
    frames : sequence of int
        Per sliding time, the input frame whose points are the data term (-1: none).
    reference_frame : int
        The input frame the template lies on, whose colours it takes.
    reference : float64 [N, 3], optional
        The template's (log) colours when known already (a run that goes on after an
        earlier part of the sequence, :attr:`reference` of that part's guides); then
        ``reference_frame`` is not read.
    points, normals, colors : lists of per-frame arrays [P_k, 3] (colors may be None)
    radius : float
        Patch radius of the Lucas-Kanade (input units).
    scale : float
        A shift whose uncertainty is ``scale`` gets weight ``exp(-1)``; the weight is
        ``exp(-(uncertainty / scale)^2)``.
    """

    def __init__(self, template, faces, frames, points, normals, colors, *, radius: float, scale: float,
                 reference_frame: int = 0, reference=None):
        self.frames = [int(k) for k in frames]
        self.vertex_count = len(template)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.points, self.normals, self.colors = points, normals, colors
        self.radius, self.scale = float(radius), float(scale)
        if reference is None and self._has(reference_frame):
            reference = self._field(reference_frame).sample(template)
        self.reference = reference

    def _has(self, k: int) -> bool:
        return k >= 0 and self.colors[k] is not None and len(self.points[k]) >= 8

    def _field(self, k: int) -> ColorField:
        # the field is read at the template's vertices
        return field_for_reads(self.points[k], self.normals[k], self.colors[k], self.vertex_count)

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, i):
        k = self.frames[i]
        if i == 0 or self.reference is None or not self._has(k):
            return None

        def guide(start: np.ndarray) -> Guide:
            normals = vertex_normals(start, self.faces)
            result = photometric_shift(start, normals, self.reference, self._field(k), radius=self.radius)
            finite = np.flatnonzero(np.isfinite(result.uncertainty))
            weight = np.exp(-((result.uncertainty[finite] / self.scale) ** 2))
            log.debug("colour guide at frame %d: support %.3f", k, weight.sum() / len(start))
            return Guide(finite, start[finite] + result.shift[finite], weight)

        return guide


def guide_colors(seq, points, normals) -> list | None:
    """Per frame, the colours ``[P, 3]`` of its cleaned ``points`` for the colour guide (None
    where a frame has none): the points' own when every frame has them, else the video's
    (:func:`fourd.appearance.point_colors.colors_from_video`) for every frame, so that all
    frames' colours come from one source and compare; without video, the points' own where
    given. None when there are no colours at all."""
    if all(f.colors is not None for f in seq.frames) or getattr(seq, "video", None) is None:
        if not any(f.colors is not None for f in seq.frames):
            return None
        return [colors_of_cleaned(f.points, f.colors, p) for f, p in zip(seq.frames, points, strict=True)]
    started = _time.perf_counter()
    colors = [
        frame_colors_from_video(seq, t, p, n)
        for t, (p, n) in enumerate(zip(points, normals, strict=True))
    ]
    log.info("point colours from the video: %.2f s", _time.perf_counter() - started)
    return colors


def frame_colors_from_video(seq, index: int, points, normals) -> np.ndarray:
    """The colours ``[P, 3]`` of frame ``index``'s cleaned ``points`` (with their ``normals``)
    from ``seq.video``, for the colour guide; InputError saying how to go without."""
    from fourd.appearance.point_colors import colors_from_video

    try:
        return colors_from_video(seq, index, points=points, normals=normals)
    except InputError as error:
        raise InputError(
            f"colour guide from the video: {error.problem} (color_guide=false goes without)", error.path
        ) from None
