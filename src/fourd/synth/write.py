"""Writing a synthetic capture to disk: the scan folder plus its ground truth.

Layout of ``OUTDIR`` (what ``fourd synth SCENE OUTDIR`` produces)::

    OUTDIR/
      frame_0000.ply ...   binary PLY scans, one per kept frame (fourd.io.frames.write_frames),
                           with red green blue when the scan has an appearance
      times.txt            one time per frame
      sensors.json         the fixed camera positions {"sensors": [[x, y, z], ...]}
      cameras.json         with video: the calibrated cameras (fourd.appearance.cameras)
      video/cam_<k>/frame_0000.png ...   with video: each camera's image of each frame
      truth.npz            the ground truth (AnimatedMesh: vertices, faces, times, observed[, rest];
                           MeshSequence: kind="meshes", vertices_<t>, faces_<t>, times)
      truth.json           what was generated (scene, frames, seed, scan options), when given
      pattern.png          garment scenes: the photo of the garment laid out flat (white on
                           black; fourd.synth.garments.pattern_photo)
      pattern.json         its calibration: pixels_per_unit, origin, outline and openings
                           (the garment's boundaries as polylines; garment units)

``fourd.load_sequence(OUTDIR)`` reads the scans (files named ``truth.*`` are not frames) and
``fourd.load_result(OUTDIR / "truth.npz")`` the truth. The folder is assembled under a temporary
name and renamed into place, so it is either complete or absent.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.atomic import atomic_dir
from fourd.jsonable import jsonable
from fourd.sequence import PointCloudSequence

logger = logging.getLogger("fourd.synth.write")

TRUTH_FILE = "truth.npz"
INFO_FILE = "truth.json"
PATTERN_IMAGE = "pattern.png"
PATTERN_FILE = "pattern.json"


def save_truth(truth, path: str | os.PathLike) -> None:
    """Write a ground truth as ``.npz`` (the layout of :func:`fourd.save`)."""
    from fourd.io.results import save

    save(truth, path)


def write_pattern_photo(pattern, folder: str | os.PathLike) -> Path:
    """Write a garment's photo (``pattern``: ``(outline [K, 2], openings)`` of
    :func:`fourd.synth.garments.pattern_outline`) into ``folder`` as ``pattern.png`` with its
    calibration ``pattern.json`` beside it (what ``garment``'s ``photo`` option reads); returns
    the photo's path."""
    from PIL import Image

    from fourd.synth.garments import pattern_photo

    folder = Path(folder)
    image, calibration = pattern_photo(*pattern)
    Image.fromarray(image).save(folder / PATTERN_IMAGE)
    (folder / PATTERN_FILE).write_text(json.dumps(calibration, indent=1) + "\n")
    return folder / PATTERN_IMAGE


def write_synth(
    truth,
    scans: PointCloudSequence,
    outdir: str | os.PathLike,
    *,
    info: dict | None = None,
    pattern=None,
) -> Path:
    """Write the scans of a ground truth and the truth itself into ``outdir``.

    Parameters
    ----------
    truth : AnimatedMesh or MeshSequence
    scans : PointCloudSequence
        E.g. :func:`fourd.synth.scan` of ``truth``.
    outdir : path-like
        Folder to create (replaced as a whole if it exists; its parent must exist).
    info : dict, optional
        JSON-able description (scene name, seed, options) written to ``truth.json``.
    pattern : (outline [K, 2], openings) , optional
        A garment's flat outline and openings (:func:`fourd.synth.garments.pattern_outline`):
        its photo is written to ``pattern.png`` and ``pattern.json``.

    Returns
    -------
    pathlib.Path
        ``outdir``.
    """
    from fourd.io.frames import write_frames

    if not isinstance(scans, PointCloudSequence):
        raise InputError(f"scans must be a PointCloudSequence, got {type(scans).__name__}")
    if not isinstance(truth, (AnimatedMesh, MeshSequence)):
        raise InputError(
            f"the truth must be an AnimatedMesh or a MeshSequence, got {type(truth).__name__}"
        )
    outdir = Path(outdir)
    with atomic_dir(outdir) as tmp:
        write_frames(scans, tmp)
        save_truth(truth, tmp / TRUTH_FILE)
        if info is not None:
            (tmp / INFO_FILE).write_text(json.dumps(jsonable(info), indent=1) + "\n")
        if pattern is not None:
            write_pattern_photo(pattern, tmp)
    logger.info("wrote %d scanned frames and the truth to %s", len(scans), outdir)
    return outdir


def synthesize(
    name: str,
    outdir: str | os.PathLike,
    *,
    frames: int | None = None,
    seed: int = 0,
    scene_options: dict | None = None,
    **scan_options,
):
    """Build scene ``name``, scan it and write both to ``outdir`` (``fourd synth``).

    ``scan_options`` are :class:`~fourd.synth.scanner.ScanOptions` fields (``cameras``,
    ``noise``, ``outliers`` ...); the scan uses ``seed`` unless ``scan_options`` gives one.

    Returns
    -------
    (truth, scans) : (AnimatedMesh or MeshSequence, PointCloudSequence)
    """
    from fourd.synth.scanner import scan_options as make_scan_options
    from fourd.synth.scenes import scene

    truth = scene(name, frames=frames, seed=seed, **(scene_options or {}))
    scan_options.setdefault("seed", seed)
    options = make_scan_options(None, **scan_options)
    from fourd.synth.scanner import scan

    scans = scan(truth, options)
    info = {
        "scene": name,
        "frames": truth.frame_count,
        "seed": seed,
        "scene_options": scene_options or {},
        "scan": options,
        "diagonal": truth.diagonal(),
        "kind": "meshes" if isinstance(truth, MeshSequence) else "animated",
    }
    from fourd.synth.garments import GARMENT_SCENES, pattern_outline

    pattern = pattern_outline(name, with_openings=True) if name in GARMENT_SCENES else None
    write_synth(truth, scans, outdir, info=info, pattern=pattern)
    return truth, scans
