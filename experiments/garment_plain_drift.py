"""Question: where does `garment` lose correspondence on the plain-fabric T-shirt
(tshirt-diffuse-video: 0.0244 mean against 0.0055 on printed cloth), and can the geometry
alone (the openings' ellipses, more data weight, a better start per frame) get it back?

    python experiments/garment_plain_drift.py scan     # garment on the bench's scan, by region
    python experiments/garment_plain_drift.py truth    # the fit alone, chained over the true meshes
    LABEL=tshirt-wide-cloth-video python experiments/garment_plain_drift.py truth   # another scene
    PIN=all python experiments/garment_plain_drift.py truth   # ... its four hems pinned exactly
    python experiments/garment_plain_drift.py meshes   # garment from the photo, scan and true meshes
    START=truth | START=velocity, DATA_WEIGHT=4, ITERATIONS=30, SCHEDULE=0.01,0.5 (data weights
    of successive fits per frame), SLIDE=false (the closest points pulled as points, as before
    `FitOptions.slide`): other trials of `truth`

`scan` runs `garment` with the bench's options (scan cached in /tmp by
`experiments/garment_fit_data.py`'s helper), binds its vertices to the truth at frame 0 as the
metric does, and prints per frame the mean error and, per region (sleeves; torso bands by rest
height), the mean error and the median turn about the vertical (degrees, result minus truth).
`truth` fits the true frame 0 (as template) onto the true frames 1-7 in turn with
`fit.fit_template` and its defaults, each hem pulled onto the true hem (closest points), and
prints the error of the whole, of the torso's top band and of the sleeves' outer parts.

Answer (2-core machine, 2026-11-30, 20 frames; error in diagonals). Before (5d3933c: the fit
pulled each vertex to its closest frame point, each hem vertex to its closest hem point):
- `scan`: the error is a tangential slide, the fitted surface stays on the data (0.0014-0.0025
  from the true surface where the correspondence is off 0.05-0.065). At the twist's peak
  (frame 5) the torso's top band is 0.044 off and turned +14.9 degrees from the truth (the
  truth turned about 19 there: the fit follows a quarter of the twist), the band above the
  waist +1.3; the sleeves 0.061 (+7.4 degrees).
- `truth`: the same on clean meshes with exact hems, so it is not the scan: 0.0117 at frame 1,
  0.033 at frame 5 (top band 0.042, sleeves 0.066). Neck and waist pinned vertex by vertex
  (`PIN=neck-waist`): 0.033; all four hems pinned (`PIN=all`): 0.030. Four times the data
  weight and 30 iterations: 0.034; each frame started where the last two frames' motion
  carries it (`START=velocity`): 0.041; started from the true frame (`START=truth`): stays
  there (0.0002).
- So the truth is an equilibrium, and a much better one: its as-rigid-as-possible energy
  (from the first frame; printed per frame) is 0.009-0.236 over frames 1-5, the fit's own
  0.316-1.526. The fit did not find it because the closest points, pulled as points, hold
  every vertex where it entered the frame: tangential motion costs data energy in every
  global step. A lower data weight in a first fit (`SCHEDULE=0.01,0.5`): 0.021 at frame 5.
- The data held only across the surface (point to plane) and each hem vertex only across the
  hem (point to line), so both slide (now `FitOptions.slide`, on): `truth` 0.0043 at frame 5
  (top band 0.0079, sleeves 0.0069), its energy now below the truth's (0.179 against 0.236:
  what is left is the rigidity's own preference, the truth's shoulders are skinned, not
  as-rigid-as-possible); with the hems pinned exactly (`PIN=all`) 0.0038. `scan` after it:
  0.0148 at frame 5 (top band 0.019, +5.6 degrees; sleeves 0.027, +1.5). Harness
  (`garment_fit_data.py`, 20k samples): 0.0244 / 0.0135 -> 0.0133 / 0.0128, Chamfer 0.0036 ->
  0.0034; printed cloth 0.0058 / 0.0074 -> 0.0056 / 0.0068. Bench: benchmarks/METHODS.md.
- Tried and not kept: each template vertex of an eccentric hem that keeps its size (radii 10%
  apart and within 10% of the first frame's in every frame: the waist; the neck's first loop
  has the occlusion hole behind it run into it, its ellipse 0.305 x 0.051 for the truth's 0.13
  x 0.10, drifting to 0.21 x 0.11) pulled to its first-frame angle on the tracked ellipse. The
  waist's band halved (0.0157 -> 0.0072 at frame 14), but the whole was mixed: plain T-shirt
  0.0133 / 0.0128 -> 0.0124 / 0.0141, the dress (bench) 0.0036 / 0.0039 -> 0.0038 / 0.0047 (its
  hem's flutes travel round it, so its ellipse turns without the fabric).
- `LABEL=tshirt-wide-cloth-video ... truth` (2026-11-30, the held-out T-shirt: arms swinging 50
  degrees): on the true meshes with exact hems the sliding fit ends 0.0123 off at frame 5
  (sleeve ends 0.0304; 0.0043 and 0.0069 at the standard swing), and at frame 2 its
  as-rigid-as-possible energy is 0.181 against the truth's 0.070: not the prior's preference
  but a worse equilibrium, reached from where the last frame left the template. 30 iterations:
  0.0080 (sleeve ends 0.0178); a low data weight first (`SCHEDULE=0.05,0.5`): 0.0112; started
  where the last step's motion carries it (`START=velocity`): **0.0066, sleeve ends 0.0075**
  (standard swing: 0.0039, 0.0031). Hence `garment.Options.motion_prediction`.
- `meshes` (2026-11-30, the photo's template, the defaults; 20k samples): on the scan 0.0112 /
  0.0063; on the true meshes themselves, given as per-frame meshes (no noise, no holes, exact
  hems, no video) **0.0088 / 0.0021**, the error rising and falling with the twist (0.0128 at
  frame 6, 0.0163 at frame 15, 0.0009 at frame 10 where the body faces forward again). So the
  scan costs a fifth of the plain T-shirt's error; the rest is the fit's equilibrium on a
  twisting, untextured surface, which perfect geometry does not fix. Tried and not kept: the
  first frame's fit as the rigidity's reference for the later frames (instead of the photo's
  inflated shape): true meshes 0.0069 / 0.0036, scan 0.0102 / 0.0069, printed cloth 0.0035 /
  0.0036 -> 0.0036 / 0.0037; still over the target, and the last frame worse.
"""

from __future__ import annotations

import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from fourd.appearance.guide import Guide
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.laplacian import cotangent_weights
from fourd.geometry.rotations import one_ring_rotations
from fourd.methods import garment
from fourd.methods.garment.fit import FitOptions, fit_template
from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from garment_fit_data import BOUNDARIES, _scene  # noqa: E402

LABEL = os.environ.get("LABEL", "tshirt-diffuse-video")


def scan() -> None:
    scene, truth, scans = _scene(LABEL)
    result = garment.reconstruct(scans, garment.Options(boundaries=BOUNDARIES[scene.name]))
    diagonal = float(np.linalg.norm(np.ptp(truth.vertices.reshape(-1, 3), axis=0)))
    samples = sample_surface(truth.vertices[0], truth.faces, 20000, np.random.default_rng(0))
    binding = bind_to_surface(result.vertices[0], truth.vertices[0], truth.faces, samples)
    followed = bound_positions(binding, truth.vertices, truth.faces)
    rest = bound_positions(binding, truth.rest[None], truth.faces)[0]
    errors = np.linalg.norm(result.vertices - followed, axis=2) / diagonal
    sleeve = np.abs(rest[:, 0]) > 0.33
    bands = {"sleeves": sleeve}
    edges = np.linspace(-0.55, 0.35, 6)
    for low, high in zip(edges[:-1], edges[1:], strict=True):
        bands[f"torso y {low:+.2f}..{high:+.2f}"] = ~sleeve & (rest[:, 1] >= low) & (rest[:, 1] < high)
    print(f"{'frame':>5} {'mean':>7} " + " ".join(f"{name:>22}" for name in bands))
    for t in range(len(result.vertices)):
        row = [f"{t:5d} {errors[t].mean():7.4f}"]
        for mask in bands.values():
            r, f = result.vertices[t, mask], followed[t, mask]
            centre = f.mean(axis=0)
            turn = np.degrees(np.angle(np.exp(1j * (np.arctan2(r[:, 2] - centre[2], r[:, 0] - centre[0])
                                                    - np.arctan2(f[:, 2] - centre[2], f[:, 0] - centre[0])))))
            row.append(f"{errors[t, mask].mean():.4f} {np.median(turn):+6.2f}deg".rjust(22))
        print(" ".join(row), flush=True)


def meshes() -> None:
    """`garment` with the scene's photo on its scan and on its true meshes given as per-frame
    meshes (noise-free, complete, exact hems; no video)."""
    import tempfile

    from fourd.metrics import evaluate
    from fourd.sequence import Frame, PointCloudSequence
    from fourd.synth.garments import pattern_outline
    from fourd.synth.write import write_pattern_photo

    scene, truth, scans = _scene(LABEL)
    folder = Path(tempfile.mkdtemp())
    photo = write_pattern_photo(pattern_outline(scene.name, with_openings=True), folder)
    true_meshes = PointCloudSequence([Frame(truth.vertices[t], time=float(t), faces=truth.faces)
                                      for t in range(len(truth.vertices))])
    for name, seq in (("scan", scans), ("true meshes", true_meshes)):
        result = garment.reconstruct(seq, garment.Options(boundaries=BOUNDARIES[scene.name], photo=str(photo)))
        r = evaluate(result, truth, samples=20000, seed=0)
        print(f"{LABEL}, photo's template, {name}: correspondence {r['correspondence_mean']:.4f} / "
              f"{r['correspondence_last']:.4f}, per frame "
              f"{' '.join(f'{e:.4f}' for e in r['per_frame']['correspondence'])}", flush=True)


def truth_fit() -> None:
    _, truth, _ = _scene(LABEL)
    diagonal = float(np.linalg.norm(np.ptp(truth.vertices.reshape(-1, 3), axis=0)))
    rest, faces = truth.vertices[0], truth.faces
    loops = boundary_loops(faces, len(rest))
    pin = os.environ.get("PIN", "")  # "": none, "neck-waist", "all"
    start = os.environ.get("START", "last")  # last | velocity | truth
    options = FitOptions(data_weight=float(os.environ.get("DATA_WEIGHT", 0.5)),
                         iterations=int(os.environ.get("ITERATIONS", 10)),
                         slide=os.environ.get("SLIDE", "true") == "true")
    schedule = [float(w) for w in os.environ.get("SCHEDULE", str(options.data_weight)).split(",")]
    weights = cotangent_weights(rest, faces, clamp_negative=True)
    top = (rest[:, 1] > 0.17) & (np.abs(rest[:, 0]) <= 0.42)
    sleeve_ends = np.abs(rest[:, 0]) > 0.42
    current = previous = rest.copy()
    for t in range(1, 8):
        target = truth.vertices[t]
        pinned = [loop for loop in loops if pin == "all" or (pin == "neck-waist" and abs(rest[loop, 1].mean()) > 0.2)]
        pulled = [(loop, target[loop]) for loop in loops if not any(loop is p for p in pinned)]
        guide = None
        if pinned:  # vertex by vertex, as strongly as a hem (anchor weight 2 times 2 = boundary weight 4)
            vertices = np.concatenate(pinned)
            guide = Guide(vertices, target[vertices], np.full(len(vertices), options.boundary_weight / options.anchor_weight))
        begin = {"last": current, "velocity": 2 * current - previous, "truth": target}[start]
        previous = current
        current = begin
        for data_weight in schedule:
            current = fit_template(rest, faces, current, target, faces, openings=pulled, guide=guide,
                                   options=replace(options, data_weight=data_weight))
        error = np.linalg.norm(current - target, axis=1) / diagonal
        print(f"frame {t}: mean {error.mean():.4f}, torso top {error[top].mean():.4f}, "
              f"sleeve ends {error[sleeve_ends].mean():.4f}; as-rigid-as-possible energy: fit "
              f"{_arap_energy(weights, rest, current):.3f}, truth {_arap_energy(weights, rest, target):.3f}", flush=True)


def _arap_energy(weights, rest: np.ndarray, deformed: np.ndarray) -> float:
    """``sum_ij w_ij |(x_i - x_j) - R_i (r_i - r_j)|^2`` over both directions of every edge,
    ``R_i`` each one-ring's best rotation."""
    rotations = one_ring_rotations(weights, rest, deformed)
    pairs = sp.triu(weights, k=1).tocoo()
    total = 0.0
    for i, j in ((pairs.row, pairs.col), (pairs.col, pairs.row)):
        residual = deformed[i] - deformed[j] - np.einsum("nab,nb->na", rotations[i], rest[i] - rest[j])
        total += float((pairs.data * (residual**2).sum(axis=1)).sum())
    return total


if __name__ == "__main__":
    {"scan": scan, "truth": truth_fit, "meshes": meshes}[sys.argv[1] if len(sys.argv) > 1 else "scan"]()
