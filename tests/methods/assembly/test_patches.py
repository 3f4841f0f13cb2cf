"""Matching patches grown around anchors (thesis 5.4.2, "Patch Growth")."""

from __future__ import annotations

import numpy as np
import pytest
from assembly_shapes import remeshed_frames, rigid_copy

from fourd.geometry.flattening import boundary_loop_vertices
from fourd.methods.assembly import CrossParamOptions, grow_patches


def _grow(pair, **options):
    return grow_patches(pair.source_vertices, pair.source_faces, pair.target_vertices,
                        pair.target_faces, pair.anchors, CrossParamOptions(**options))


def test_patches_are_matching_disks_holding_enough_anchors():
    pair = rigid_copy()
    grown = _grow(pair)
    assert grown.covered.all()  # the second pass covers what the anchors' patches left
    assert len(grown.pairs) >= len(pair.anchors.source)
    for patch in grown.pairs:
        for side, faces in ((patch.source, pair.source_faces), (patch.target, pair.target_faces)):
            local = np.searchsorted(side.vertices, faces[side.faces])
            boundary_loop_vertices(local, len(side.vertices))  # raises unless a disk
            assert side.distance.max() <= side.radius
        # a rigid copy: both patches are the same piece of surface, with the same anchors
        np.testing.assert_array_equal(patch.source.faces, patch.target.faces)
        assert len(patch.anchors) >= 3
        assert np.isin(pair.anchors.source[patch.anchors], patch.source.vertices).all()
    first = grown.pairs[: len(pair.anchors.source)]
    assert [p.centre for p in first] == pair.anchors.source.tolist()


@pytest.mark.parametrize("count", [3, 5])
def test_growth_stops_at_the_anchor_count(count):
    pair = rigid_copy()
    grown = _grow(pair, patch_anchors=count, min_anchors=3, boundary_band=0.1)
    largest = 0.2 * np.linalg.norm(np.ptp(pair.source_vertices, axis=0))
    held = [len(p.anchors) for p in grown.pairs if p.source.radius < largest]
    capped = [len(p.anchors) for p in grown.pairs if p.source.radius >= largest]
    # the radius stops at the count-th anchor: more come in only at equal distance or by
    # hole filling, never many more; a patch stopped by the largest radius holds fewer
    assert min(held) >= count and np.median(held) <= count + 1
    assert all(3 <= n for n in capped)


def test_patches_larger_than_the_largest_radius_are_given_up():
    pair = rigid_copy()
    grown = _grow(pair, max_radius=0.01)  # about a third of an edge: no anchor pair fits
    assert grown.pairs == [] and not grown.covered.any()
    assert grown.discarded >= len(pair.anchors.source)


def test_remeshed_frames_get_patches_on_both_triangulations():
    pair = remeshed_frames()
    grown = _grow(pair)
    assert grown.covered.mean() > 0.99
    for patch in grown.pairs:
        assert abs(patch.target.radius - patch.source.radius) < 1e-12
