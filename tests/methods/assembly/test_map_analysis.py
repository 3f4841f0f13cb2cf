"""Analysis of a pair map (thesis 5.5): a rigid map breaks nothing; a region carried off on its
own is flagged as one region, and the stretch test tells a kept shape from a squashed one."""

from __future__ import annotations

import numpy as np
import pytest
from assembly_shapes import rigid_copy

from fourd.methods.assembly import (
    Block,
    Options,
    edge_ratios,
    inconsistent_regions,
    merge_blocks,
    passes_stretch_test,
)


def test_a_rigid_map_is_consistent_everywhere():
    pair = rigid_copy()
    mapped = np.ones(len(pair.source_vertices), dtype=bool)
    ratios = edge_ratios(pair.source_vertices, pair.source_faces, pair.truth)
    np.testing.assert_allclose(ratios, 1.0, atol=1e-12)
    analysis = inconsistent_regions(pair.source_vertices, pair.source_faces, pair.truth, mapped)
    assert analysis.regions == 0 and not analysis.flagged.any()
    assert passes_stretch_test(pair.source_vertices, pair.source_faces, pair.truth, mapped)


def test_a_region_carried_off_is_flagged_as_one_region():
    pair = rigid_copy()
    vertices = pair.source_vertices
    points = pair.truth.copy()
    cap = vertices[:, 2] > 0.85  # a cap of a few vertices, moved 3 edges along the normal
    points[cap] += 3.0 * pair.edge * vertices[cap] / np.linalg.norm(vertices[cap], axis=1, keepdims=True)
    mapped = np.ones(len(vertices), dtype=bool)
    analysis = inconsistent_regions(vertices, pair.source_faces, points, mapped)
    assert analysis.flagged[cap].all() and analysis.regions == 1
    # the flags reach about one ring beyond the cap, not across the mesh
    assert analysis.flagged.sum() < 4 * cap.sum()
    # unmapped vertices are never flagged
    mapped[cap] = False
    assert not inconsistent_regions(vertices, pair.source_faces, points, mapped).flagged[cap].any()
    # squashed to half its size, the cap fails the thesis' stretch test
    squashed = pair.source_vertices.copy()
    centre = squashed[cap].mean(axis=0)
    squashed[cap] = centre + 0.5 * (squashed[cap] - centre)
    assert not passes_stretch_test(vertices, pair.source_faces, squashed, cap)
    assert passes_stretch_test(vertices, pair.source_faces, vertices, cap)


def test_a_band_of_flags_across_the_surface_does_not_take_a_half_with_it():
    # the neck between two parts that the next frame breaks: the flags cut the surface in two,
    # and neither half is an island to add to the region
    import trimesh

    sphere = trimesh.creation.icosphere(4)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    edge = float(np.median(sphere.edges_unique_length))
    band = np.abs(vertices[:, 2]) < 0.6 * edge
    points = vertices + (3.0 * edge * band)[:, None] * vertices
    analysis = inconsistent_regions(vertices, faces, points, np.ones(len(vertices), dtype=bool))
    assert analysis.flagged[band].all() and analysis.regions == 1
    assert not analysis.flagged[np.abs(vertices[:, 2]) > 0.3].any()


def test_the_merge_can_unmap_inconsistent_regions():
    pair = rigid_copy()
    left = Block(pair.source_faces, pair.source_vertices[None], np.ones((1, len(pair.source_vertices)), dtype=bool))
    right = Block(pair.source_faces, (pair.source_vertices + [0.01, 0.0, 0.0])[None],
                  np.ones((1, len(pair.source_vertices)), dtype=bool))
    merged, report = merge_blocks(left, right, Options(relax_sweeps=1, correct=True, paste=True))
    # a clean map: nothing to correct, the shift recovered
    assert report.flagged == 0
    np.testing.assert_allclose(merged.vertices[1], pair.source_vertices + [0.01, 0.0, 0.0], atol=1e-6)
    with pytest.raises(ValueError, match="correct_stretch"):
        Options(correct_stretch=1.0)
