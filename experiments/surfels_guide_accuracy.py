"""Question: `surfels` with the colours' guide still drifts on bending-arm-cloth-video (per
frame 0.0023 -> 0.0053 of the diagonal), where `kinematic` with its guide holds 0.0019 / 0.0028.
Are the guides themselves off (the Lucas-Kanade's targets drift), or are good guides not
followed (weight, truncation, the other terms)?

    PYTHONPATH=src python experiments/surfels_guide_accuracy.py [SCENE FRAMES RESOLUTION USE]

Runs `surfels` (default options) on the scene in cloth with the rig's video (defaults:
bending-arm 20 frames at 128 rays, the first 10 used), records every call of the guides over the
whole sequence (the final optimisation's rounds), and prints per frame, for the last such call:
the surfels' error against the truth (each surfel bound to the truth at frame 0, as
`fourd.metrics.scores` binds the vertices), the guides' targets' error, the share of surfels
with a guide and the mean certainty; then the same for the final model's surfels. All in
fractions of the diagonal (medians; the certainty-weighted mean for the targets). Then the
Lucas-Kanade's own floor: its targets started at the truth's positions and at the surfels', for
larger patches, more steps and denser patches.

Answer (the defaults; benchmarks/METHODS.md, "How near the guides are to the truth"): the
guides' targets are no nearer the truth than the surfels (final round, frame 9: surfels 0.0053,
tangential 0.0036; targets 0.0051, 0.0035), so the surfels follow their guides and the guides
are the limit. Started at the truth the Lucas-Kanade stays within 0.0015-0.0023 (0.0006-0.0009
with 192-surfel patches); started at the surfels its targets in the late frames stay at the
surfels' drift (0.0030-0.0033) whatever the patch or the number of steps. The drift is mostly
shared by a patch (frame 9: 0.0030 of 0.0036), and even that one shift is taken back only 0.66-0.81
from the truth. A colour field continuous across its points (4 fits blended) brings the targets
a little nearer (frame 9: 0.0032 -> 0.0028).
"""

import os
import pickle
import sys

import numpy as np
from scipy.spatial import cKDTree

import fourd
from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import ColorField
from fourd.bench.suite import PROTOCOL
from fourd.methods.surfels import Options, assembly, pipeline, reconstruct
from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface
from fourd.metrics.scores import _TRUTH, _rng, evaluate


def cloth_video_scene(scene: str, frames: int, resolution: int, use: int):
    """The truth and the scans of the first ``use`` of the scene's ``frames`` frames, scanned
    as the bench does at ``resolution`` rays per side, in printed cloth with the rig's video."""
    truth = fourd.synth.scene(scene, frames=frames)
    scans = fourd.synth.scan(
        truth, **{**PROTOCOL, "resolution": resolution, "appearance": "cloth", "video": True}
    )
    truth = fourd.AnimatedMesh(truth.faces, truth.vertices[:use], truth.times[:use])
    scans = fourd.PointCloudSequence(
        scans.frames[:use], scans.names[:use], scans.video.select(slice(0, use))
    )
    return truth, scans


def print_scores(name: str, result, truth, seconds: float) -> None:
    """Chamfer / completeness-95 / correspondence mean / last of ``result`` against ``truth``
    (`fourd.metrics.evaluate`, 20k samples), s/frame, and the per-frame correspondence."""
    report = evaluate(result, truth, samples=20000)
    print(
        f"{name}: {report['chamfer']:.4f} / {report['completeness_95']:.4f} / "
        f"{report['correspondence_mean']:.4f} / {report['correspondence_last']:.4f}, "
        f"{seconds:.2f} s/frame",
        flush=True,
    )
    print("  " + " ".join(f"{v:.4f}" for v in report["per_frame"]["correspondence"]), flush=True)


def main(scene: str, frames: int, resolution: int, use: int) -> None:
    truth, scans = cloth_video_scene(scene, frames, resolution, use)
    calls, kept = [], {}
    guides_of = assembly.color_guides

    def record(state, observed, *args):
        guides = guides_of(state, observed, *args)
        if state.frames == use:
            calls.append((state, observed, guides))
            kept["args"] = args
        return guides

    mesh_of = pipeline.surfel_mesh

    def keep(state, sampling, **kwargs):
        kept["state"] = state
        return mesh_of(state, sampling, **kwargs)

    assembly.color_guides, pipeline.surfel_mesh = record, keep
    reconstruct(scans, Options())
    assembly.color_guides, pipeline.surfel_mesh = guides_of, mesh_of

    diagonal = truth.diagonal()
    samples = sample_surface(*truth.frame(0), 60000, _rng(0, _TRUTH, 0))

    def followed(state):
        binding = bind_to_surface(state.positions[0], truth.vertices[0], truth.faces, samples)
        return bound_positions(binding, truth.vertices, truth.faces)  # [T, S, 3]

    print(f"{len(calls)} calls of the guides over all {use} frames")
    for k, (state, observed, guides) in enumerate(calls):
        where = followed(state)
        first = np.argmax(observed, axis=0)
        print(f"call {k}: {state.count} surfels, first observed later than frame 0: "
              f"{np.mean(first > 0):.3f}")
        print("  frame  surfels (tangential)  targets, weighted (tangential)  guided  certainty  gain")
        for t in range(use):
            normal = state.normals[t]
            needed = where[t] - state.positions[t]
            along = needed - np.sum(needed * normal, axis=1, keepdims=True) * normal
            line = (f"  {t:5d}  {np.median(np.linalg.norm(needed, axis=1)) / diagonal:.4f}"
                    f" ({np.median(np.linalg.norm(along, axis=1)) / diagonal:.4f})")
            mine = guides.frames == t
            if mine.any():
                s, w = guides.surfels[mine], guides.weights[mine]
                off = guides.targets[mine] - where[t, s]
                off_along = off - np.sum(off * normal[s], axis=1, keepdims=True) * normal[s]
                shift = guides.targets[mine] - state.positions[t, s]
                gain = np.sum(shift * along[s]) / np.sum(along[s] ** 2)
                line += (f"   {np.sum(w * np.linalg.norm(off, axis=1)) / w.sum() / diagonal:.4f}"
                         f" ({np.sum(w * np.linalg.norm(off_along, axis=1)) / w.sum() / diagonal:.4f})"
                         f"                  {len(s) / state.count:.2f}    {w.mean():.2f}"
                         f"      {gain:.2f}")
            print(line, flush=True)
    state = kept["state"]
    where = followed(state)
    error = np.linalg.norm(state.positions - where, axis=2) / diagonal
    print("final surfels, median per frame: " + " ".join(f"{v:.4f}" for v in np.median(error, 1)))
    print("final surfels, mean per frame:   " + " ".join(f"{v:.4f}" for v in error.mean(1)))
    state, observed, _ = calls[-1]
    if os.environ.get("DUMP"):  # the recorded run, for analyses of one's own
        with open(os.environ["DUMP"], "wb") as file:
            pickle.dump(dict(truth=truth, state=state, observed=observed, args=kept["args"]), file)
    lucas_kanade_floor(truth, samples, state, observed, kept["args"], followed(state), diagonal)


class BlendedField(ColorField):
    """The colour field continuous across its points: the linear fits of the 4 nearest points
    blended by Gaussian weights, instead of the nearest point's fit alone."""

    def sample(self, positions, *, with_gradients=False):
        flat = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        distance, near = self.tree.query(flat, k=4, workers=-1)
        self.fit(near.ravel())
        weight = np.exp(-((distance / np.median(distance[:, -1])) ** 2))
        weight /= weight.sum(axis=1, keepdims=True)
        gradients = self.gradients[near]  # [Q, 4, C, 3]
        values = self.values[near] + np.einsum(
            "qkcd,qkd->qkc", gradients, flat[:, None, :] - self.points[near]
        )
        values = np.einsum("qk,qkc->qc", weight, values)
        if not with_gradients:
            return values
        noise = np.einsum("qk,qkc->qc", weight, self.gradient_noise[near])
        return values, np.einsum("qk,qkcd->qcd", weight, gradients), noise


def lucas_kanade_floor(truth, samples, state, observed, args, where, diagonal) -> None:
    """The Lucas-Kanade's targets of the last call's surfels (those first observed in frame
    0) against the truth, per frame 1..: started at the truth's positions (its own floor) and
    at the surfels', for patch sizes, steps and densities; certainty-weighted means of the
    tangential error, fractions of the diagonal."""
    points, normals, colors, settings = args
    fields = [ColorField(p, n, c) for p, n, c in zip(points, normals, colors, strict=True)]
    first = np.argmax(observed, axis=0) == 0

    def targets(start, neighbours=24, radius=1.0, iterations=3, truth_at=where, at=first):
        """``start``'s targets against ``truth_at`` (positions [T, N, 3] both)."""
        reference = fields[0].sample(start[0])
        out = []
        for t in range(1, state.frames):
            normal = cKDTree(points[t]).query(start[t])[1]
            shift = photometric_shift(
                start[t], normals[t][normal], reference, fields[t], neighbours=neighbours,
                radius=radius * settings.radius, iterations=iterations,
            )
            ok = np.isfinite(shift.uncertainty) & at
            weight = np.exp(-((shift.uncertainty[ok] / settings.scale) ** 2))
            off = start[t][ok] + shift.shift[ok] - truth_at[t][ok]
            n = normals[t][normal][ok]
            off -= np.sum(off * n, axis=1, keepdims=True) * n
            out.append(np.sum(weight * np.linalg.norm(off, axis=1)) / weight.sum() / diagonal)
        return " ".join(f"{v:.4f}" for v in out)

    for neighbours, radius in ((24, 1.0), (48, 1.5), (96, 2.0), (192, 3.0)):
        print(f"{neighbours} neighbours within {radius} x color_radius: from the truth "
              f"{targets(where, neighbours, radius)}", flush=True)
        print(f"   from the surfels {targets(state.positions, neighbours, radius)}", flush=True)
    for iterations in (6, 12):
        print(f"{iterations} steps, from the surfels {targets(state.positions, iterations=iterations)}")
    for factor in (4, 16):
        dense = sample_surface(*truth.frame(0), factor * state.count, np.random.default_rng(1))
        binding = bind_to_surface(dense.points, truth.vertices[0], truth.faces, samples)
        moved = bound_positions(binding, truth.vertices, truth.faces)
        print(f"patches {factor} times as dense, from the truth: "
              f"{targets(moved, truth_at=moved, at=np.ones(moved.shape[1], dtype=bool))}",
              flush=True)
    for t in (3, 6, state.frames - 1):
        # each surfel's tangential error, and its mean over its Lucas-Kanade patch
        normal = state.normals[t]
        error = state.positions[t] - where[t]
        error -= np.sum(error * normal, axis=1, keepdims=True) * normal
        distance, patch = cKDTree(state.positions[t]).query(
            state.positions[t], k=24, distance_upper_bound=settings.radius
        )
        weight = np.where(np.isfinite(distance), np.exp(-((distance / (0.5 * settings.radius)) ** 2)), 0)
        shared = np.einsum("sk,skd->sd", weight, error[np.where(weight > 0, patch, 0)])
        shared /= weight.sum(axis=1)[:, None]
        # the truth moved by the patch's mean error only: one shift per patch, which the
        # Lucas-Kanade models exactly
        start = where[t] + shared
        shift = photometric_shift(
            start, normal, fields[0].sample(where[0]), fields[t], radius=settings.radius
        ).shift
        gain = np.sum(-shift[first] * shared[first]) / np.sum(shared[first] ** 2)
        print(f"frame {t}: surfels' error {np.median(np.linalg.norm(error[first], axis=1)) / diagonal:.4f}"
              f", its patch's mean {np.median(np.linalg.norm(shared[first], axis=1)) / diagonal:.4f}"
              f", the rest {np.median(np.linalg.norm((error - shared)[first], axis=1)) / diagonal:.4f};"
              f" from the truth moved by the patch's mean the shift takes back {gain:.2f} of it")
    blended = [BlendedField(p, n, c) for p, n, c in zip(points, normals, colors, strict=True)]
    for name, kind in (("nearest point's fit (the project's)", fields), ("4 fits blended", blended)):
        for t in (3, state.frames - 1):
            shift = photometric_shift(
                state.positions[t], state.normals[t], kind[0].sample(where[0]), kind[t],
                radius=settings.radius,
            )
            ok = np.isfinite(shift.uncertainty) & first
            weight = np.exp(-((shift.uncertainty[ok] / settings.scale) ** 2))
            off = state.positions[t][ok] + shift.shift[ok] - where[t][ok]
            n = state.normals[t][ok]
            off -= np.sum(off * n, axis=1, keepdims=True) * n
            error = np.sum(weight * np.linalg.norm(off, axis=1)) / weight.sum() / diagonal
            print(f"colour field {name}, frame {t}, from the surfels: {error:.4f}, "
                  f"{np.mean(weight > 1e-3):.2f} guided", flush=True)
    shift = photometric_shift(
        where[-1], state.normals[-1], fields[0].sample(where[0]), fields[-1], radius=settings.radius
    )
    near = cKDTree(where[0]).query_ball_point(where[0], settings.radius)
    shared = np.array([shift.shift[n].mean(axis=0) for n in near])
    print(f"last frame, from the truth: |shift| median {np.median(np.linalg.norm(shift.shift, axis=1)) / diagonal:.4f}"
          f", its patch's mean {np.median(np.linalg.norm(shared, axis=1)) / diagonal:.4f}")


if __name__ == "__main__":
    args = sys.argv[1:] or ["bending-arm", "20", "128", "10"]
    main(args[0], int(args[1]), int(args[2]), int(args[3]))
