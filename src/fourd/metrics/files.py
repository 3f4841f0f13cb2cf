"""Metrics of saved files: a result and a ground truth read from disk (``fourd evaluate``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.metrics.match import check_truth
from fourd.metrics.scores import evaluate, metric_floor


def load_truth(path: str | os.PathLike):
    """Read a ground truth: a result-style ``.npz`` (``vertices``, ``faces``), a point sequence
    ``.npz`` (``points [T, P, 3]``, as in ``../shared/data``; ``loc`` and ``scale`` applied
    when present), a folder written by ``fourd synth`` (its ``truth.npz``), or anything
    :func:`fourd.load_result` reads."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file or folder", path)
    if path.is_dir():
        for name in ("truth.npz", "truth"):
            if (path / name).exists():
                return load_truth(path / name)
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                keys = set(data.files)
                if "vertices" in keys and "faces" in keys:
                    vertices = data["vertices"].astype(np.float64)
                    faces = data["faces"]
                    times = data["times"] if "times" in keys else None
                    if vertices.ndim == 3:
                        return AnimatedMesh(faces, vertices, times)
                if "points" in keys and "faces" not in keys:
                    points = data["points"].astype(np.float64)
                    if points.ndim == 3:
                        if "scale" in keys and "loc" in keys:
                            points = points * data["scale"].astype(np.float64) + data["loc"].astype(np.float64)
                        times = data["times"] if "times" in keys else None
                        return AnimatedMesh(np.zeros((0, 3), dtype=np.int64), points, times)
        except (OSError, ValueError) as error:
            raise InputError(f"cannot read ({error})", path) from None
        except InputError as error:
            raise InputError(error.problem, path) from None
    return _load_result(path)


def _load_result(path: Path):
    from fourd.io.results import load_result

    return load_result(path)


def evaluate_files(
    result_path: str | os.PathLike,
    truth_path: str | os.PathLike,
    *,
    samples: int = 60000,
    seed: int = 0,
    floor: bool = True,
    force: bool = False,
    folds: bool = False,
) -> dict:
    """:func:`evaluate` a saved result against a saved truth (see :func:`load_truth`); with
    ``floor`` the truth's :func:`metric_floor` is added under ``"floor"``.

    A truth with another frame count or a bounding box unlike the result's is refused
    (InputError naming both files, :func:`~fourd.metrics.match.check_truth`); ``force``
    scores it anyway (frames matched by time where the counts differ). ``folds`` also scores
    the truth's folds (:func:`fourd.metrics.folds.fold_recall`)."""
    result = _load_result(Path(result_path)) if Path(result_path).exists() else None
    if result is None:
        raise InputError("no such file or folder", result_path)
    truth = load_truth(truth_path)
    truth = check_truth(result, truth, result_path, truth_path, force=force)
    report = evaluate(result, truth, samples=samples, seed=seed, folds=folds)
    report["result_path"] = os.fspath(result_path)
    report["truth_path"] = os.fspath(truth_path)
    if floor:
        report["floor"] = metric_floor(truth, samples=samples, seed=seed)
    return report
