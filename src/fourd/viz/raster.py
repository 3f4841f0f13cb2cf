"""A small z-buffer software rasteriser: pictures without a display.

The rasteriser (numba, no GPU, no X server) writes, per pixel, the nearest triangle and its
perspective-correct barycentric coordinates; shading is then a vectorised pass that
interpolates vertex normals, colours and texture coordinates per pixel (so checks stay crisp
on coarse meshes) and applies Lambert + ambient light from a light fixed to the camera.
Points are splatted as small discs into the same depth buffer.

Examples
--------
>>> import trimesh
>>> s = trimesh.creation.icosphere(2)
>>> render_mesh(s.vertices, s.faces, width=64, height=48).shape
(48, 64, 3)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.viz import texture as tex
from fourd.viz.camera import Camera, fit_camera

BACKGROUND = (255, 255, 255)


# --------------------------------------------------------------------------- kernels


@njit(cache=True)
def _rasterize(xy, depth, faces, face_id, bary, inv_depth):  # pragma: no cover - numba
    """Z-buffer the triangles: per pixel, nearest face and perspective-correct barycentrics."""
    height, width = face_id.shape
    near = 1e-9
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        z0, z1, z2 = depth[i0], depth[i1], depth[i2]
        if z0 <= near or z1 <= near or z2 <= near:
            continue
        x0, y0 = xy[i0, 0], xy[i0, 1]
        x1, y1 = xy[i1, 0], xy[i1, 1]
        x2, y2 = xy[i2, 0], xy[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        xmin = max(int(math.floor(min(x0, min(x1, x2)))), 0)
        xmax = min(int(math.ceil(max(x0, max(x1, x2)))), width - 1)
        ymin = max(int(math.floor(min(y0, min(y1, y2)))), 0)
        ymax = min(int(math.ceil(max(y0, max(y1, y2)))), height - 1)
        if xmin > xmax or ymin > ymax:
            continue
        inv = 1.0 / area
        for y in range(ymin, ymax + 1):
            sy = y + 0.5
            for x in range(xmin, xmax + 1):
                sx = x + 0.5
                w0 = ((x1 - sx) * (y2 - sy) - (x2 - sx) * (y1 - sy)) * inv
                w1 = ((x2 - sx) * (y0 - sy) - (x0 - sx) * (y2 - sy)) * inv
                w2 = 1.0 - w0 - w1
                if w0 < -1e-7 or w1 < -1e-7 or w2 < -1e-7:
                    continue
                q0, q1, q2 = w0 / z0, w1 / z1, w2 / z2
                iz = q0 + q1 + q2
                if iz > inv_depth[y, x]:
                    inv_depth[y, x] = iz
                    face_id[y, x] = f
                    bary[y, x, 0] = q0 / iz
                    bary[y, x, 1] = q1 / iz
                    bary[y, x, 2] = q2 / iz


@njit(cache=True)
def _splat(xy, depth, radius, bias, point_id, inv_depth):  # pragma: no cover - numba
    """Z-buffer discs of ``radius`` pixels; ``bias`` > 0 lets points on a surface win."""
    height, width = point_id.shape
    r2 = radius * radius
    for p in range(xy.shape[0]):
        z = depth[p]
        if z <= 1e-9:
            continue
        iz = (1.0 / z) * (1.0 + bias)
        cx, cy = xy[p, 0], xy[p, 1]
        xmin = max(int(math.floor(cx - radius)), 0)
        xmax = min(int(math.ceil(cx + radius)), width - 1)
        ymin = max(int(math.floor(cy - radius)), 0)
        ymax = min(int(math.ceil(cy + radius)), height - 1)
        for y in range(ymin, ymax + 1):
            dy = y + 0.5 - cy
            for x in range(xmin, xmax + 1):
                dx = x + 0.5 - cx
                if dx * dx + dy * dy <= r2 and iz > inv_depth[y, x]:
                    inv_depth[y, x] = iz
                    point_id[y, x] = p


# --------------------------------------------------------------------------- shading


def _light_direction(camera: Camera, light) -> np.ndarray:
    """World direction towards the light; ``light`` is given in camera space
    (x right, y up, z towards the viewer) and defaults to upper left, behind the viewer."""
    light = np.array([-0.45, 0.65, 0.6] if light is None else light, dtype=np.float64)
    if light.shape != (3,) or not np.linalg.norm(light) > 0:
        raise InputError(f"light must be a nonzero 3-vector in camera space, got {light!r}")
    right, up, forward = camera.basis()
    world = light[0] * right + light[1] * up - light[2] * forward
    return world / np.linalg.norm(world)


def _shade_pattern(base, pattern, texture):
    """Colour per pixel from the (optional) base colour and the texture pattern in [0, 1]."""
    p = pattern[:, None]
    if base is None:
        if texture == "checker":
            return tex.CHECK_DARK * (1 - p) + tex.CHECK_LIGHT * p
        if texture == "grid":
            return tex.CLAY * p + np.array([0.18, 0.2, 0.28]) * (1 - p)
        return np.broadcast_to(tex.CLAY, (len(pattern), 3))
    if texture == "none":
        return base
    return base * (0.55 + 0.45 * p)


def _check_mesh(vertices, faces):
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise InputError(f"vertices must have shape [N, 3], got {list(vertices.shape)}")
    if not np.isfinite(vertices).all():
        raise InputError("vertices contain NaN or infinite values")
    faces = np.asarray(faces)
    faces = np.zeros((0, 3), np.int64) if faces.size == 0 else np.ascontiguousarray(faces, np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(f"faces must have shape [F, 3], got {list(faces.shape)}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise InputError("faces index vertices that do not exist")
    return vertices, faces


def _per_vertex(values, count, name, width=3):
    if values is None:
        return None
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (count, width):
        raise InputError(f"{name} must have shape [{count}, {width}], got {list(values.shape)}")
    return values


def _colors01(colors):
    """Accept colours in [0, 1] floats or 0..255 integers."""
    colors = np.asarray(colors)
    if np.issubdtype(colors.dtype, np.integer):
        return colors.astype(np.float64) / 255.0
    return colors.astype(np.float64)


def render(
    *,
    camera: Camera,
    width: int = 512,
    height: int = 512,
    vertices: np.ndarray | None = None,
    faces: np.ndarray | None = None,
    vertex_colors: np.ndarray | None = None,
    texture_coords: np.ndarray | None = None,
    texture: str = "checker",
    filled: np.ndarray | None = None,
    points: np.ndarray | None = None,
    point_colors: np.ndarray | None = None,
    point_radius: float | None = None,
    light=None,
    ambient: float = 0.35,
    background=BACKGROUND,
) -> np.ndarray:
    """Render a mesh and/or points into one picture; the common core of the public renderers.

    ``filled [N]`` (bool or weights in [0, 1]) tints vertices blue (filled-in regions), after
    the texture. Returns ``uint8 [height, width, 3]``. See :func:`render_mesh` for the rest.
    """
    if width < 1 or height < 1:
        raise InputError(f"width and height must be positive, got {width}x{height}")
    if texture not in tex.TEXTURES:
        raise InputError(f"unknown texture {texture!r}; choose one of {', '.join(tex.TEXTURES)}")
    if not 0.0 <= ambient <= 1.0:
        raise InputError(f"ambient must be in [0, 1], got {ambient}")
    image = np.empty((height, width, 3))
    image[:] = np.asarray(background, dtype=np.float64) / 255.0
    inv_depth = np.zeros((height, width))
    face_id = np.full((height, width), -1, dtype=np.int64)
    bary = np.zeros((height, width, 3))
    lit = _light_direction(camera, light)

    if vertices is not None:
        vertices, faces = _check_mesh(vertices, np.zeros((0, 3)) if faces is None else faces)
        count = len(vertices)
        base = _per_vertex(
            None if vertex_colors is None else _colors01(vertex_colors), count, "vertex_colors"
        )
        coords = _per_vertex(texture_coords, count, "texture_coords")
        if filled is not None:
            filled = np.asarray(filled, dtype=np.float64)
            if filled.shape != (count,):
                raise InputError(f"filled must have shape [{count}], got {list(filled.shape)}")
        if len(faces):
            xy, depth = camera.project(vertices, width, height)
            _rasterize(xy, depth, faces, face_id, bary, inv_depth)
        hit = face_id >= 0
        if hit.any():
            fid = face_id[hit]
            b = bary[hit]
            corner = faces[fid]  # [M, 3]

            def interp(attr):
                return (
                    b[:, 0, None] * attr[corner[:, 0]]
                    + b[:, 1, None] * attr[corner[:, 1]]
                    + b[:, 2, None] * attr[corner[:, 2]]
                )

            normal = interp(vertex_normals(vertices, faces))
            normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
            position = interp(vertices)
            view = camera.eye - position
            back = np.einsum("ij,ij->i", normal, view) < 0
            normal[back] *= -1.0  # two-sided lighting; back faces are darkened below
            lambert = np.clip(normal @ lit, 0.0, 1.0)
            shade = ambient + (1.0 - ambient) * lambert
            shade[back] *= 0.7
            pattern = (
                tex.texture_pattern(interp(coords), texture)
                if coords is not None and texture != "none"
                else np.ones(len(fid))
            )
            effective = texture if coords is not None else "none"
            color = _shade_pattern(None if base is None else interp(base), pattern, effective)
            if filled is not None:
                weight = 0.65 * np.clip(interp(filled[:, None]), 0.0, 1.0)
                color = (1.0 - weight) * color + weight * tex.FILLED_TINT
            image[hit] = np.clip(color * shade[:, None], 0.0, 1.0)

    if points is not None:
        points = np.ascontiguousarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"points must have shape [P, 3], got {list(points.shape)}")
        if len(points):
            radius = (
                max(1.0, min(width, height) / 320.0)
                if point_radius is None
                else float(point_radius)
            )
            point_id = np.full((height, width), -1, dtype=np.int64)
            xy, depth = camera.project(points, width, height)
            _splat(xy, depth, radius, 0.01, point_id, inv_depth)
            hit = point_id >= 0
            if hit.any():
                if point_colors is None:
                    # depth cue: nearer points darker
                    d = depth[point_id[hit]]
                    lo, hi = float(depth[depth > 0].min()), float(depth.max())
                    t = (d - lo) / (hi - lo) if hi > lo else np.zeros_like(d)
                    color = (
                        np.array([0.1, 0.25, 0.55]) * (1 - t[:, None])
                        + np.array([0.55, 0.7, 0.9]) * t[:, None]
                    )
                else:
                    pc = _colors01(point_colors)
                    if pc.shape == (3,):
                        color = np.broadcast_to(pc, (int(hit.sum()), 3))
                    else:
                        color = _per_vertex(pc, len(points), "point_colors")[point_id[hit]]
                image[hit] = color
    return np.round(image * 255.0).astype(np.uint8)


def render_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    camera: Camera | None = None,
    width: int = 512,
    height: int = 512,
    vertex_colors: np.ndarray | None = None,
    texture_coords: np.ndarray | None = None,
    texture: str = "checker",
    points: np.ndarray | None = None,
    light=None,
    ambient: float = 0.35,
    background=BACKGROUND,
) -> np.ndarray:
    """Render one triangle mesh, shaded, to an RGB image.

    Parameters
    ----------
    vertices : ndarray [N, 3]
    faces : ndarray int [F, 3]
        May be empty: the vertices are then drawn as points.
    camera : Camera, optional
        Default: :func:`fit_camera` on the mesh's bounds (3/4 view, Y up). Pass one camera for
        every frame of a sequence so the pictures line up.
    width, height : int
        Picture size in pixels.
    vertex_colors : ndarray [N, 3], optional
        Base colours (floats in [0, 1] or integers 0..255), interpolated per pixel.
    texture_coords : ndarray [N, 3], optional
        Solid-texture coordinates (one check per unit), interpolated per pixel so the
        pattern stays crisp on coarse meshes; see :mod:`fourd.viz.texture`.
    texture : {"checker", "grid", "none"}
    points : ndarray [P, 3], optional
        Extra points splatted with the mesh (depth tested).
    light : 3 floats, optional
        Direction towards the light in camera space (x right, y up, z towards the viewer).
    ambient : float
        Ambient share of the Lambert + ambient shading, in [0, 1].
    background : 3 ints

    Returns
    -------
    ndarray uint8 [height, width, 3]
    """
    vertices, faces = _check_mesh(vertices, faces)
    if width < 1 or height < 1:
        raise InputError(f"width and height must be positive, got {width}x{height}")
    if camera is None:
        camera = fit_camera(
            np.stack([vertices.min(axis=0), vertices.max(axis=0)]), aspect=width / height
        )
    if len(faces) == 0:
        return render(
            camera=camera,
            width=width,
            height=height,
            points=vertices,
            point_colors=vertex_colors,
            background=background,
        )
    return render(
        camera=camera,
        width=width,
        height=height,
        vertices=vertices,
        faces=faces,
        vertex_colors=vertex_colors,
        texture_coords=texture_coords,
        texture=texture,
        points=points,
        light=light,
        ambient=ambient,
        background=background,
    )


def render_points(
    points: np.ndarray,
    *,
    camera: Camera | None = None,
    width: int = 512,
    height: int = 512,
    colors: np.ndarray | None = None,
    radius: float | None = None,
    background=BACKGROUND,
) -> np.ndarray:
    """Splat points ``[P, 3]`` as depth-tested discs of ``radius`` pixels (default scales with
    the picture); without ``colors`` nearer points are darker. Returns uint8 ``[H, W, 3]``."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise InputError(f"points must have shape [P, 3] with P > 0, got {list(points.shape)}")
    if width < 1 or height < 1:
        raise InputError(f"width and height must be positive, got {width}x{height}")
    if camera is None:
        camera = fit_camera(
            np.stack([points.min(axis=0), points.max(axis=0)]), aspect=width / height
        )
    return render(
        camera=camera,
        width=width,
        height=height,
        points=points,
        point_colors=colors,
        point_radius=radius,
        background=background,
    )
