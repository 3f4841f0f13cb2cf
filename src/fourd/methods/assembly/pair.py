"""A source mesh mapped onto a target mesh: the cross-parameterisation of thesis section 5.4,
its steps chained.

With refinement on, a first patch map with small patches (``refine_radius``) leaves vertices
unmapped where anchors are sparse, and anchors are added there (5.4.4,
:mod:`~fourd.methods.assembly.refine`); the patch map is then computed with the refined
anchors (5.4.2, :mod:`~fourd.methods.assembly.crossparam`) and relaxed (5.4.3,
:mod:`~fourd.methods.assembly.relax`). The anchors are taken as given: clean them first
(:func:`~fourd.methods.assembly.anchors.consistent_anchors`,
:func:`~fourd.methods.assembly.anchors.spread_anchors`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from fourd.methods.assembly.anchors import Anchors
from fourd.methods.assembly.crossparam import CrossParameterization, cross_parameterize
from fourd.methods.assembly.options import PairOptions
from fourd.methods.assembly.refine import Refinement, refine_anchors
from fourd.methods.assembly.relax import RelaxedMap, relax_map


class PairMap(NamedTuple):
    """The map of :func:`cross_parameterize_pair`.

    faces : int64 [N]
        Target triangle of each source vertex (-1: no counterpart on the target).
    barycentric : float64 [N, 3]
    points : float64 [N, 3]
        The mapped points (NaN where unmapped).
    anchors : Anchors
        The anchors the patch map used (the given ones and the refinement's).
    patch_map : CrossParameterization
        The map before the relaxation.
    relaxed : RelaxedMap
        The relaxation, with its energy and flips per sweep.
    refinement : Refinement or None
    """

    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray
    anchors: Anchors
    patch_map: CrossParameterization
    relaxed: RelaxedMap
    refinement: Refinement | None


def cross_parameterize_pair(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    anchors: Anchors,
    options: PairOptions | None = None,
) -> PairMap:
    """Map the source mesh's vertices onto the target surface (module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
        Both meshes oriented the same way (outward normals).
    anchors : Anchors
    options : PairOptions, optional

    Returns
    -------
    PairMap
    """
    options = PairOptions() if options is None else options
    meshes = (source_vertices, source_faces, target_vertices, target_faces)
    refinement = None
    if options.refine is not None:
        limited = replace(options.crossparam, max_radius=min(options.refine_radius, options.crossparam.max_radius))
        first = cross_parameterize(*meshes, anchors, limited)
        refinement = refine_anchors(*meshes, anchors, first.faces, first.barycentric, options.refine)
        anchors = refinement.anchors
    patch_map = cross_parameterize(*meshes, anchors, options.crossparam)
    relaxed = relax_map(*meshes, patch_map.faces, patch_map.barycentric, options.relax)
    return PairMap(relaxed.faces, relaxed.barycentric, relaxed.points, anchors, patch_map, relaxed, refinement)
