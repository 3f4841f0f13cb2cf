"""The HTML viewer: one folder whose ``index.html`` plays a result with three.js.

The page is self-contained: three.js (bundled with the package, MIT licence beside it), the
viewer script, its style and the data (vertex positions per frame, first-frame texture
lattice, ``observed`` flags, per-vertex errors against a truth, input points, metrics and the
exported ``.glb``) are inlined, so it opens from a local file (``file://`` pages cannot
``fetch()`` sibling files or load ES modules in Chromium) and from any static HTTP server
alike, and loads nothing from the network. The same pieces are also written beside it
(``viewer.js``, ``viewer.css``, ``three.fourd.min.js``, ``result.glb``,
``metrics.json``) for reuse.

The page sets ``window.fourdReady = true`` once loaded and exposes ``window.fourdSetFrame(i)``
(used by the browser test).
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


def _subsample(points: np.ndarray, limit: int, seed: int) -> np.ndarray:
    if len(points) <= limit:
        return points
    rng = np.random.default_rng(seed)
    return points[np.sort(rng.choice(len(points), size=limit, replace=False))]


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
) -> dict:
    """The page's data (``window.FOURD_DATA``) as a JSON-ready dict; arrays are base64 of
    little-endian float32 / uint32 / uint8."""
    result = as_result(result)
    animated = isinstance(result, AnimatedMesh)
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
    if scans is not None:
        scans = _load_scans(scans)
        pts = [_subsample(f.points, MAX_POINTS_PER_FRAME, i) for i, f in enumerate(scans.frames)]
        if len(pts) != result.frame_count:
            times = np.asarray(scans.times)
            pts = [pts[int(np.argmin(np.abs(times - t)))] for t in result.times]
        data["points"] = [_b64(p, "<f4") for p in pts]
        all_points = np.concatenate(pts)
        if len(all_points):
            from fourd.geometry.neighbors import point_spacing

            data["pointSize"] = float(point_spacing(pts[0]) * 0.6) if len(pts[0]) > 3 else None
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

    Returns
    -------
    Path
        ``outdir/index.html``.
    """
    result = as_result(result)
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise InputError("exists and is not a folder", outdir)
    if not outdir.parent.exists():
        raise InputError("the output folder's parent does not exist", outdir.parent)
    outdir.mkdir(exist_ok=True)
    metrics = _load_metrics(metrics)

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
    data = viewer_data(
        result, truth=truth, scans=scans, metrics=metrics, title=title, glb=glb, fps=fps,
        material=material,
    )
    if glb_path is not None and glb is None:
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
