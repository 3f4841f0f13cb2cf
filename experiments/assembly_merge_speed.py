"""Question: how long does one `assembly` merge take on a full-size frame, and how good is its
map? (Run it at two commits to compare them, as for the speed-up in METHODS.md.)

Setup: crane frames 0 and 2, each remeshed on its own at 256 rays (``synth.scan(...,
mode="remeshed")``, about 34,000 vertices per frame), reconstructed by ``assembly`` (one
merge); the second frame's correspondence error against the truth (the output vertices bound
to the truth's first frame and followed along the true motion), fractions of the diagonal.

Run: ``.venv/bin/python experiments/assembly_merge_speed.py [RESOLUTION]``

Answer (loaded 2-core machine, 2026-11-27): before the speed-ups (02648a0) 197.7 s, mean
0.00173, 95th percentile 0.00291, largest 0.0140; after (patches near their centre, shorter
geodesic searches, the shared point-to-plane ICP) 70.6 s, 0.00152 / 0.00260 / 0.0097.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fourd import synth
from fourd.methods import reconstruct
from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface


def main() -> None:
    resolution = int(sys.argv[1]) if len(sys.argv) > 1 else 256
    truth = synth.scene("crane", frames=2, start=0, step=2)
    scans = synth.scan(truth, resolution=resolution, seed=0, mode="remeshed")
    started = time.perf_counter()
    result = reconstruct(scans, "assembly")
    seconds = time.perf_counter() - started
    samples = sample_surface(truth.vertices[0], truth.faces, 60000, np.random.default_rng(0))
    binding = bind_to_surface(result.vertices[0], truth.vertices[0], truth.faces, samples)
    followed = bound_positions(binding, truth.vertices, truth.faces)
    error = np.linalg.norm(result.vertices[1] - followed[1], axis=1) / truth.diagonal()
    print(f"{len(result.vertices[0])} vertices, one merge {seconds:.1f} s; correspondence mean "
          f"{error.mean():.5f}, 95th percentile {np.percentile(error, 95):.5f}, largest {error.max():.4f}")


if __name__ == "__main__":
    main()
