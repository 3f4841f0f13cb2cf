"""``fourd info``: a short description of an input folder or a result, in any format fourd
writes (``.npz``, ``.glb``, USD, ``.pc2`` with its ``.obj``, a folder of per-frame meshes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence

#: Result kind (:func:`fourd.io.results.result_kind`) -> how ``fourd info`` names the format.
FORMAT_NAMES = {
    "npz": "fourd .npz",
    "glb": "glTF binary (.glb)",
    "usd": "USD stage",
    "pc2": "point cache (.pc2 with its .obj)",
    "abc": "Alembic archive (.abc)",
    "folder": "folder of per-frame meshes",
}

#: Files a folder result holds besides its meshes (:mod:`fourd.io.meshfolder`).
_FOLDER_SIDECARS = ("times.txt", "observed.npy")


def _is_result_npz(path: Path) -> bool:
    try:
        with np.load(path) as data:
            return "faces" in data.files or "kind" in data.files
    except (OSError, ValueError):
        raise InputError("cannot read this .npz file", path) from None


def _is_result_folder(path: Path) -> bool:
    """A folder written by :func:`fourd.save`: it has ``observed.npy``, or it holds only
    ``.obj``/``.ply`` meshes (with faces) and ``times.txt``. A scan folder (points, or meshes
    beside ``sensors.json``, a truth, ...) is an input."""
    if (path / "observed.npy").is_file():
        return True
    files = [p for p in path.iterdir() if p.is_file() and not p.name.startswith(".")]
    meshes = sorted(p for p in files if p.suffix.lower() in (".obj", ".ply"))
    if not meshes or any(p not in meshes and p.name not in _FOLDER_SIDECARS for p in files):
        return False
    from fourd.io.meshfiles import read_obj
    from fourd.io.ply import read_ply

    first = meshes[0]
    mesh = read_obj(first) if first.suffix.lower() == ".obj" else read_ply(first)
    return mesh.faces is not None and len(mesh.faces) > 0


def is_result(path) -> bool:
    """Whether ``path`` (which exists) is a result rather than an input sequence."""
    from fourd.io.results import RESULT_SUFFIXES

    path = Path(path)
    if path.is_dir():
        return _is_result_folder(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return _is_result_npz(path)
    return suffix in RESULT_SUFFIXES


def describe_sequence(seq: PointCloudSequence) -> str:
    counts = np.array([len(f) for f in seq])
    lo, hi = seq.bounds()
    lines = [
        f"point cloud sequence: {len(seq)} frames, times {seq.times[0]:g} .. {seq.times[-1]:g}",
        f"points per frame: min {counts.min()}, median {int(np.median(counts))}, max {counts.max()}",
        f"bounds: {np.round(lo, 4).tolist()} .. {np.round(hi, 4).tolist()} (diagonal {seq.diagonal():.4g})",
        f"normals: {'yes' if all(f.normals is not None for f in seq) else 'no'}; "
        f"colours: {'yes' if all(f.colors is not None for f in seq) else 'no'}; "
        f"sensors: {'yes' if seq.has_sensors else 'no'}",
    ]
    meshes = [len(f.faces) for f in seq if f.faces is not None]
    if meshes:
        lines.append(f"per-frame meshes: {len(meshes)} of {len(seq)} frames have faces "
                     f"(median {int(np.median(meshes))} triangles)")
    if seq.video is not None:
        sizes = sorted({f"{c.width}x{c.height}" for c in seq.video.cameras})
        lines.append(
            f"video: {len(seq.video.cameras)} cameras ({', '.join(seq.video.names)}), "
            f"images {', '.join(sizes)}"
        )
    return "\n".join(lines)


def _range(values) -> str:
    lo, hi = int(np.min(values)), int(np.max(values))
    return f"{lo}" if lo == hi else f"{lo} .. {hi}"


def describe_surface(faces: np.ndarray, vertex_count: int) -> str:
    """One mesh's topology in a few words: closed and manifold with its pieces and genus (the
    sum over its pieces), or what keeps it from that: its boundary loops, the sides shared by
    more than two faces and the pinched vertices."""
    from fourd.metrics.topology import topology

    found = topology(faces, vertex_count)
    pieces = f"{found.components} piece{'' if found.components == 1 else 's'}"
    if found.closed_manifold:
        oriented = "" if found.oriented else " (faces not turned consistently)"
        return f"closed and manifold{oriented}, {pieces}, genus {(2 * found.components - found.euler) // 2}"
    problems = []
    if found.boundary_loops:
        problems.append(f"{found.boundary_loops} boundary loop{'' if found.boundary_loops == 1 else 's'}")
    if found.nonmanifold_edges:
        problems.append(f"{found.nonmanifold_edges} sides shared by more than two faces")
    if found.pinched_vertices:
        problems.append(f"{found.pinched_vertices} pinched {'vertex' if found.pinched_vertices == 1 else 'vertices'}"
                        " where faces touch at a point only")
    state = "not closed" if found.boundary_loops else "closed but not manifold"
    return f"{state} ({', '.join(problems)}), {pieces}"


def describe_result(result, *, observed_stored: bool = True) -> str:
    """Lines ``kind``, ``connectivity``, ``frames`` (with the time range), ``vertices``,
    ``faces``, ``surface`` (:func:`describe_surface`; per-frame meshes: how many frames are
    closed and manifold) and, for an AnimatedMesh, the filled-in share and the rest pose; then
    the bounds. ``observed_stored`` False: the format does not hold the ``observed`` flags."""
    frames = f"frames: {result.frame_count}, times {result.times[0]:g} .. {result.times[-1]:g}"
    if isinstance(result, AnimatedMesh):
        points_only = len(result.faces) == 0
        if observed_stored:
            filled = f"{1.0 - result.observed.mean():.1%} of vertex-frames"
        else:
            filled = "not stored in this format"
        lines = [
            "kind: animated " + ("point set (no faces)" if points_only else "mesh"),
            f"connectivity: one for all {result.frame_count} frames (vertex i is the same "
            "point in every frame)",
            frames,
            f"vertices: {result.vertex_count}",
            f"faces: {len(result.faces)}",
            *([] if points_only else [f"surface: {describe_surface(result.faces, result.vertex_count)}"]),
            f"filled in (not observed): {filled}",
            f"rest pose: {'yes' if result.rest is not None else 'no'}",
            f"UVs: {'yes' if result.uv is not None else 'no'}",
            f"vertex colours: {'yes' if result.colors is not None else 'no'}",
        ]
    elif isinstance(result, MeshSequence):
        vertices = [len(v) for v, _ in result.meshes]
        faces = [len(f) for _, f in result.meshes]
        lines = [
            "kind: per-frame meshes",
            "connectivity: each frame its own (no correspondence between frames)",
            frames,
            f"vertices per frame: {_range(vertices)}",
            f"faces per frame: {_range(faces)}",
            f"surface: {_closed_frames(result)} of {result.frame_count} frames closed and manifold",
        ]
    else:
        raise InputError(f"not a result: {type(result).__name__}")
    lo, hi = result.bounds()
    lines.append(
        f"bounds: {np.round(lo, 4).tolist()} .. {np.round(hi, 4).tolist()} "
        f"(diagonal {result.diagonal():.4g})"
    )
    return "\n".join(lines)


def _closed_frames(result: MeshSequence) -> int:
    from fourd.metrics.topology import topology

    return sum(topology(f, len(v)).closed_manifold for v, f in result.meshes if len(f))


def describe(path) -> str:
    """Describe ``path``: a result (see the module docstring) or an input sequence."""
    path = Path(path)
    if not path.exists():
        raise InputError("does not exist", path)
    if is_result(path):
        from fourd.io.results import OBSERVED_KINDS, load_result, result_kind

        kind = result_kind(path)
        stored = kind in OBSERVED_KINDS and (kind != "folder" or (path / "observed.npy").is_file())
        result = load_result(path)
        return f"{path}: result, {FORMAT_NAMES[kind]}\n" + describe_result(
            result, observed_stored=stored
        )
    from fourd.io.frames import load_sequence

    return f"{path}: input\n" + describe_sequence(load_sequence(path))
