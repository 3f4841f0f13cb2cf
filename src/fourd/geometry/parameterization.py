"""Texture coordinates of a triangle mesh: a UV atlas (charts cut along seams, flattened and
packed into the unit square) and the seam handling formats need.

UVs are kept per face corner, ``uv [F, 3, 2]``: corner ``c`` of face ``f`` belongs to vertex
``faces[f, c]``. A seam is where two corners of the same vertex have different UVs; formats
with face-varying attributes (USD, Alembic, OBJ's ``vt``) take corners as they are
(:func:`indexed_corners`), formats with per-vertex attributes only (glTF) need the vertices
on seams duplicated (:func:`split_seams`). Neither changes the mesh's own vertices, so an
animation's per-frame positions still map one to one onto them.

The atlas comes from xatlas (an optional extra: ``pip install 'fourd[uv]'``), computed once
on one pose (the template) and shared by every frame: a texture painted once follows the
surface through the animation.

References
----------
J. Young, "xatlas" (https://github.com/jpcy/xatlas), after Lévy, Petitjean, Ray, Maillot:
Least squares conformal maps for automatic texture atlas generation, SIGGRAPH 2002.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fourd.errors import InputError

__all__ = ["Seams", "indexed_corners", "split_seams", "uv_atlas", "uv_available"]


def uv_available() -> bool:
    """Whether :func:`uv_atlas` can run (the xatlas package is importable)."""
    try:
        import xatlas  # noqa: F401
    except ImportError:
        return False
    return True


def uv_atlas(
    vertices: np.ndarray, faces: np.ndarray, *, resolution: int = 1024, padding: int = 2
) -> np.ndarray:
    """A UV atlas of a triangle mesh: per-corner texture coordinates ``[F, 3, 2]`` in [0, 1].

    The surface is cut into charts of low distortion, each flattened (LSCM) and packed into
    one square; ``u`` to the right, ``v`` up (OBJ's and USD's convention), every chart
    counter-clockwise like the faces (none mirrored: tangent spaces agree). The charts keep
    their relative size (one texel covers the same area everywhere) and the square's aspect
    (the packed rectangle is not stretched to fill it).

    Parameters
    ----------
    vertices : array [N, 3]
        One pose of the mesh (for an animation, its template or first frame).
    faces : int array [F, 3]
    resolution : int
        The texture size, in texels, the packing is planned for (about: xatlas may use a
        slightly different one); ``padding`` is counted in its texels.
    padding : int
        Texels left empty between charts, so filtering a texture of ``resolution`` texels
        does not bleed one chart into another.

    Returns
    -------
    ndarray, float64 [F, 3, 2]

    Raises
    ------
    InputError
        xatlas not installed (saying what to install), no faces, bad shapes.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> uv = uv_atlas(box.vertices, box.faces, resolution=64)  # doctest: +SKIP
    >>> uv.shape, bool(uv.min() >= 0 and uv.max() <= 1)  # doctest: +SKIP
    ((12, 3, 2), True)
    """
    try:
        import xatlas
    except ImportError:
        raise InputError(
            "UV atlases need the xatlas package, which is not installed: pip install 'fourd[uv]'"
        ) from None
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(
            f"a UV atlas needs vertices [N, 3] and faces [F, 3], got {list(vertices.shape)} "
            f"and {list(faces.shape)}"
        )
    if len(faces) == 0:
        raise InputError("a UV atlas needs faces: this mesh has none")
    if int(resolution) < 8 or int(padding) < 0:
        raise InputError(f"resolution must be at least 8 and padding at least 0, got "
                         f"{resolution} and {padding}")
    # xatlas works in float32: centre and scale first so large coordinates keep their digits
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    extent = float((hi - lo).max()) or 1.0
    local = ((vertices - (lo + hi) / 2) / extent).astype(np.float32)
    atlas = xatlas.Atlas()
    atlas.add_mesh(local, np.ascontiguousarray(faces, dtype=np.uint32))
    pack = xatlas.PackOptions()
    pack.resolution = int(resolution)
    pack.padding = int(padding)
    charts = xatlas.ChartOptions()
    atlas.generate(charts, pack)
    if atlas.atlas_count > 1:  # did not fit one square: let xatlas size one atlas itself
        atlas = xatlas.Atlas()
        atlas.add_mesh(local, np.ascontiguousarray(faces, dtype=np.uint32))
        pack.resolution = 0
        atlas.generate(charts, pack)
    mapping, indices, uvs = atlas[0]
    if not np.array_equal(mapping[indices], faces):  # xatlas keeps faces in order; make sure
        raise RuntimeError("xatlas changed the faces of the mesh it was given")
    # xatlas normalises u and v by the atlas' width and height separately: undo the stretch
    width, height = float(atlas.width), float(atlas.height)
    side = max(width, height)
    uvs = uvs.astype(np.float64) * [width / side, height / side]
    _, chart = atlas.get_mesh_vertex_assignment(0)
    uvs = _unmirrored(uvs, indices, chart.astype(np.int64), int(atlas.chart_count))
    return np.clip(uvs[indices], 0.0, 1.0)


def _unmirrored(uvs: np.ndarray, faces: np.ndarray, chart: np.ndarray, count: int) -> np.ndarray:
    """``uvs`` [M, 2] with every chart that xatlas laid out mirrored (clockwise in the
    atlas) flipped in ``u`` within its own bounding box, so it stays where it was packed."""
    valid = (chart >= 0) & (chart < count)  # vertices outside any chart: left alone
    a, b, c = (uvs[faces[:, i]] for i in range(3))
    signed = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    face_chart = chart[faces[:, 0]]
    keep = valid[faces[:, 0]]
    if not keep.any():
        return uvs
    area = np.bincount(face_chart[keep], weights=signed[keep], minlength=count)
    flip = valid & (area[np.where(valid, chart, 0)] < 0)
    if not flip.any():
        return uvs
    lo = np.full(count, np.inf)
    hi = np.full(count, -np.inf)
    np.minimum.at(lo, chart[valid], uvs[valid, 0])
    np.maximum.at(hi, chart[valid], uvs[valid, 0])
    out = uvs.copy()
    out[flip, 0] = lo[chart[flip]] + hi[chart[flip]] - uvs[flip, 0]
    return out


class Seams(NamedTuple):
    """A mesh with its vertices split along UV seams (:func:`split_seams`).

    vertex : int64 [M]
        The original vertex of each new one; ``vertex[:N] == arange(N)`` (every original
        vertex keeps its index; the copies made on seams follow, ``M - N`` of them).
    faces : int64 [F, 3]
        The faces over the new vertices (same order as the original faces).
    uv : float64 [M, 2]
        One texture coordinate per new vertex.
    """

    vertex: np.ndarray
    faces: np.ndarray
    uv: np.ndarray


def split_seams(faces: np.ndarray, uv: np.ndarray, vertex_count: int) -> Seams:
    """Duplicate the vertices whose corners carry different UVs, for formats that hold one UV
    per vertex (glTF). Vertex ``i < N`` stays vertex ``i`` (with the UV of its first corner);
    per-vertex data of the new mesh is ``data[..., seams.vertex, :]``.

    Parameters
    ----------
    faces : int array [F, 3]
    uv : array [F, 3, 2]
        Per-corner UVs.
    vertex_count : int
        N; vertices used by no face keep UV (0, 0).

    Examples
    --------
    >>> faces = np.array([[0, 1, 2], [2, 1, 3]])
    >>> uv = np.array([[[0, 0], [1, 0], [0, 1]], [[0.5, 1], [1, 0], [1, 1]]], float)
    >>> seams = split_seams(faces, uv, 4)   # vertex 2 is on a seam: (0, 1) and (0.5, 1)
    >>> seams.vertex.tolist(), seams.faces.tolist()
    ([0, 1, 2, 3, 2], [[0, 1, 2], [4, 1, 3]])
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    corners = faces.ravel()
    uv_corners = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if len(uv_corners) != len(corners):
        raise InputError(f"uv must have one entry per face corner ({len(corners)}), got "
                         f"{len(uv_corners)}")
    keys = np.empty(len(corners), dtype=[("v", np.int64), ("u", np.float64), ("w", np.float64)])
    keys["v"], keys["u"], keys["w"] = corners, uv_corners[:, 0], uv_corners[:, 1]
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    # each original vertex keeps its index for its (vertex, uv) pair met first in the faces;
    # its other pairs become new vertices, numbered in the order the faces meet them
    owner = unique["v"]
    by_owner = np.lexsort((first, owner))
    is_first = np.zeros(len(unique), dtype=bool)
    is_first[by_owner[np.r_[True, owner[by_owner][1:] != owner[by_owner][:-1]]]] = True
    new_index = np.empty(len(unique), dtype=np.int64)
    new_index[is_first] = owner[is_first]
    extra = np.flatnonzero(~is_first)
    extra = extra[np.argsort(first[extra], kind="stable")]
    new_index[extra] = vertex_count + np.arange(len(extra))
    vertex = np.concatenate([np.arange(vertex_count), owner[extra]])
    out_uv = np.zeros((len(vertex), 2))
    out_uv[new_index] = np.stack([unique["u"], unique["w"]], axis=1)
    return Seams(vertex, new_index[inverse.ravel()].reshape(-1, 3), out_uv)


def indexed_corners(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-corner UVs ``[F, 3, 2]`` as distinct values ``[K, 2]`` and one index per corner
    ``[3F]`` (face-varying indexed primvars: USD ``primvars:st``, Alembic ``uv``).

    Examples
    --------
    >>> values, indices = indexed_corners(np.array([[[0, 0], [1, 0], [0, 1]], [[0, 1], [1, 0], [1, 1]]]))
    >>> values.tolist(), indices.tolist()
    ([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]], [0, 2, 1, 1, 2, 3])
    """
    corners = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    values, indices = np.unique(corners, axis=0, return_inverse=True)
    return values, indices.ravel().astype(np.int64)
