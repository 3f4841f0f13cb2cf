"""Metrics of a reconstruction against ground truth.

Every distance is a fraction of the truth's bounding-box diagonal over all frames, so figures
are comparable across scenes and units.

Surface distances (accuracy, completeness, Chamfer)
    Both surfaces are sampled densely and uniformly by area (``samples`` points per surface and
    frame, seeded; a point-sequence truth without faces is subsampled to ``samples`` of its
    points). *Accuracy* is the distance from each result sample to the nearest truth sample
    (is the output where the truth is?), *completeness* from each truth sample to the nearest
    result sample (is the truth covered?). Means are over samples and frames (equal sample
    counts per frame); the 95th percentiles pool all frames. *Chamfer* is the mean of the two
    means. Sample-to-sample distances are biased upward by the sampling density; that bias is
    the *floor* (:func:`metric_floor`: the truth scored against itself with independent
    samples), reported beside every figure.

Correspondence (:class:`~fourd.AnimatedMesh` results only)
    Every output vertex at the first frame is bound to its exact nearest true surface point
    (triangle and barycentric coordinates; for a point truth, the nearest truth point). That
    material point's true trajectory is followed and compared with the output vertex in every
    frame: mean over vertices per frame (the curve), mean over all frames, first frame (the
    binding distance) and last frame (drift). The truth scored against itself binds exactly,
    so the correspondence floor is zero.

Temporal jitter
    RMS of the second differences ``x[t+1] - 2 x[t] + x[t-1]`` of the output trajectories
    divided by the same RMS of the bound true trajectories (frames assumed evenly spaced).
    About 1: as smooth as the truth; above 1: the output shakes; below 1: it smooths motion
    away. ``None`` for fewer than three frames or a truth that does not move.

Completeness split by ``observed``
    Truth samples are split by the ``observed`` flag of the output vertex nearest to the result
    sample that covers them: completeness over observed and over filled-in output regions.

Volume and topology
    Per frame: connected components, boundary loops, Euler characteristic, non-manifold edges,
    closed-and-manifold flag (no boundary and no non-manifold edge); the enclosed volume for
    closed, consistently oriented frames and the relative volume change ``(max - min) / mean``
    when every frame is closed (also for the truth).

Examples
--------
>>> import numpy as np, trimesh
>>> from fourd import AnimatedMesh
>>> sphere = trimesh.creation.icosphere(2)
>>> truth = AnimatedMesh(sphere.faces, np.stack([sphere.vertices + [0, 0, 0.1 * t] for t in range(4)]))
>>> report = evaluate(truth, truth, samples=5000)
>>> report["correspondence_mean"] < 1e-9
True
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.jsonable import jsonable
from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface
from fourd.metrics.topology import Topology, enclosed_volume, topology

log = logging.getLogger("fourd.metrics.scores")

#: Roles in the sampling seed, so result and truth samples are independent even for the same mesh.
_RESULT, _TRUTH = 0, 1


def _frame_count(value, name: str) -> int:
    if not isinstance(value, (AnimatedMesh, MeshSequence)):
        raise InputError(f"{name} must be an AnimatedMesh or a MeshSequence, got {type(value).__name__}")
    return value.frame_count


def _tree(points: np.ndarray) -> cKDTree:
    # Unbalanced trees build faster and answer far queries (a poor result) several times faster.
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _rng(seed: int, role: int, frame: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), role, frame])


def _summary(values) -> float | None:
    values = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else None


def _topologies(mesh) -> list[Topology]:
    if isinstance(mesh, AnimatedMesh):
        return [topology(mesh.faces, mesh.vertex_count)] * mesh.frame_count
    return [topology(faces, len(vertices)) for vertices, faces in mesh.meshes]


def _volumes(mesh, topologies: list[Topology]) -> list[float | None]:
    volumes = []
    for t, topo in enumerate(topologies):
        vertices, faces = mesh.frame(t)
        # a pinch (pieces touching at a vertex) still bounds a volume
        ok = topo.boundary_edges == 0 and topo.nonmanifold_edges == 0 and topo.oriented
        volumes.append(enclosed_volume(vertices, faces) if ok else None)
    return volumes


def _volume_change(volumes: list[float | None]) -> float | None:
    if len(volumes) < 2 or any(v is None for v in volumes):
        return None
    values = np.asarray(volumes, dtype=float)
    mean = values.mean()
    return float((values.max() - values.min()) / mean) if mean > 0 else None


def evaluate(result, truth, *, samples: int = 60000, seed: int = 0, timing: dict | None = None,
             folds: bool = False) -> dict:
    """Score ``result`` against ``truth``; see the module docstring for every metric.

    Parameters
    ----------
    result : AnimatedMesh or MeshSequence
        The reconstruction, one frame per truth frame.
    truth : AnimatedMesh or MeshSequence
        Ground truth; an :class:`AnimatedMesh` without faces is a point sequence.
    samples : int
        Surface samples per surface and frame.
    seed : int
        Sampling seed (result and truth samples are drawn from independent streams).
    timing : dict, optional
        Run measurements (e.g. ``seconds_per_frame``, ``peak_memory_mb``), passed through.
    folds : bool
        Also score the truth's folds (:func:`fourd.metrics.folds.fold_recall`: ``fold_recall``,
        ``fold_precision``, ``folds_truth``, ``folds_result``; per frame ``folds_truth`` and
        ``folds_found``); ``None`` without it or for a result without faces.

    Returns
    -------
    dict
        JSON-ready. Scalars: ``accuracy``, ``accuracy_95``, ``completeness``,
        ``completeness_95``, ``chamfer``, ``completeness_observed``, ``completeness_filled``,
        ``filled_fraction``, ``correspondence_mean``, ``correspondence_first``,
        ``correspondence_last``, ``jitter`` (with ``jitter_output``, ``jitter_truth``),
        ``volume_change``, ``truth_volume_change``, ``closed_manifold`` (fraction of frames),
        ``components_max``, ``boundary_loops_max``, ``nonmanifold_edges_max``,
        ``pinched_vertices_max``; ``None`` where a
        metric does not apply. ``per_frame``: lists of ``accuracy``, ``completeness``,
        ``chamfer``, ``correspondence``, ``volume``, ``truth_volume``, ``components``,
        ``boundary_loops``, ``euler``, ``nonmanifold_edges``, ``closed_manifold``. Plus
        ``frames``, ``diagonal`` (input units), ``samples``, ``seed``, ``result_kind``,
        ``timing``.

    Raises
    ------
    InputError
        Different frame counts, or a truth without extent.
    """
    frames = _frame_count(result, "result")
    if _frame_count(truth, "truth") != frames:
        raise InputError(f"the result has {frames} frames but the truth has {truth.frame_count}")
    samples = int(samples)
    if samples < 1:
        raise InputError(f"samples must be positive, got {samples}")
    diagonal = truth.diagonal()
    if not diagonal > 0:
        raise InputError("the truth has no extent (zero bounding-box diagonal)")

    accuracy, completeness, acc_95, comp_95 = [], [], [], []
    pooled_acc, pooled_comp, pooled_filled = [], [], []
    truth_first = None
    animated = isinstance(result, AnimatedMesh)
    for t in range(frames):
        rv, rf = result.frame(t)
        tv, tf = truth.frame(t)
        ts = sample_surface(tv, tf, samples, _rng(seed, _TRUTH, t))
        if t == 0:
            truth_first = ts
        if len(rv) == 0:  # an empty frame: nothing accurate, nothing covered
            accuracy.append(np.nan)
            acc_95.append(np.nan)
            comp = np.ones(len(ts.points))
            filled = np.ones(len(ts.points), dtype=bool)
        else:
            rs = sample_surface(rv, rf, samples, _rng(seed, _RESULT, t))
            acc = _tree(ts.points).query(rs.points, workers=-1)[0] / diagonal
            comp, nearest = _tree(rs.points).query(ts.points, workers=-1)
            comp = comp / diagonal
            accuracy.append(acc.mean())
            acc_95.append(np.percentile(acc, 95))
            pooled_acc.append(acc)
            if animated:
                filled = ~result.observed[t][rs.vertices[nearest]]
            else:
                filled = np.zeros(len(comp), dtype=bool)
        completeness.append(comp.mean())
        comp_95.append(np.percentile(comp, 95))
        pooled_comp.append(comp)
        pooled_filled.append(filled)

    pooled_comp = np.concatenate(pooled_comp)
    pooled_filled = np.concatenate(pooled_filled)
    acc_all = np.concatenate(pooled_acc) if pooled_acc else np.zeros(0)
    per_frame_chamfer = [(a + c) / 2 for a, c in zip(accuracy, completeness, strict=True)]
    report = {
        "frames": frames,
        "diagonal": diagonal,
        "samples": samples,
        "seed": seed,
        "result_kind": type(result).__name__,
        "accuracy": float(acc_all.mean()) if len(acc_all) else None,
        "accuracy_95": float(np.percentile(acc_all, 95)) if len(acc_all) else None,
        "completeness": float(pooled_comp.mean()),
        "completeness_95": float(np.percentile(pooled_comp, 95)),
        "completeness_observed": float(pooled_comp[~pooled_filled].mean()) if (~pooled_filled).any() else None,
        "completeness_filled": float(pooled_comp[pooled_filled].mean()) if pooled_filled.any() else None,
        "filled_fraction": float(pooled_filled.mean()),
    }
    report["chamfer"] = (
        (report["accuracy"] + report["completeness"]) / 2 if report["accuracy"] is not None else None
    )
    report.update(_correspondence(result, truth, truth_first, diagonal) if animated else _no_correspondence())

    topologies = _topologies(result)
    volumes = _volumes(result, topologies)
    truth_volumes = _volumes(truth, _topologies(truth))
    report.update(
        {
            "volume_change": _volume_change(volumes),
            "truth_volume_change": _volume_change(truth_volumes),
            # A point set (no faces in any frame) is neither closed nor open: not applicable.
            "closed_manifold": (
                float(np.mean([topo.closed_manifold for topo in topologies]))
                if any(len(result.frame(t)[1]) for t in range(frames))
                else None
            ),
            "components_max": max(topo.components for topo in topologies),
            "boundary_loops_max": max(topo.boundary_loops for topo in topologies),
            "nonmanifold_edges_max": max(topo.nonmanifold_edges for topo in topologies),
            "pinched_vertices_max": max(topo.pinched_vertices for topo in topologies),
        }
    )
    report.update(_folds(result, truth) if folds else _NO_FOLDS)
    fold_frames = {"folds_truth": report.pop("per_frame_folds_truth", None),
                   "folds_found": report.pop("per_frame_folds_found", None)}
    per_frame = report.pop("_per_frame_correspondence")
    report["per_frame"] = {
        "accuracy": accuracy,
        "accuracy_95": acc_95,
        "completeness": completeness,
        "completeness_95": comp_95,
        "chamfer": per_frame_chamfer,
        "correspondence": per_frame,
        "volume": volumes,
        "truth_volume": truth_volumes,
        "components": [topo.components for topo in topologies],
        "boundary_loops": [topo.boundary_loops for topo in topologies],
        "euler": [topo.euler for topo in topologies],
        "nonmanifold_edges": [topo.nonmanifold_edges for topo in topologies],
        "closed_manifold": [topo.closed_manifold for topo in topologies],
        **fold_frames,
    }
    report["timing"] = dict(timing) if timing is not None else None
    return jsonable(report)


_NO_FOLDS = {"fold_recall": None, "fold_precision": None, "folds_truth": None, "folds_result": None}


def _folds(result, truth) -> dict:
    from fourd.metrics.folds import fold_recall

    if not any(len(result.frame(t)[1]) for t in range(truth.frame_count)):
        return dict(_NO_FOLDS)
    return fold_recall(result, truth)


def _no_correspondence() -> dict:
    return {
        "correspondence_mean": None,
        "correspondence_first": None,
        "correspondence_last": None,
        "correspondence_slope": None,
        "jitter": None,
        "jitter_output": None,
        "jitter_truth": None,
        "_per_frame_correspondence": None,
    }


def _correspondence(result: AnimatedMesh, truth, truth_samples, diagonal: float) -> dict:
    """Bind output vertices at frame 0 to the truth, follow the bound points, compare."""
    if not isinstance(truth, AnimatedMesh):
        log.info("the truth has no fixed connectivity: correspondence is not measured")
        return _no_correspondence()
    binding = bind_to_surface(result.vertices[0], truth.vertices[0], truth.faces, truth_samples)
    followed = bound_positions(binding, truth.vertices, truth.faces)  # [T, N, 3]
    errors = np.linalg.norm(result.vertices - followed, axis=2) / diagonal  # [T, N]
    curve = errors.mean(axis=1)
    out = {
        "correspondence_mean": float(errors.mean()),
        "correspondence_first": float(curve[0]),
        "correspondence_last": float(curve[-1]),
        "correspondence_slope": correspondence_slope(curve),
        "_per_frame_correspondence": curve,
        "jitter": None,
        "jitter_output": None,
        "jitter_truth": None,
    }
    if len(curve) >= 3:
        jitter_output = _rms_second_difference(result.vertices) / diagonal
        jitter_truth = _rms_second_difference(followed) / diagonal
        out["jitter_output"] = jitter_output
        out["jitter_truth"] = jitter_truth
        if jitter_truth > 1e-9:
            out["jitter"] = jitter_output / jitter_truth
    return out


#: Frames at the start of a sequence left out of the correspondence slope (the error's first
#: rise from zero at the binding frame is not drift), when at least as many remain.
SLOPE_SKIP = 20


def correspondence_slope(curve) -> float | None:
    """The trend of a per-frame correspondence curve: its least-squares slope against the frame
    index, per 100 frames (diagonal fractions), over the frames after the first
    :data:`SLOPE_SKIP` when at least as many follow them, else over all; None for fewer than 3
    frames. Near zero: no drift; positive: the error grows (issue 56).

    >>> round(correspondence_slope([0.0, 0.01, 0.02, 0.03]), 6)
    1.0
    """
    curve = np.asarray(curve, dtype=np.float64)
    if len(curve) < 3:
        return None
    if len(curve) >= 2 * SLOPE_SKIP:
        frames, curve = np.arange(SLOPE_SKIP, len(curve)), curve[SLOPE_SKIP:]
    else:
        frames = np.arange(len(curve))
    return float(np.polyfit(frames, curve, 1)[0] * 100)


def _rms_second_difference(trajectories: np.ndarray) -> float:
    second = trajectories[2:] - 2.0 * trajectories[1:-1] + trajectories[:-2]
    return float(np.sqrt(np.mean(np.einsum("tnd,tnd->tn", second, second))))


def metric_floor(truth, *, samples: int = 60000, seed: int = 0) -> dict:
    """The truth scored against itself with independent samples: what a perfect result scores.

    The truth samples are the very ones :func:`evaluate` draws with the same ``seed``; the
    "result" samples come from an independent stream, so accuracy, completeness and Chamfer show
    the bias of sample-to-sample distances at this density. Correspondence binds exactly (0).
    """
    return evaluate(truth, truth, samples=samples, seed=seed)
