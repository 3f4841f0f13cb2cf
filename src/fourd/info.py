"""``fourd info``: a short description of an input folder or a result file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence


def _is_result(path: Path) -> bool:
    if path.suffix.lower() == ".abc":
        return True
    if path.suffix == ".npz":
        try:
            with np.load(path) as data:
                return "faces" in data.files or data.get("kind", None) is not None
        except (OSError, ValueError):
            raise InputError("cannot read this .npz file", path) from None
    return False


def describe_sequence(seq: PointCloudSequence) -> str:
    counts = np.array([len(f) for f in seq])
    lo, hi = seq.bounds()
    lines = [
        f"point cloud sequence: {len(seq)} frames, times {seq.times[0]:g} .. {seq.times[-1]:g}",
        f"points per frame: min {counts.min()}, median {int(np.median(counts))}, max {counts.max()}",
        f"bounds: {np.round(lo, 4).tolist()} .. {np.round(hi, 4).tolist()} (diagonal {seq.diagonal():.4g})",
        f"normals: {'yes' if all(f.normals is not None for f in seq) else 'no'}; "
        f"sensors: {'yes' if seq.has_sensors else 'no'}",
    ]
    return "\n".join(lines)


def describe_result(result) -> str:
    if isinstance(result, AnimatedMesh):
        filled = 1.0 - result.observed.mean()
        return "\n".join([
            f"animated mesh: {result.frame_count} frames, {result.vertex_count} vertices, "
            f"{len(result.faces)} faces (one connectivity)",
            f"times {result.times[0]:g} .. {result.times[-1]:g}; filled-in vertex-frames {filled:.1%}; "
            f"rest pose {'yes' if result.rest is not None else 'no'}; "
            f"UVs {'yes' if result.uv is not None else 'no'}; "
            f"vertex colours {'yes' if result.colors is not None else 'no'}",
            f"bounds diagonal {result.diagonal():.4g}",
        ])
    if isinstance(result, MeshSequence):
        counts = np.array([len(f) for _, f in result.meshes])
        return (f"mesh sequence: {result.frame_count} frames (per-frame connectivity), "
                f"faces per frame {counts.min()} .. {counts.max()}")
    raise InputError(f"not a result: {type(result).__name__}")


def describe(path) -> str:
    """Describe ``path``: a result (.npz with faces, an Alembic .abc) or an input sequence."""
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    if _is_result(path):
        from fourd.io.results import load_result

        return f"{path}\n" + describe_result(load_result(path))
    from fourd.io.frames import load_sequence

    return f"{path}\n" + describe_sequence(load_sequence(path))
