"""Question: the wrinkling step (thesis chapter 4) makes the plain T-shirt's Chamfer slightly
worse (0.00215 -> 0.00219 in the bench): is that the wrinkles moving vertices the scan observed
off their data, and does holding observed vertices to their data
(`garment.Options.wrinkles_hold_data`) keep the folds and lose the error?

    python experiments/garment_wrinkles_data.py tshirt-diffuse-video

Fits `garment` once per row (its bench options: `boundaries` from the scene) without
wrinkles, with the thesis' wrinkles everywhere, and with them held to the data; prints Chamfer,
accuracy and completeness-95 (five digits, 60k samples as the bench), the fold recall and
precision, correspondence mean / last frame. The scan is kept in /tmp between runs (shared
with `garment_fit_data.py`).

Answer (2-core machine, nothing else running, at the commit adding `wrinkles_hold_data`):

| row | Chamfer (accuracy) | completeness-95 | fold recall / precision | s/frame |
|---|---|---|---|---|
| no wrinkles | 0.00215 (0.00193) | 0.00418 | 0.751 / 0.556 | 4.81 |
| wrinkles everywhere (thesis) | 0.00219 (0.00198) | 0.00421 | 0.765 / 0.512 | 7.21 |
| wrinkles held to the data | 0.00215 (0.00193) | 0.00417 | 0.758 / 0.549 | 7.29 |

Correspondence 0.0134 / 0.0138 in every row. Yes: the Chamfer the thesis' wrinkles add is in
the accuracy, the observed vertices moved off the scan's surface; held to the data they keep
the fit's accuracy, and the folds they add where the template completed the frame (and where a
vertex lagged its data) keep most of the recall they gained.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

from fourd.methods import garment
from fourd.metrics import evaluate
from fourd.metrics.folds import fold_recall

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from garment_fit_data import BOUNDARIES, _scene  # noqa: E402

ROWS = {
    "no wrinkles": {"wrinkles": False},
    "wrinkles everywhere (thesis)": {"wrinkles": True, "wrinkles_hold_data": False},
    "wrinkles held to the data": {"wrinkles": True, "wrinkles_hold_data": True},
}


def main(label: str) -> None:
    scene, truth, scans = _scene(label)
    base = garment.Options(boundaries=BOUNDARIES[scene.name])
    for name, fields in ROWS.items():
        started = time.perf_counter()
        result = garment.reconstruct(scans, replace(base, **fields))
        seconds = time.perf_counter() - started
        r = evaluate(result, truth, samples=60000, seed=0)
        folds = fold_recall(result, truth)
        print(f"{label} {name}: Chamfer {r['chamfer']:.5f} (accuracy {r['accuracy']:.5f}), completeness-95 "
              f"{r['completeness_95']:.5f}, fold recall {folds['fold_recall']:.3f} precision "
              f"{folds['fold_precision']:.3f}, correspondence {r['correspondence_mean']:.4f} / "
              f"{r['correspondence_last']:.4f}, {seconds / len(scans):.2f} s/frame", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tshirt-diffuse-video")
