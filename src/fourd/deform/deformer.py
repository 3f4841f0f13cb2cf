"""Material-aware mesh deformation: anchors, precomputation once, poses many times (thesis
``004_f87f5acf96d50b57.txt``, chapter 2, Figure 2.3).

1. The anchor transformations (rotations with a uniform scale) are propagated to every
   triangle by blending them (:func:`~fourd.deform.algebra.blend`) with weights from the
   bending stiffness (:func:`~fourd.deform.extrapolation.blending_weights`, equation 2.1; per
   rotation axis for an anisotropic material, section 2.6).
2. The vertices are placed so that each triangle follows its transformation as closely as its
   shearing stiffness asks (:class:`~fourd.deform.reposition.Repositioning`, equation 2.4).
3. Dragged vertices (positional constraints, section 2.5) get their anchor triangle's rotation
   from a 1D search (:mod:`~fourd.deform.rotation_search`).

Both linear systems depend only on the rest mesh, the material and the choice of anchors,
fixed and dragged vertices, so they are factorised in the constructor and a pose is a blend, a
right-hand side and two triangular solves.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from fourd.deform.algebra import Similarity, blend, similarity_matrices, split_similarity
from fourd.deform.extrapolation import blending_weights
from fourd.deform.material import Material
from fourd.deform.reposition import Repositioning
from fourd.deform.rotation_search import area_change, binary_search, parabola_search
from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency, face_areas

__all__ = ["Deformer"]


class Deformer:
    """Precomputed material-aware deformation of one mesh.

    Parameters
    ----------
    rest : float64 [N, 3]
        The mesh to deform.
    faces : int [F, 3]
    material : Material, optional
        Stiffness fields (default uniform).
    anchors : int [K]
        Anchor triangles whose transformations :meth:`pose` takes.
    fixed : int [M], optional
        Vertices kept at their rest positions (a region of influence's boundary). Default: the
        first vertex of the first anchor when no vertex is dragged (the thesis fixes one vertex
        to remove the free translation).
    handles : int [H], optional
        Vertices the user drags (:meth:`pose` ``positions``); each adds an anchor triangle (the
        first face holding it) whose rotation is searched.
    search : ``"binary"`` or ``"parabola"``
        The 1D rotation search of section 2.5.2.

    Examples
    --------
    >>> import trimesh
    >>> bar = trimesh.creation.box(extents=(4, 1, 1))
    >>> deformer = Deformer(bar.vertices, bar.faces, anchors=[0, 6])
    >>> bool(np.allclose(deformer.pose(np.stack([np.eye(3)] * 2)), bar.vertices))
    True
    """

    def __init__(
        self,
        rest: np.ndarray,
        faces: np.ndarray,
        material: Material | None = None,
        anchors=(),
        *,
        fixed=None,
        handles=(),
        search: Literal["binary", "parabola"] = "binary",
    ):
        self.rest = np.asarray(rest, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        if self.rest.ndim != 2 or self.rest.shape[1] != 3 or self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise InputError("rest must be [N, 3] and faces [F, 3]")
        pairs, _ = face_adjacency(self.faces)
        if material is None:
            material = Material(np.ones(len(pairs)), np.ones(len(self.faces)))  # uniform
        self.material = material
        self.material.check(self.faces, pairs)
        if search not in ("binary", "parabola"):
            raise InputError(f"search must be binary or parabola, got {search!r}")
        self.search = search
        self.handles = np.asarray(handles, dtype=np.int64).ravel()
        anchors = [int(a) for a in np.asarray(anchors, dtype=np.int64).ravel()]
        self.user_anchor_count = len(anchors)
        self.handle_anchors = []
        for vertex in self.handles:
            holding = np.flatnonzero(np.any(self.faces == vertex, axis=1))
            if len(holding) == 0:
                raise InputError(f"dragged vertex {vertex} belongs to no triangle")
            choice = next((int(f) for f in holding if int(f) not in anchors), int(holding[0]))
            if choice not in anchors:
                anchors.append(choice)
            self.handle_anchors.append(anchors.index(choice))
        self.anchors = np.array(anchors, dtype=np.int64)
        if fixed is None:
            fixed = [] if len(self.handles) else [int(self.faces[self.anchors[0], 0])] if len(self.anchors) else []
        self.fixed = np.asarray(fixed, dtype=np.int64).ravel()
        bending = self.material.bending
        if self.material.anisotropic:
            self.axis_weights = np.stack(
                [blending_weights(self.faces, bending[:, c], self.anchors, pairs=pairs) for c in range(3)]
            )
            self.weights = self.axis_weights.mean(axis=0)
        else:
            self.axis_weights = None
            self.weights = blending_weights(self.faces, bending, self.anchors, pairs=pairs)
        self.system = Repositioning(self.rest, self.faces, self.material.shearing, fixed=self.fixed, handles=self.handles)
        self.rest_areas = face_areas(self.rest, self.faces)
        self.angles = np.zeros(len(self.handles))

    def triangle_transforms(self, anchors: Similarity) -> np.ndarray:
        """Blended transformations [F, 3, 3] of every triangle for ``K`` anchor transformations."""
        return similarity_matrices(blend(self.weights, anchors, self.axis_weights))

    def _solve(self, anchors: Similarity, positions) -> np.ndarray:
        return self.system.solve(self.triangle_transforms(anchors), self.rest[self.fixed], positions)

    def pose(self, transforms=None, positions=None, *, axes=None) -> np.ndarray:
        """New vertex positions [N, 3].

        Parameters
        ----------
        transforms : float64 [K, 3, 3], optional
            Transformations of the user's anchor triangles (rotations with a uniform scale;
            default the identity).
        positions : float64 [H, 3], optional
            Where the dragged vertices go (required when the deformer has ``handles``).
        axes : float64 [H, 3], optional
            Rotation axis of each dragged vertex's anchor (in an interactive tool, the view
            direction). Default (also for a zero row): the normal of the plane through the
            fixed vertices' centroid, the vertex's rest position and its new position.
        """
        k = self.user_anchor_count
        given = np.broadcast_to(np.eye(3), (k, 3, 3)) if transforms is None else np.asarray(transforms, float)
        if given.shape != (k, 3, 3):
            raise InputError(f"transforms must be [{k}, 3, 3], one per anchor triangle, got {list(given.shape)}")
        user = split_similarity(given) if k else Similarity(np.zeros((0, 3)), np.zeros(0))
        rotvecs = np.zeros((len(self.anchors), 3))
        log_scales = np.zeros(len(self.anchors))
        rotvecs[:k], log_scales[:k] = user.rotvecs, user.log_scales
        if len(self.handles) == 0:
            return self._solve(Similarity(rotvecs, log_scales), None)
        if positions is None:
            raise InputError("this deformer has dragged vertices: give their positions")
        positions = np.asarray(positions, dtype=np.float64).reshape(len(self.handles), 3)
        default = self._default_axes(positions)
        axes = default if axes is None else np.array(axes, dtype=float).reshape(len(self.handles), 3)
        missing = np.linalg.norm(axes, axis=1) == 0
        axes[missing] = default[missing]
        axes = axes / np.maximum(np.linalg.norm(axes, axis=1, keepdims=True), 1e-300)

        def energy_of(h, angle):
            trial = rotvecs.copy()
            trial[self.handle_anchors[h]] = angle * axes[h]
            vertices = self._solve(Similarity(trial, log_scales), positions)
            return area_change(self.rest_areas, vertices, self.faces, self.material.shearing)

        for _ in range(2 if len(self.handles) > 1 else 1):  # coordinate descent over the handles
            for h in range(len(self.handles)):
                energy = lambda angle, h=h: energy_of(h, angle)  # noqa: E731
                search = binary_search if self.search == "binary" else parabola_search
                self.angles[h] = search(energy, self.angles[h])
                rotvecs[self.handle_anchors[h]] = self.angles[h] * axes[h]
        return self._solve(Similarity(rotvecs, log_scales), positions)

    def _default_axes(self, positions: np.ndarray) -> np.ndarray:
        pivot = self.rest[self.fixed].mean(axis=0) if len(self.fixed) else self.rest[self.faces[self.anchors[0]]].mean(axis=0)
        before, after = self.rest[self.handles] - pivot, positions - pivot
        axes = np.cross(before, after)
        small = np.linalg.norm(axes, axis=1) < 1e-12 * np.maximum(np.linalg.norm(before, axis=1) ** 2, 1e-300)
        axes[small] = [0.0, 0.0, 1.0]
        return axes


def rotation_about(axis, angle: float) -> np.ndarray:
    """The 3x3 rotation by ``angle`` radians about ``axis``."""
    axis = np.asarray(axis, dtype=np.float64)
    return Rotation.from_rotvec(angle * axis / np.linalg.norm(axis)).as_matrix()
