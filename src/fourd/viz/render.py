"""Pictures without a display: a small z-buffer software rasteriser and the sheets built on it.

The rasteriser (numba, no GPU, no X server) writes, per pixel, the nearest triangle and its
perspective-correct barycentric coordinates; shading is then a vectorised pass that
interpolates vertex normals, colours and texture coordinates per pixel (so checks stay crisp
on coarse meshes) and applies Lambert + ambient light from a light fixed to the camera.
Points are splatted as small discs into the same depth buffer.

On top of it: :func:`contact_sheet` (frames in a grid, texture carried from the first frame
by the correspondences, optional error and ``observed`` colouring), :func:`turntable`,
:func:`render_animation` (GIF via Pillow; MP4 when ``imageio-ffmpeg`` is installed) and
:func:`bench_sheet` for the benchmark.

Examples
--------
>>> import trimesh
>>> from fourd.viz.render import render_mesh
>>> s = trimesh.creation.icosphere(2)
>>> render_mesh(s.vertices, s.faces, width=64, height=48).shape
(48, 64, 3)
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.io.atomic import atomic_path
from fourd.io.results import as_result
from fourd.viz import texture as tex

log = logging.getLogger("fourd.viz.render")

BACKGROUND = (255, 255, 255)


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera looking from ``eye`` at ``target``; ``fov`` is vertical, degrees."""

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray | tuple = (0.0, 1.0, 0.0)
    fov: float = 30.0

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (3,) or not np.isfinite(value).all():
                raise InputError(f"camera {name} must be 3 finite numbers, got {value!r}")
            object.__setattr__(self, name, value)
        if not 1.0 <= self.fov <= 170.0:
            raise InputError(f"camera fov must be in [1, 170] degrees, got {self.fov}")
        if np.linalg.norm(self.target - self.eye) == 0:
            raise InputError("camera eye and target coincide")

    def basis(self) -> np.ndarray:
        """Rows: right, up, forward (unit vectors, world coordinates)."""
        forward = self.target - self.eye
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        if np.linalg.norm(right) < 1e-9:  # looking along up: pick any perpendicular
            right = np.cross(forward, [1.0, 0.0, 0.0])
        right = right / np.linalg.norm(right)
        return np.stack([right, np.cross(right, forward), forward])

    def project(self, points: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates ``[M, 2]`` (x right, y down, pixel centres at +0.5) and depth ``[M]``
        (distance along the view axis; <= 0 behind the camera)."""
        local = (np.asarray(points, dtype=np.float64) - self.eye) @ self.basis().T
        depth = local[:, 2]
        focal = 0.5 * height / math.tan(math.radians(self.fov) * 0.5)
        safe = np.where(depth > 1e-12, depth, 1e-12)
        xy = np.empty((len(local), 2))
        xy[:, 0] = 0.5 * width + focal * local[:, 0] / safe
        xy[:, 1] = 0.5 * height - focal * local[:, 1] / safe
        return xy, depth

    def orbit(self, degrees: float) -> Camera:
        """The camera turned by ``degrees`` about the vertical axis through the target."""
        a = math.radians(degrees)
        c, s = math.cos(a), math.sin(a)
        rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        return Camera(self.target + rot @ (self.eye - self.target), self.target, self.up, self.fov)


def fit_camera(
    bounds: np.ndarray,
    *,
    azimuth: float = 35.0,
    elevation: float = 20.0,
    fov: float = 30.0,
    aspect: float = 1.0,
    margin: float = 1.05,
) -> Camera:
    """A 3/4 view (Y up) that keeps the box ``bounds [2, 3]`` in the picture from any angle.

    ``azimuth`` turns from +Z towards +X, ``elevation`` lifts above the XZ plane (degrees).
    The camera is the nearest (along the view direction) at which all eight corners of the box
    project inside the picture, shrunk by ``margin``; a fixed camera from the bounds of a
    whole sequence keeps every frame in view.
    """
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or not np.isfinite(bounds).all():
        raise InputError(f"bounds must be finite with shape [2, 3], got {list(bounds.shape)}")
    if not (aspect > 0 and 1.0 <= fov <= 170.0 and margin > 0):
        raise InputError(
            f"need aspect > 0, fov in [1, 170], margin > 0; got {aspect}, {fov}, {margin}"
        )
    center = bounds.mean(axis=0)
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
    radius = radius if radius > 0 else 1.0
    half = math.radians(fov) * 0.5
    half = min(half, math.atan(math.tan(half) * aspect))
    distance = margin * radius / math.sin(half)
    az, el = math.radians(azimuth), math.radians(elevation)
    direction = np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    camera = Camera(center + distance * direction, center, np.array([0.0, 1.0, 0.0]), fov)
    # Tighten: the nearest distance (bisection) at which the projected box corners still fit.
    corners = np.array(
        [[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    tan_v = math.tan(math.radians(fov) * 0.5)
    basis = camera.basis()

    def fits(d):
        local = (corners - (center + d * direction)) @ basis.T
        if local[:, 2].min() <= 1e-6 * distance:
            return False
        extent = max(
            np.abs(local[:, 0] / local[:, 2]).max() / (tan_v * aspect),
            np.abs(local[:, 1] / local[:, 2]).max() / tan_v,
        )
        return extent * margin <= 1.0

    lo_d, hi_d = 0.0, distance
    for _ in range(30):
        mid = 0.5 * (lo_d + hi_d)
        lo_d, hi_d = (lo_d, mid) if fits(mid) else (mid, hi_d)
    camera = Camera(center + hi_d * direction, center, camera.up, fov)
    return camera


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


# --------------------------------------------------------------------------- sequences


def _sequence_bounds(result, truth=None, input=None) -> np.ndarray:
    boxes = [result.bounds()]
    if truth is not None:
        boxes.append(truth.bounds())
    if input is not None:
        boxes.append(np.asarray(input.bounds()))
    boxes = np.asarray(boxes)
    return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])


def pick_frames(count: int, frames=None, *, target: int = 8) -> list[int]:
    """``frames`` checked against ``count``, or about ``target`` evenly spaced indices."""
    if frames is None:
        n = min(count, target)
        return sorted({int(round(x)) for x in np.linspace(0, count - 1, n)})
    picked = [int(f) for f in frames]
    for f in picked:
        if not -count <= f < count:
            raise InputError(f"frame {f} out of range: the result has {count} frames")
    return [f % count for f in picked]


class _Styler:
    """Per-frame vertex colours and texture coordinates of a result (errors computed once)."""

    def __init__(self, result, *, texture, truth, error_colors, observed_tint, cells=10.0):
        if texture not in tex.TEXTURES:
            raise InputError(
                f"unknown texture {texture!r}; choose one of {', '.join(tex.TEXTURES)}"
            )
        self.result, self.texture, self.cells = result, texture, cells
        self.observed_tint = observed_tint and isinstance(result, AnimatedMesh)
        self.errors = self.scale = None
        if error_colors:
            if truth is None:
                raise InputError("error_colors needs a truth to measure against")
            self.errors = tex.vertex_errors(result, truth)
            self.scale = tex.error_scale(self.errors)

    def __call__(self, i):
        """``(vertices, faces, colors or None, texture coords or None, filled or None)``."""
        vertices, faces = self.result.frame(i)
        colors = None if self.errors is None else tex.colormap(self.errors[i], self.scale)
        filled = None
        if self.observed_tint and not self.result.observed[i].all():
            filled = (~self.result.observed[i]).astype(np.float64)
        coords = None
        if self.texture != "none":
            coords = tex.texture_coordinates(self.result, i, cells=self.cells)
        return vertices, faces, colors, coords, filled

    def caption(self) -> str:
        parts = []
        if self.texture != "none":
            if isinstance(self.result, AnimatedMesh):
                parts.append(f"{self.texture} painted on frame 0, carried by the correspondences")
            else:
                parts.append(f"no correspondence: {self.texture} from each frame's own positions")
        if self.errors is not None:
            parts.append("colour: distance to truth")
        if self.observed_tint and not self.result.observed.all():
            parts.append("blue: filled in (not observed)")
        return "; ".join(parts)


def _input_points(input, i, result):
    if input is None:
        return None
    count = len(input.frames)
    if count == result.frame_count:
        return input.frames[i].points
    times = np.asarray(input.times)
    return input.frames[int(np.argmin(np.abs(times - result.times[i])))].points


def _font(size):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        return ImageFont.load_default()


def _render_frames(result, frames, camera, size, styler, input):
    images = []
    radius = None  # splat size of faceless frames: measured once, on the first
    for i in frames:
        vertices, faces, colors, coords, filled = styler(i)
        if len(faces):
            image = render(
                camera=camera,
                width=size,
                height=size,
                vertices=vertices,
                faces=faces,
                vertex_colors=colors,
                texture_coords=coords,
                texture=styler.texture,
                filled=filled,
                points=_input_points(input, i, result),
            )
        else:
            pc = colors
            if pc is None and coords is not None:
                pattern = tex.texture_pattern(coords, styler.texture)
                light = 0.7 * tex.CLAY  # darker than the surface's light check: visible on white
                pc = tex.CHECK_DARK * (1 - pattern[:, None]) + light * pattern[:, None]
            if filled is not None:
                pc = tex.tint_unobserved(
                    np.broadcast_to(tex.CLAY, vertices.shape) if pc is None else pc, filled == 0
                )
            if radius is None:
                radius = _splat_radius(vertices, camera, size)
            image = render(
                camera=camera,
                width=size,
                height=size,
                points=vertices,
                point_colors=pc,
                point_radius=radius,
            )
        images.append(image)
    return images


def _splat_radius(points: np.ndarray, camera: Camera, size: int) -> float:
    """Disc radius in pixels: about half the projected point spacing, within [1, size / 60]."""
    if len(points) < 4:
        return max(1.0, size / 120)
    from fourd.geometry.neighbors import point_spacing

    depth = float(np.median((points - camera.eye) @ camera.basis()[2]))
    focal = 0.5 * size / math.tan(math.radians(camera.fov) * 0.5)
    radius = 0.5 * point_spacing(points) * focal / max(depth, 1e-12)
    return float(np.clip(radius, 1.0, max(1.0, size / 60)))


def _grid_image(tiles, labels, columns, title, caption, colorbar=None):
    """Tiles with labels under a header; returns a PIL image."""
    from PIL import Image, ImageDraw

    size_y, size_x = tiles[0].shape[:2]
    columns = max(1, min(columns, len(tiles)))
    rows = -(-len(tiles) // columns)
    font_size = max(11, size_y // 22)
    header = int(font_size * 3.4)
    sheet = Image.new("RGB", (columns * size_x, header + rows * size_y), BACKGROUND)
    draw = ImageDraw.Draw(sheet)
    font, small = _font(font_size + 2), _font(font_size)
    draw.text((8, 4), title or "", fill=(20, 20, 20), font=font)
    draw.text((8, 4 + int(font_size * 1.6)), caption or "", fill=(70, 70, 70), font=small)
    if colorbar is not None:
        vmax, units = colorbar
        bar_w, bar_h = min(180, columns * size_x // 4), max(8, font_size // 2)
        x0, y0 = columns * size_x - bar_w - 60, int(font_size * 0.5)
        ramp = (tex.colormap(np.linspace(0, vmax, bar_w), vmax) * 255).astype(np.uint8)
        sheet.paste(Image.fromarray(np.repeat(ramp[None], bar_h, axis=0)), (x0, y0))
        draw.text((x0, y0 + bar_h + 2), "0", fill=(60, 60, 60), font=small)
        draw.text(
            (x0 + bar_w - 10, y0 + bar_h + 2), f"{vmax:.3g}{units}", fill=(60, 60, 60), font=small
        )
    for k, (tile, label) in enumerate(zip(tiles, labels, strict=True)):
        x, y = (k % columns) * size_x, header + (k // columns) * size_y
        sheet.paste(Image.fromarray(tile), (x, y))
        draw.rectangle([x, y, x + size_x - 1, y + size_y - 1], outline=(225, 225, 225))
        draw.text((x + 6, y + 4), label, fill=(30, 30, 30), font=small)
    return sheet


def _readable(path: Path) -> Path:
    """Usual permissions (umask) for a file written through a private temporary."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)
    return path


def _save_image(image, path: Path) -> Path:
    path = Path(path)
    fmt = (path.suffix.lstrip(".") or "png").upper().replace("JPG", "JPEG")
    with atomic_path(path) as tmp:
        try:
            image.save(tmp, format=fmt)
        except (KeyError, ValueError) as exc:
            raise InputError(f"cannot write an image in format {fmt!r} ({exc})", path) from exc
    return _readable(path)


def contact_sheet(
    result,
    path,
    *,
    frames=None,
    columns: int = 4,
    texture: str = "checker",
    truth=None,
    error_colors: bool = False,
    observed_tint: bool = True,
    input=None,
    tile: int = 320,
    camera: Camera | None = None,
    title: str | None = None,
) -> Path:
    """Frames of a result in a grid, one camera for all, written as a PNG.

    The texture (``"checker"``, ``"grid"`` or ``"none"``) is painted on the first frame and
    carried to every frame by the correspondences of an :class:`AnimatedMesh`, so drift
    shows as a swimming pattern; for a :class:`MeshSequence` it comes from each frame's own
    positions (the caption says so).

    Parameters
    ----------
    result : AnimatedMesh, MeshSequence or path of a saved result
    path : str or Path
        The image to write (PNG; the format follows the extension).
    frames : sequence of int, optional
        Default: about 8 evenly spaced frames, first and last included.
    columns : int
    truth : AnimatedMesh, optional
        Ground truth for ``error_colors`` (per-vertex distance to the truth surface).
    error_colors : bool
        Colour vertices by their distance to ``truth`` (one scale for all frames).
    observed_tint : bool
        Tint vertices that were filled in (``observed == False``) blue.
    input : PointCloudSequence, optional
        Input points drawn over each frame (the frame with the same index, or nearest time).
    tile : int
        Side of one frame's picture in pixels.
    camera : Camera, optional
        Default: fitted to the bounds of the whole sequence (3/4 view, Y up).
    title : str, optional

    Returns
    -------
    Path
        ``path``.
    """
    result = as_result(result)
    if columns < 1:
        raise InputError(f"columns must be at least 1, got {columns}")
    picked = pick_frames(result.frame_count, frames)
    camera = camera or fit_camera(_sequence_bounds(result, None, input))
    styler = _Styler(
        result, texture=texture, truth=truth, error_colors=error_colors, observed_tint=observed_tint
    )
    tiles = _render_frames(result, picked, camera, tile, styler, input)
    labels = [f"frame {i}  t={result.times[i]:.3g}" for i in picked]
    kind = "animated mesh" if isinstance(result, AnimatedMesh) else "mesh sequence"
    title = title or f"{kind}: {result.frame_count} frames"
    colorbar = (styler.scale, "") if styler.errors is not None else None
    return _save_image(_grid_image(tiles, labels, columns, title, styler.caption(), colorbar), path)


def bench_sheet(result, truth, path, *, title: str | None = None, frames=None) -> Path:
    """The benchmark's picture of one (scene, method): a contact sheet with the first-frame
    checkerboard (drift shows as swimming checks) and filled-in regions tinted.

    ``truth`` is accepted for a future error row and to fit the camera to both; it may be None.
    """
    result = as_result(result)
    camera = fit_camera(_sequence_bounds(result, truth))
    return contact_sheet(
        result,
        path,
        frames=frames,
        columns=4,
        texture="checker",
        truth=truth,
        error_colors=False,
        observed_tint=True,
        tile=256,
        camera=camera,
        title=title,
    )


def turntable(
    result,
    path,
    *,
    frame: int = 0,
    views: int = 8,
    columns: int = 4,
    texture: str = "checker",
    tile: int = 320,
    fps: float = 12.0,
) -> Path:
    """One frame seen from ``views`` angles around the vertical axis.

    A ``.gif`` path writes an animation; any other image extension a grid of the views.
    """
    result = as_result(result)
    if views < 1:
        raise InputError(f"views must be at least 1, got {views}")
    (frame,) = pick_frames(result.frame_count, [frame])
    base = fit_camera(_sequence_bounds(result))
    styler = _Styler(result, texture=texture, truth=None, error_colors=False, observed_tint=True)
    angles = [360.0 * k / views for k in range(views)]
    tiles = [_render_frames(result, [frame], base.orbit(a), tile, styler, None)[0] for a in angles]
    path = Path(path)
    if path.suffix.lower() == ".gif":
        return _write_gif(tiles, path, fps)
    labels = [f"{a:.0f} deg" for a in angles]
    return _save_image(
        _grid_image(tiles, labels, columns, f"turntable, frame {frame}", styler.caption()), path
    )


def _write_gif(images, path: Path, fps: float) -> Path:
    from PIL import Image

    if not fps > 0:
        raise InputError(f"fps must be positive, got {fps}")
    pil = [Image.fromarray(im) for im in images]
    with atomic_path(path) as tmp:
        pil[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=pil[1:],
            duration=int(round(1000.0 / fps)),
            loop=0,
            optimize=False,
        )
    return _readable(path)


def render_animation(
    result,
    path,
    *,
    fps: float = 10.0,
    size: int = 384,
    texture: str = "checker",
    truth=None,
    error_colors: bool = False,
    observed_tint: bool = True,
    input=None,
    frames=None,
) -> Path:
    """The whole sequence (or ``frames``) as an animated ``.gif`` (Pillow) or ``.mp4``
    (needs the ``imageio-ffmpeg`` package; an InputError says so when it is missing)."""
    result = as_result(result)
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise InputError("animation path must end in .gif or .mp4", path)
    if suffix == ".mp4":
        try:
            import imageio.v2 as imageio
            import imageio_ffmpeg  # noqa: F401
        except ImportError as exc:
            raise InputError(
                "writing MP4 needs the imageio-ffmpeg package (pip install imageio-ffmpeg); "
                "use a .gif path instead",
                path,
            ) from exc
    picked = (
        list(range(result.frame_count))
        if frames is None
        else pick_frames(result.frame_count, frames)
    )
    camera = fit_camera(_sequence_bounds(result, None, input))
    styler = _Styler(
        result, texture=texture, truth=truth, error_colors=error_colors, observed_tint=observed_tint
    )
    size += size % 2  # even sizes for video encoders
    images = _render_frames(result, picked, camera, size, styler, input)
    if suffix == ".gif":
        return _write_gif(images, path, fps)
    with atomic_path(path) as tmp:
        with imageio.get_writer(tmp, fps=fps, codec="libx264", macro_block_size=2) as writer:
            for im in images:
                writer.append_data(im)
    return _readable(path)
