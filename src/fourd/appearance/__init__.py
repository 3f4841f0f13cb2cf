"""Colour and video: calibrated cameras, optical flow, anchors lifted to 3D, photometric terms.

Modules: :mod:`~fourd.appearance.cameras` (the pinhole model and ``cameras.json``),
:mod:`~fourd.appearance.flow` (dense optical flow between consecutive images, forward-backward
check), :mod:`~fourd.appearance.depth` (depth maps splatted from a frame's points),
:mod:`~fourd.appearance.anchor_tracks` (sparse 3D anchor tracks from the flow of every camera),
:mod:`~fourd.appearance.colored_icp` (rigid registration by geometry and colour, for coloured
points without video), :mod:`~fourd.appearance.vertex_colors` (input colours carried to a
result's vertices), :mod:`~fourd.appearance.surface_color` (a frame's colours as a field on its
surface), :mod:`~fourd.appearance.photometric` (per-vertex shifts from the colours: the colour
guide of ``kinematic``), :mod:`~fourd.appearance.lighting` (the fixed lamps' shading),
:mod:`~fourd.appearance.point_colors` (colours for uncoloured points from the video).
OpenCV is imported only when flow is computed.
"""

from __future__ import annotations

from fourd.appearance.lighting import fit_lighting
from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import ColorField
from fourd.appearance.vertex_colors import vertex_colors

__all__ = ["ColorField", "anchors", "colored_icp", "fit_lighting", "photometric_shift", "vertex_colors"]


def anchors(seq, **options):
    """3D anchor tracks between consecutive frames from the optical flow of ``seq.video``;
    see :func:`fourd.appearance.anchor_tracks.anchors` (returns an
    :class:`~fourd.appearance.anchor_tracks.Anchors`)."""
    from fourd.appearance.anchor_tracks import anchors as _anchors

    return _anchors(seq, **options)


def colored_icp(source, source_colors, target, target_colors, **options):
    """Rigid registration of coloured points by geometry and colour (Park, Zhou, Koltun 2017);
    see :func:`fourd.appearance.colored_icp.colored_icp`."""
    from fourd.appearance.colored_icp import colored_icp as _colored_icp

    return _colored_icp(source, source_colors, target, target_colors, **options)
