"""The HTML viewer: one folder whose ``index.html`` plays a result with three.js.

The page is self-contained: three.js (bundled with the package, MIT licence beside it), the
viewer script, its style and the data (vertex positions per frame, first-frame texture
lattice, ``observed`` flags, per-vertex errors against a truth, input points, metrics and the
exported ``.glb``) are inlined, so it opens from a local file (``file://`` pages cannot
``fetch()`` sibling files or load ES modules in Chromium) and from any static HTTP server
alike, and loads nothing from the network. The same pieces are also written beside it
(``viewer.js``, ``viewer.css``, ``three.fourd.min.js``, ``result.glb``,
``metrics.json``) for reuse.

With the input scans it can also show whether the texture swims (:func:`write_viewer`'s
``carried_colors`` and ``video``; ``fourd view --input``):

- the "carried colour" colouring: each vertex keeps the colour the input had under it at frame
  0 (:func:`carried_vertex_colors`), on every frame, and the input points are drawn in their
  own colours of each frame; vertices drifting over the surface show as colours sliding
  against the points';
- the video panel (:mod:`fourd.viz.video_panel`): the selected camera's image of the frame
  shown (downscaled to ``video_size`` pixels at most, the page says when), with the mesh's
  outline projected over it through the camera's calibration, following the frame slider and
  playback.

The page sets ``window.fourdReady = true`` once loaded and exposes ``window.fourdSetFrame(i)``
and ``window.fourdVideo()`` (used by the browser test).
"""

from __future__ import annotations

import base64
import dataclasses
import json
import logging
import os
import re
from importlib import resources
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.io.atomic import atomic_path
from fourd.io.results import as_result
from fourd.jsonable import jsonable
from fourd.viz import texture as tex
from fourd.viz.video_panel import VIDEO_SIZE, video_panel

log = logging.getLogger("fourd.viz.viewer")

#: Files of ``fourd/viz/static`` copied beside the page.
STATIC_FILES = ("three.fourd.min.js", "viewer.js", "viewer.css", "three.LICENSE")

#: Largest ``.glb`` inlined into the page; a bigger one stays beside it and the page fetches
#: it when served over HTTP (from ``file://`` its playback toggle is then unavailable).
EMBED_GLB_LIMIT = 24_000_000

#: Input points kept per frame in the page (a seeded subsample beyond this).
MAX_POINTS_PER_FRAME = 30_000


def _static(name: str) -> str:
    return resources.files("fourd.viz").joinpath("static", name).read_text(encoding="utf-8")


def _b64(array, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def _load_scans(scans):
    if scans is None or hasattr(scans, "frames"):
        return scans
    from fourd import load_sequence

    return load_sequence(scans)


def _load_metrics(metrics):
    if metrics is None or isinstance(metrics, dict):
        return metrics
    path = Path(metrics)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read the metrics JSON ({exc})", path) from exc


def _subsample(count: int, limit: int, seed: int) -> np.ndarray:
    """Indices of at most ``limit`` of ``count`` points, in order (a seeded draw beyond it)."""
    if count <= limit:
        return np.arange(count)
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(count, size=limit, replace=False))


def _point_colors(frame) -> np.ndarray:
    """A frame's recorded colours [P, 3] in [0, 1], mid grey where it has none."""
    return frame.colors if frame.colors is not None else np.full((len(frame.points), 3), 0.5)


def input_frames(scans, result) -> np.ndarray:
    """For each result frame, the input frame shown beside it: the same index when the counts
    agree, else the input frame nearest in time; int64 ``[T]``."""
    if len(scans.frames) == result.frame_count:
        return np.arange(result.frame_count)
    times = np.asarray(scans.times)
    return np.abs(times[None, :] - np.asarray(result.times)[:, None]).argmin(axis=1)


def _write_glb(result, outdir: Path) -> Path | None:
    """``outdir/result.glb`` through :func:`fourd.io.results.save`, or None when that writer
    is not available (the page then plays from the inlined frames only)."""
    if not isinstance(result, AnimatedMesh) or len(result.faces) == 0:
        return None
    try:
        from fourd.io.results import save
    except ImportError:
        log.info("fourd.io.results is not available: no .glb in the viewer")
        return None
    path = outdir / "result.glb"
    if result.uv is not None:  # the page paints its own texture on the result's N vertices:
        result = dataclasses.replace(result, uv=None)  # no vertices split on UV seams
    try:
        save(result, path)
    except (InputError, NotImplementedError, ValueError) as exc:
        log.warning("could not write %s (%s): the viewer plays the inlined frames only", path, exc)
        return None
    return path if path.exists() else None


def carried_vertex_colors(anim: AnimatedMesh, scans, source=None) -> np.ndarray:
    """The "carried colour" [N, 3] in [0, 1]: frame 0's vertex colours from the input's
    colours (:func:`fourd.appearance.vertex_colors.frame_vertex_colors`), kept on every frame;
    InputError naming ``source`` (the input's path) when the input has no colours."""
    from fourd.appearance.vertex_colors import frame_vertex_colors

    if not any(frame.colors is not None for frame in scans.frames):
        raise InputError("has no colours to carry to the vertices (its frames hold none)", source)
    return frame_vertex_colors(anim, scans, 0)


def vertex_flexibility(faces: np.ndarray, material, vertex_count: int) -> np.ndarray:
    """Per vertex [N] in [0, 1]: 1 minus the smallest bending stiffness of its edges, scaled
    over the mesh (0: the stiffest vertex, 1: the most flexible)."""
    from fourd.deform import load_material
    from fourd.geometry.meshes import face_adjacency

    material = load_material(material) if isinstance(material, (str, os.PathLike)) else material
    material.check(faces)
    _, edges = face_adjacency(faces)
    bending = material.bending if material.bending.ndim == 1 else material.bending.min(axis=1)
    stiffness = np.full(vertex_count, np.inf)
    np.minimum.at(stiffness, edges[:, 0], bending)
    np.minimum.at(stiffness, edges[:, 1], bending)
    stiffness[~np.isfinite(stiffness)] = bending.max() if len(bending) else 1.0
    span = float(np.ptp(stiffness))
    return (stiffness.max() - stiffness) / span if span > 0 else np.zeros(vertex_count)


def viewer_data(
    result,
    *,
    truth=None,
    scans=None,
    metrics=None,
    title=None,
    glb: bytes | None = None,
    cells: float = 10.0,
    fps: float | None = None,
    material=None,
    carried_colors: bool | None = False,
    video: bool | None = False,
    video_size: int = VIDEO_SIZE,
    source=None,
) -> dict:
    """The page's data (``window.FOURD_DATA``) as a JSON-ready dict; arrays are base64 of
    little-endian float32 / uint32 / uint8 (options: :func:`write_viewer`; ``source``: the
    result's path, named in error messages, by default ``result`` when it is a path)."""
    if source is None and isinstance(result, (str, os.PathLike)):
        source = result
    result = as_result(result)
    animated = isinstance(result, AnimatedMesh)
    if carried_colors and not animated:
        raise InputError(
            "carried colours need an animated mesh (one connectivity), not per-frame meshes",
            source,
        )
    frames0 = result.frame(0)[0]
    box = np.stack([frames0.min(axis=0), frames0.max(axis=0)]) if len(frames0) else result.bounds()
    space = tex.texture_space(box, cells=cells)
    bounds = result.bounds()
    data: dict = {
        "version": 1,
        "title": title or ("animated mesh" if animated else "mesh sequence"),
        "kind": "animated" if animated else "sequence",
        "frameCount": result.frame_count,
        "times": [float(t) for t in result.times],
        "texture": {"origin": [float(x) for x in space.origin], "cell": float(space.cell)},
        "palette": {
            "dark": tex.CHECK_DARK.tolist(),
            "light": tex.CHECK_LIGHT.tolist(),
            "clay": tex.CLAY.tolist(),
            "tint": tex.FILLED_TINT.tolist(),
        },
        "colormap": tex.colormap(np.linspace(0.0, 1.0, 64), 1.0).round(4).tolist(),
        "fps": float(fps) if fps else 10.0,
        "metrics": jsonable(metrics) if metrics is not None else {},
        "hasErrors": False,
    }
    if animated:
        data["caption"] = (
            "Texture painted on frame 0 and carried by the correspondences: drift shows as swimming checks."
        )
        data["vertexCount"] = result.vertex_count
        data["positions"] = _b64(result.vertices, "<f4")
        data["faces"] = _b64(result.faces, "<u4")
        if not result.observed.all():
            data["observed"] = _b64(result.observed, "u1")
    else:
        data["caption"] = (
            "Mesh sequence without correspondence: the texture comes from each frame's own positions."
        )
        data["frames"] = [
            {"positions": _b64(v, "<f4"), "faces": _b64(f, "<u4")} for v, f in result.meshes
        ]
    if truth is not None:
        truth = as_result(truth)
        errors = tex.vertex_errors(result, truth)
        data["errorScale"] = tex.error_scale(errors)
        data["truthDiagonal"] = float(truth.diagonal())
        data["hasErrors"] = True
        if animated:
            data["errors"] = _b64(np.stack(errors), "<f4")
        else:
            for entry, err in zip(data["frames"], errors, strict=True):
                entry["errors"] = _b64(err, "<f4")
        bounds = np.stack(
            [np.minimum(bounds[0], truth.bounds()[0]), np.maximum(bounds[1], truth.bounds()[1])]
        )
    if material is not None:
        if truth is not None:
            raise InputError("colour by the truth or by a material, not both")
        if not animated:
            raise InputError("a material colours an animated mesh (one connectivity), not per-frame meshes")
        flexible = vertex_flexibility(result.faces, material, result.vertex_count)
        data["errors"] = _b64(np.tile(flexible, (result.frame_count, 1)), "<f4")
        data["errorScale"] = 1.0
        data["hasErrors"] = True
        data["errorLabel"] = "stiffness colouring (learned material)"
        data["errorLegend"] = (
            "Flexibility of the learned material at each vertex (1 minus the smallest bending "
            "stiffness of its edges, scaled to the mesh's range): pale is stiff, dark bends."
        )
    if (carried_colors or video) and scans is None:
        wanted = "carried colours need" if carried_colors else "the video panel needs"
        raise InputError(f"{wanted} the input scans (fourd view --input FOLDER)")
    if scans is not None:
        where = None if hasattr(scans, "frames") else scans  # the input's path, for errors
        scans = _load_scans(scans)
        if carried_colors is None:  # when the input can give them
            carried_colors = animated and any(f.colors is not None for f in scans.frames)
        if video is None:
            video = scans.video is not None
        shown = input_frames(scans, result)
        kept = [_subsample(len(f.points), MAX_POINTS_PER_FRAME, i) for i, f in enumerate(scans.frames)]
        pts = [scans.frames[k].points[kept[k]] for k in shown]
        data["points"] = [_b64(p, "<f4") for p in pts]
        all_points = np.concatenate(pts)
        if len(all_points):
            from fourd.geometry.neighbors import point_spacing

            data["pointSize"] = float(point_spacing(pts[0]) * 0.6) if len(pts[0]) > 3 else None
        if carried_colors:
            carried = carried_vertex_colors(result, scans, where)
            data["carriedColors"] = _b64(np.round(carried * 255.0), "u1")
            # the points in their own colours (grey where a frame has none)
            data["pointColors"] = [
                _b64(np.round(_point_colors(scans.frames[k])[kept[k]] * 255.0), "u1") for k in shown
            ]
        if video:
            if scans.video is None:
                raise InputError(
                    "has no video to show (cameras.json and video/<camera>/ images)", where
                )
            data["video"] = video_panel(scans.video, shown, size=video_size)
    first_faces = result.frame(0)[1]
    if len(first_faces) == 0 and len(frames0) > 3:
        from fourd.geometry.neighbors import point_spacing

        data["vertexPointSize"] = float(point_spacing(frames0) * 0.9)
    data["bounds"] = bounds.tolist()
    if glb is not None:
        data["glb"] = base64.b64encode(glb).decode("ascii")
    return data


_DATA_PREFIX = "window.FOURD_DATA = "


def read_viewer_data(index) -> dict:
    """The data inlined in a viewer page written by :func:`write_viewer` (for tools and tests)."""
    index = Path(index)
    try:
        page = index.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read the viewer page ({exc})", index) from exc
    start = page.find(_DATA_PREFIX)
    end = page.find(";\n</script>", start)
    if start < 0 or end < 0:
        raise InputError("not a fourd viewer page (no FOURD_DATA)", index)
    return json.loads(page[start + len(_DATA_PREFIX) : end])


def _readable(path: Path) -> None:
    """Give a file written through a private temporary the usual permissions (umask)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    _readable(path)


def write_viewer(
    result,
    outdir,
    *,
    truth=None,
    scans=None,
    metrics=None,
    title: str | None = None,
    fps: float | None = None,
    material=None,
    carried_colors: bool = False,
    video: bool = False,
    video_size: int = VIDEO_SIZE,
) -> Path:
    """Write the viewer folder and return the path of its ``index.html``.

    Parameters
    ----------
    result : AnimatedMesh, MeshSequence or path of a saved result
    outdir : str or Path
        Folder to write into (created when missing; its parent must exist). The viewer's files
        in it are replaced; nothing else in it is touched.
    truth : AnimatedMesh or path, optional
        Ground truth: enables the error colouring (distance of each vertex to the truth).
    scans : PointCloudSequence or folder, optional
        Input points, shown per frame with the "input points" toggle (subsampled to
        :data:`MAX_POINTS_PER_FRAME`).
    metrics : dict or path of a JSON file, optional
        Shown in the side panel and written as ``metrics.json``.
    title : str, optional
    fps : float, optional
        Playback rate at speed 1 (default 10 frames per second).
    material : Material or path, optional
        A learned material (:func:`fourd.deform.learn_material`) of the result's mesh: the
        colouring shows where it bends (:func:`vertex_flexibility`) instead of the error.
    carried_colors : bool or None
        Add the "carried colour" colouring: frame 0's vertex colours taken from the input's
        colours (:func:`carried_vertex_colors`) and kept on every frame, beside the input points
        in their own colours; vertices that drift over the surface show as colours swimming
        against the points'. Needs ``scans`` with colours and an animated mesh (one
        connectivity). None: when those are there.
    video : bool or None
        Show the input's video (``scans.video``: ``cameras.json`` and ``video/<camera>/``) in a
        panel beside the mesh, the selected camera's image of the frame shown, with the mesh's
        outline projected over it (:mod:`fourd.viz.video_panel`). Needs ``scans`` with video.
        None: when the input has video.
    video_size : int
        Longest side, in pixels, of the inlined video images (default
        :data:`~fourd.viz.video_panel.VIDEO_SIZE`); larger ones are downscaled, and the page
        says so.

    Returns
    -------
    Path
        ``outdir/index.html``.
    """
    source = result if isinstance(result, (str, os.PathLike)) else None
    result = as_result(result)
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise InputError("exists and is not a folder", outdir)
    if not outdir.parent.exists():
        raise InputError("the output folder's parent does not exist", outdir.parent)
    metrics = _load_metrics(metrics)
    # the data first: a bad request fails before anything is written
    data = viewer_data(
        result, truth=truth, scans=scans, metrics=metrics, title=title, fps=fps,
        material=material, carried_colors=carried_colors, video=video, video_size=video_size,
        source=source,
    )
    outdir.mkdir(exist_ok=True)
    glb_path = _write_glb(result, outdir)
    glb = None
    if glb_path is not None:
        _readable(glb_path)
        if glb_path.stat().st_size <= EMBED_GLB_LIMIT:
            glb = glb_path.read_bytes()
        else:
            log.info(
                "%s is over %d bytes: not inlined (the page fetches it over HTTP)",
                glb_path,
                EMBED_GLB_LIMIT,
            )
    if glb is not None:
        data["glb"] = base64.b64encode(glb).decode("ascii")
    elif glb_path is not None:
        data["glbUrl"] = glb_path.name
    data_js = _DATA_PREFIX + json.dumps(data, separators=(",", ":")) + ";"

    for name in STATIC_FILES:
        _write_text(outdir / name, _static(name))
    if metrics is not None:
        _write_text(outdir / "metrics.json", json.dumps(jsonable(metrics), indent=2) + "\n")

    page = _static("index.template.html")
    title_text = (
        (title or data["title"]).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    )
    parts = {
        "{{TITLE}}": title_text,
        "{{CSS}}": _static("viewer.css"),
        "{{THREE}}": _static("three.fourd.min.js"),
        # JSON may contain "</" only inside strings; escape it so it cannot end the script
        "{{DATA}}": data_js.replace("</", "<\\/"),
        "{{VIEWER}}": _static("viewer.js"),
    }
    # one pass, so text inserted for one marker is never scanned for another
    page = re.sub(r"\{\{(TITLE|CSS|THREE|DATA|VIEWER)\}\}", lambda m: parts[m.group(0)], page)
    index = outdir / "index.html"
    _write_text(index, page)
    log.info("viewer written to %s (%.1f MB)", index, index.stat().st_size / 1e6)
    return index
