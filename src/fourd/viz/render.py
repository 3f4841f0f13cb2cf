"""Sheets, turntables and animations of a result, drawn with the software rasteriser
(:mod:`fourd.viz.raster`).

:func:`contact_sheet` (frames in a grid, texture carried from the first frame by the
correspondences, optional error and ``observed`` colouring), :func:`turntable`,
:func:`render_animation` (GIF via Pillow; MP4 when ``imageio-ffmpeg`` is installed) and
:func:`bench_sheet` for the benchmark.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.io.atomic import atomic_path
from fourd.io.results import as_result
from fourd.viz import texture as tex
from fourd.viz.camera import Camera, fit_camera
from fourd.viz.raster import BACKGROUND, render

log = logging.getLogger("fourd.viz.render")


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
