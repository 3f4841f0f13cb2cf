"""``fourd demo``: the embedded default run, needing no downloaded data.

Builds a small procedural deforming shape, scans it with three virtual depth cameras,
reconstructs it with the default method, and writes the result, its metrics against the
known truth, a picture and a web viewer.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from fourd import synth
from fourd.animation import AnimatedMesh
from fourd.io.results import save
from fourd.jsonable import jsonable
from fourd.methods import DEFAULT_METHOD, reconstruct

log = logging.getLogger("fourd.demo")

DEMO_SCENE = "bending-arm"
DEMO_FRAMES = 12
DEMO_RESOLUTION = 160


def run_demo(
    outdir: str | Path = "demo-out",
    *,
    method: str | None = None,
    scene: str = DEMO_SCENE,
    frames: int = DEMO_FRAMES,
    seed: int = 0,
) -> dict[str, Path]:
    """Run the demo; returns the paths written, by label."""
    from fourd.metrics import evaluate
    from fourd.synth.write import write_synth
    from fourd.viz.render import contact_sheet
    from fourd.viz.viewer import write_viewer

    method = method or DEFAULT_METHOD
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    log.info("demo: scene %s, %d frames, method %s", scene, frames, method)
    truth = synth.scene(scene, frames=frames, seed=seed)
    scans = synth.scan(truth, cameras=3, noise=0.002, outliers=0.02, resolution=DEMO_RESOLUTION, seed=seed)
    write_synth(truth, scans, outdir / "scans")

    reconstruct_started = time.perf_counter()
    result = reconstruct(scans, method)
    seconds = time.perf_counter() - reconstruct_started
    paths = {}
    suffixes = [".glb", ".npz"]
    for suffix in suffixes:
        paths[f"result{suffix}"] = outdir / f"result{suffix}"
        save(result, paths[f"result{suffix}"])

    metrics = evaluate(result, truth, timing={"seconds_per_frame": seconds / len(scans)})
    metrics = {"scene": scene, "frames": frames, "method": method, **metrics}
    paths["metrics"] = outdir / "metrics.json"
    from fourd.io.atomic import atomic_path

    with atomic_path(paths["metrics"]) as tmp:
        tmp.write_text(json.dumps(jsonable(metrics), indent=2))
    paths["contact sheet"] = contact_sheet(
        result, outdir / "contact-sheet.png", truth=truth if isinstance(result, AnimatedMesh) else None, input=scans
    )
    paths["viewer"] = write_viewer(result, outdir / "view", truth=truth, scans=scans, metrics=metrics)
    log.info("demo finished in %.1f s (reconstruction %.2f s/frame)", time.perf_counter() - started,
             seconds / len(scans))
    summary = {k: metrics.get(k) for k in ("chamfer", "completeness_95", "correspondence_mean",
                                           "correspondence_last") if k in metrics}
    log.info("metrics: %s", ", ".join(f"{k} {v:.4f}" for k, v in summary.items() if v is not None))
    return paths


