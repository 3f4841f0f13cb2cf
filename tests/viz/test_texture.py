import numpy as np
import pytest
import trimesh

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.viz import texture as tex


def moving_sphere(frames=4, shift=0.5, subdivisions=2):
    s = trimesh.creation.icosphere(subdivisions)
    vertices = np.stack([s.vertices + [shift * t, 0.0, 0.0] for t in range(frames)])
    return AnimatedMesh(s.faces, vertices)


def test_checker_alternates_between_neighbouring_cells():
    coords = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [1.5, 1.5, 0.5], [-0.5, 0.5, 0.5]])
    assert tex.texture_pattern(coords, "checker").tolist() == [1.0, 0.0, 1.0, 0.0]


def test_grid_is_dark_only_near_lattice_planes():
    coords = np.array([[0.5, 0.5, 0.5], [1.01, 0.5, 0.5], [0.5, 2.99, 0.5]])
    assert tex.texture_pattern(coords, "grid", line=0.08).tolist() == [1.0, 0.0, 0.0]
    assert tex.texture_pattern(coords, "none").tolist() == [1.0, 1.0, 1.0]
    with pytest.raises(InputError, match="unknown texture"):
        tex.texture_pattern(coords, "plaid")


def test_texture_space_has_requested_cells_along_the_diagonal():
    space = tex.texture_space(np.array([[0.0, 0, 0], [3.0, 4.0, 0]]), cells=10)
    assert space.cell == pytest.approx(0.5)
    span = space.apply(np.array([[3.0, 4.0, 0]])) - space.apply(np.array([[0.0, 0, 0]]))
    assert np.linalg.norm(span) == pytest.approx(10.0)


def test_animated_mesh_texture_is_fixed_on_the_first_frame():
    anim = moving_sphere()
    first = tex.texture_coordinates(anim, 0)
    last = tex.texture_coordinates(anim, anim.frame_count - 1)
    assert np.array_equal(first, last)
    assert tex.carries_correspondence(anim)


def test_mesh_sequence_texture_follows_each_frames_positions():
    anim = moving_sphere(shift=0.5)
    seq = MeshSequence(tuple(anim.frame(i) for i in range(anim.frame_count)))
    space = tex.texture_space(
        anim.bounds() * 0 + np.stack([anim.vertices[0].min(0), anim.vertices[0].max(0)])
    )
    moved = tex.texture_coordinates(seq, 2) - tex.texture_coordinates(seq, 0)
    assert np.allclose(moved, [1.0 / space.cell, 0, 0])
    assert not tex.carries_correspondence(seq)


def test_vertex_errors_are_zero_against_itself_and_bounded_by_a_shift():
    anim = moving_sphere(frames=3)
    errors = tex.vertex_errors(anim, anim)
    assert len(errors) == 3 and all(np.all(e == 0) for e in errors)
    shifted = AnimatedMesh(anim.faces, anim.vertices + [0.0, 0.05, 0.0])
    errors = tex.vertex_errors(anim, shifted)
    flat = np.concatenate(errors)
    assert flat.max() <= 0.05 + 1e-9  # a vertex is never farther than the shift
    assert flat.mean() > 0.01  # but the shift is seen
    assert tex.error_scale(errors) <= 0.05 + 1e-9


def test_vertex_errors_match_truth_frames_by_time_when_counts_differ():
    anim = moving_sphere(frames=3)
    truth = AnimatedMesh(
        anim.faces, np.concatenate([anim.vertices, anim.vertices[-1:] + 5]), times=[0, 1, 2, 3]
    )
    errors = tex.vertex_errors(anim, truth)
    assert all(np.all(e == 0) for e in errors)


def test_colormap_and_tint():
    colors = tex.colormap(np.array([0.0, 0.5, 1.0, 7.0]), 1.0)
    assert colors.shape == (4, 3)
    brightness = colors.sum(axis=1)
    assert brightness[0] > brightness[1] > brightness[2]  # more error, darker
    assert np.allclose(colors[2], colors[3])  # clipped above the scale
    tinted = tex.tint_unobserved(np.ones((3, 3)), np.array([True, False, True]))
    assert np.allclose(tinted[[0, 2]], 1.0)
    assert tinted[1, 2] > tinted[1, 0]  # bluer
