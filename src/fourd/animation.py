"""Reconstruction results: :class:`AnimatedMesh` (one connectivity) and :class:`MeshSequence`."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fourd.errors import InputError


def _faces(array, vertex_count: int, name: str = "faces") -> np.ndarray:
    faces = np.asarray(array)
    if faces.size == 0:
        return np.zeros((0, 3), dtype=np.int64)
    if not np.issubdtype(faces.dtype, np.integer):
        if np.issubdtype(faces.dtype, np.floating) and np.all(faces == np.round(faces)):
            faces = faces.astype(np.int64)
        else:
            raise InputError(f"{name} must hold integer vertex indices, got dtype {faces.dtype}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(f"{name} must have shape [F, 3], got {list(faces.shape)}")
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if faces.min() < 0 or faces.max() >= vertex_count:
        raise InputError(
            f"{name} index vertices from {faces.min()} to {faces.max()} but there are {vertex_count}"
        )
    return faces


def _times(times, count: int) -> np.ndarray:
    times = np.arange(count, dtype=float) if times is None else np.asarray(times, dtype=float)
    if times.shape != (count,):
        raise InputError(f"times must have shape [{count}], got {list(times.shape)}")
    if not np.isfinite(times).all():
        raise InputError("times must be finite")
    if np.any(np.diff(times) <= 0):
        raise InputError("times must increase strictly")
    return times


@dataclass(frozen=True, eq=False)
class AnimatedMesh:
    """One mesh connectivity animated over time: vertex ``i`` is the same point in every frame.

    Attributes
    ----------
    faces : ndarray, int64 [F, 3]
        Triangles (may be empty: a point-sequence ground truth such as ``dfaust-hopping``).
    vertices : ndarray, float64 [T, N, 3]
        Vertex positions per frame, input units.
    times : ndarray, float64 [T]
        Frame times (defaults to 0, 1, 2, ...).
    observed : ndarray, bool [T, N]
        True where the vertex had input data near it in that frame (False: filled in).
        Defaults to all True.
    rest : ndarray, float64 [N, 3] or None
        The template / urshape the animation was built from.
    uv : ndarray, float64 [F, 3, 2] or None
        Texture coordinates per face corner (``uv[f, c]`` belongs to vertex ``faces[f, c]``),
        in [0, 1], ``v`` up (glTF and OBJ flip or keep it as their convention wants when
        written). Per corner, not per vertex, so that a UV seam needs no extra vertices and
        vertex ``i`` stays vertex ``i`` in every frame; writers that want per-vertex UVs split
        the seams (:func:`fourd.geometry.parameterization.split_seams`). Made by
        :func:`fourd.geometry.parameterization.uv_atlas`.
    colors : ndarray, float64 [T, N, 3] or None
        Vertex colours per frame in [0, 1], in the input's colour space (scanners and PLY
        files give sRGB-encoded colours; writers of formats that want linear colour convert).
        Made by :func:`fourd.appearance.vertex_colors`.
    """

    faces: np.ndarray
    vertices: np.ndarray
    times: np.ndarray | None = None
    observed: np.ndarray | None = None
    rest: np.ndarray | None = None
    uv: np.ndarray | None = None
    colors: np.ndarray | None = None

    def __post_init__(self):
        vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        if vertices.ndim != 3 or vertices.shape[2] != 3:
            raise InputError(f"vertices must have shape [T, N, 3], got {list(vertices.shape)}")
        frames, count = vertices.shape[:2]
        if frames == 0 or count == 0:
            raise InputError(f"vertices is empty (shape {list(vertices.shape)})")
        if not np.isfinite(vertices).all():
            raise InputError("vertices contain NaN or infinite values")
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", _faces(self.faces, count))
        object.__setattr__(self, "times", _times(self.times, frames))
        if self.observed is None:
            observed = np.ones((frames, count), dtype=bool)
        else:
            observed = np.asarray(self.observed).astype(bool)
            if observed.shape != (frames, count):
                raise InputError(
                    f"observed must have shape [{frames}, {count}], got {list(observed.shape)}"
                )
        object.__setattr__(self, "observed", observed)
        if self.rest is not None:
            rest = np.ascontiguousarray(self.rest, dtype=np.float64)
            if rest.shape != (count, 3) or not np.isfinite(rest).all():
                raise InputError(f"rest must be finite with shape [{count}, 3], got {list(rest.shape)}")
            object.__setattr__(self, "rest", rest)
        if self.uv is not None:
            uv = np.ascontiguousarray(self.uv, dtype=np.float64)
            if uv.shape != (len(self.faces), 3, 2) or not np.isfinite(uv).all():
                raise InputError(
                    f"uv must be finite with shape [{len(self.faces)}, 3, 2] (one per face "
                    f"corner), got {list(uv.shape)}"
                )
            object.__setattr__(self, "uv", uv)
        if self.colors is not None:
            colors = np.ascontiguousarray(self.colors, dtype=np.float64)
            if colors.shape != (frames, count, 3) or not np.isfinite(colors).all():
                raise InputError(
                    f"colors must be finite with shape [{frames}, {count}, 3], got {list(colors.shape)}"
                )
            object.__setattr__(self, "colors", np.clip(colors, 0.0, 1.0))

    def __len__(self) -> int:
        return len(self.vertices)

    @property
    def frame_count(self) -> int:
        return self.vertices.shape[0]

    @property
    def vertex_count(self) -> int:
        return self.vertices.shape[1]

    def frame(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices [N, 3], faces [F, 3])`` of one frame."""
        return self.vertices[index], self.faces

    def select(self, start: int | None = None, stop: int | None = None, step: int | None = None):
        """A new AnimatedMesh with frames ``start:stop:step`` (UVs, rest pose and the frames'
        colours kept)."""
        s = slice(start, stop, step)
        colors = None if self.colors is None else self.colors[s]
        return replace(self, vertices=self.vertices[s], times=self.times[s],
                       observed=self.observed[s], colors=colors)

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds over all frames, ``[2, 3]``."""
        return np.stack([self.vertices.min(axis=(0, 1)), self.vertices.max(axis=(0, 1))])

    def diagonal(self) -> float:
        lo, hi = self.bounds()
        return float(np.linalg.norm(hi - lo))


@dataclass(frozen=True, eq=False)
class MeshSequence:
    """Per-frame meshes without shared connectivity (e.g. per-frame or volumetric methods).

    Attributes
    ----------
    meshes : tuple of (vertices float64 [N_t, 3], faces int64 [F_t, 3])
    times : ndarray, float64 [T]
    """

    meshes: tuple[tuple[np.ndarray, np.ndarray], ...]
    times: np.ndarray | None = None

    def __post_init__(self):
        meshes = []
        for i, (vertices, faces) in enumerate(self.meshes):
            vertices = np.ascontiguousarray(vertices, dtype=np.float64)
            if vertices.ndim != 2 or vertices.shape[1] != 3:
                raise InputError(f"mesh {i}: vertices must have shape [N, 3], got {list(vertices.shape)}")
            if not np.isfinite(vertices).all():
                raise InputError(f"mesh {i}: vertices contain NaN or infinite values")
            meshes.append((vertices, _faces(faces, len(vertices), f"mesh {i} faces")))
        if not meshes:
            raise InputError("a mesh sequence needs at least one mesh")
        object.__setattr__(self, "meshes", tuple(meshes))
        object.__setattr__(self, "times", _times(self.times, len(meshes)))

    def __len__(self) -> int:
        return len(self.meshes)

    @property
    def frame_count(self) -> int:
        return len(self.meshes)

    def frame(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        return self.meshes[index]

    def select(self, start: int | None = None, stop: int | None = None, step: int | None = None):
        s = slice(start, stop, step)
        return MeshSequence(self.meshes[s], self.times[s])

    def bounds(self) -> np.ndarray:
        lo = np.min([v.min(axis=0) for v, _ in self.meshes if len(v)], axis=0)
        hi = np.max([v.max(axis=0) for v, _ in self.meshes if len(v)], axis=0)
        return np.stack([lo, hi])

    def diagonal(self) -> float:
        lo, hi = self.bounds()
        return float(np.linalg.norm(hi - lo))
