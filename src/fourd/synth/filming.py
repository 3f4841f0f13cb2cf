"""The multi-view video of a synthetic capture: the scanner's rig as calibrated colour cameras.

Each camera of the scanner's rig (:func:`fourd.synth.scanner.camera_rig`) is also a colour
camera: :func:`rig_cameras` gives its OpenCV model (:mod:`fourd.appearance.cameras`), and
:func:`film_frame` its picture of one truth frame, ray-cast through every pixel centre with the
scanner's own caster (so images and scans agree on what each camera sees). A pixel that hits the
truth shows its colour (:mod:`fourd.synth.paint`: albedo on the rest surface x Lambertian
shading); the scanner's occluder, when on, is a ball with its own printed pattern (it moves with
the ball); the background is a flat dark grey. Every pixel gets Gaussian noise of
``color_noise`` and is quantised to 8 bits.

With ``video_resolution`` equal to the scan's ``resolution`` (the default) pixel ``(i, j)`` of
camera ``k`` is the depth camera's ray ``i * n + j``: an RGB-D rig.
"""

from __future__ import annotations

import numpy as np
import trimesh

from fourd.appearance.cameras import Camera
from fourd.errors import InputError
from fourd.synth.albedo import albedo
from fourd.synth.shading import shaded_colors

#: Background grey level (linear, 0-1).
BACKGROUND = 0.12


def rig_cameras(rig, resolution: int) -> tuple[Camera, ...]:
    """The rig's cameras as calibrated pinhole cameras with square images of ``resolution``
    pixels: camera ``k`` is named ``cam_<k>``, looks along ``rig.forward[k]``, image x along
    ``rig.right[k]``, image y along ``-rig.up[k]``; its pixel centres are the scanner's rays
    through the imaged square (:func:`fourd.synth.scanner.camera_rays`)."""
    cameras = []
    for k in range(len(rig.positions)):
        distance = float(np.linalg.norm(rig.centre - rig.positions[k]))
        focal = distance * resolution / float(rig.width)
        centre = (resolution - 1) / 2.0
        K = np.array([[focal, 0.0, centre], [0.0, focal, centre], [0.0, 0.0, 1.0]])
        R = np.stack([rig.right[k], -rig.up[k], rig.forward[k]])
        cameras.append(Camera(f"cam_{k}", K, R, -R @ rig.positions[k], resolution, resolution))
    return tuple(cameras)


def film_frame(truth, index: int, options, *, rig=None) -> np.ndarray:
    """Every camera's image of truth frame ``index``: uint8 ``[K, n, n, 3]``.

    Parameters
    ----------
    truth : AnimatedMesh or MeshSequence
        A surface truth (an AnimatedMesh without faces cannot be filmed).
    index : int
    options : ScanOptions
        Needs ``appearance``; uses ``video_resolution`` (default ``resolution``),
        ``color_noise``, ``occluder``, the rig settings and ``seed`` (pixel noise draws from
        ``default_rng([seed, index, 2])``).
    rig : CameraRig, optional
        Default: the scanner's rig of the truth.
    """
    from fourd.geometry.normals import vertex_normals
    from fourd.synth.paint import hit_colors, truth_paint
    from fourd.synth.scanner import (
        _first_hits,
        _occluder_centre,
        _truth_frames,
        camera_rays,
        camera_rig,
        studio_lamps,
    )

    if options.appearance is None:
        raise InputError("filming needs an appearance (skin or cloth)")
    frame_count, bounds, point_truth = _truth_frames(truth)
    if point_truth:
        raise InputError("a point truth (no faces) cannot be filmed: video needs a surface")
    if not 0 <= index < frame_count:
        raise InputError(f"frame index {index} is outside the truth's {frame_count} frames")
    if rig is None:
        rig = camera_rig(
            bounds, options.cameras, distance=options.distance, elevation=options.elevation,
            first_angle=options.first_angle, field=options.field,
        )  # fmt: skip
    n = options.video_resolution or options.resolution
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    vertices, faces = truth.frame(index)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    normals = vertex_normals(vertices, faces)
    paint = truth_paint(truth, options.appearance, options.seed, lamps=studio_lamps(options.lighting))
    all_vertices, all_faces = vertices, faces
    if options.occluder:
        ball = trimesh.creation.icosphere(subdivisions=3, radius=0.12 * diagonal)
        ball_centre = _occluder_centre(rig, diagonal, index / max(frame_count - 1, 1))
        all_faces = np.concatenate([faces, np.asarray(ball.faces) + len(vertices)])
        all_vertices = np.concatenate([vertices, np.asarray(ball.vertices) + ball_centre])
    rng = np.random.default_rng([options.seed, index, 2])
    images = np.empty((len(rig.positions), n, n, 3), dtype=np.uint8)
    for k in range(len(rig.positions)):
        _, directions = camera_rays(rig, k, n)
        focal = float(np.linalg.norm(rig.centre - rig.positions[k]))
        depth, hit = _first_hits(
            all_vertices, all_faces, rig.positions[k], rig.right[k], rig.up[k], rig.forward[k],
            focal, float(rig.width), n, directions,
        )  # fmt: skip
        color = np.full((n * n, 3), BACKGROUND)
        on = np.flatnonzero((hit >= 0) & (hit < len(faces)))
        points = rig.positions[k] + depth[on, None] * directions[on]
        color[on] = hit_colors(paint, vertices, faces, normals, hit[on], points, directions[on])
        if options.occluder:
            on_ball = np.flatnonzero(hit >= len(faces))
            where = rig.positions[k] + depth[on_ball, None] * directions[on_ball]
            radial = (where - ball_centre) / (0.12 * diagonal)
            box = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
            base = albedo(radial, "cloth", bounds=box, seed=options.seed + 101)
            color[on_ball] = shaded_colors(base, radial, lamps=paint.lamps)
        color = color + rng.normal(scale=options.color_noise, size=color.shape)
        images[k] = np.round(np.clip(color, 0.0, 1.0) * 255.0).reshape(n, n, 3)
    return images
