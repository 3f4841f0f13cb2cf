"""An animated mesh closed at the end (as ``assembly`` and ``surfels`` do): holes filled and small
handles opened, in every frame."""

import numpy as np
from scipy.spatial.transform import Rotation

from fourd.geometry import hole_closing
from fourd.geometry.hole_closing import holes_to_close
from fourd.methods.assembly import Options
from fourd.methods.assembly.hierarchy import Block
from fourd.metrics.topology import topology
from tests.geometry.test_handles import _body_with_an_arch, _pinched


def close_small_holes(block: Block, *args) -> Block:
    return Block(*hole_closing.close_small_holes(block.faces, block.vertices, block.observed, *args))


def test_a_handle_of_the_first_frame_is_cut_out_of_every_frame():
    """A body with a thin arch (genus 1) moving rigidly over 3 frames, with a hole in its side:
    closed with the default ``open_handles``, one connectivity of genus 0 serves every frame;
    the membranes (the hole's and the arch's openings) move with the body (the membrane is
    affine-equivariant), are not observed, and every vertex kept keeps its track and flag."""
    vertices, faces = _body_with_an_arch()
    faces = faces[~(vertices[faces].mean(axis=1)[:, 0] > 0.93)]  # a hole on the side
    turns = [Rotation.from_rotvec([0.0, 0.3 * t, 0.1 * t]).as_matrix() for t in range(3)]
    frames = np.stack([vertices @ turn.T + [0.2 * t, 0.0, -0.1 * t] for t, turn in enumerate(turns)])
    observed = np.ones((3, len(vertices)), dtype=bool)
    observed[1, ::7] = False
    block = Block(faces, frames, observed)
    closed = close_small_holes(block, 0.25, 0.1, Options().open_handles)
    found = topology(closed.faces, closed.vertices.shape[1])
    assert found.closed_manifold and found.oriented and found.components == 1 and found.euler == 2
    assert not _pinched(closed.faces)
    closing = holes_to_close(frames[0], faces, 0.25, 0.1, Options().open_handles)
    kept, added = closing.kept, len(closing.vertices) - len(closing.kept)
    assert 0 < len(vertices) - len(kept) < 0.02 * len(vertices) and added > 0
    np.testing.assert_array_equal(closed.vertices[:, : len(kept)], frames[:, kept])
    np.testing.assert_array_equal(closed.observed[:, : len(kept)], observed[:, kept])
    assert not closed.observed[:, len(kept):].any()
    for t, turn in enumerate(turns):
        moved = closed.vertices[0, len(kept):] @ turn.T + [0.2 * t, 0.0, -0.1 * t]
        np.testing.assert_allclose(closed.vertices[t, len(kept):], moved, atol=1e-9)
    # without opening: the hole closed, the arch kept
    kept_handle = close_small_holes(block, 0.25, 0.1, 0)
    assert topology(kept_handle.faces, kept_handle.vertices.shape[1]).euler == 0
    assert kept_handle.vertices.shape[1] >= len(vertices)


def test_pieces_touching_at_a_vertex_come_out_as_two_closed_manifolds():
    """Two spheres sharing one vertex (a pinch), one with a hole and a triangle hanging from it
    by a vertex, over 2 frames: the flap is dropped with its own vertices, the hole is filled
    and the pinch split into a copy per sphere, at the same place in every frame, with its
    observed flag; each sphere is then a closed manifold of its own."""
    import trimesh

    sphere = trimesh.creation.icosphere(2)
    count = len(sphere.vertices)
    antipode = int(np.argmin(sphere.vertices @ sphere.vertices[0]))
    other = sphere.faces + count
    other[other == count + antipode] = 0  # the second sphere, beside the first, touches it at vertex 0
    flap = [[5, 2 * count, 2 * count + 1]]  # a triangle hanging from the first sphere by vertex 5
    faces = np.vstack([sphere.faces[1:], other, flap])  # the first sphere has a one-face hole
    first = np.vstack([sphere.vertices, sphere.vertices + 2 * sphere.vertices[0], [[3, 3, 3], [3, 3, 4]]])
    frames = np.stack([first, 1.5 * first + [0.1, 0.2, 0.3]])
    observed = np.ones((2, 2 * count + 2), dtype=bool)
    observed[1, 0] = False
    closed = close_small_holes(Block(faces, frames, observed), 0.25, 1.0, Options().open_handles)
    found = topology(closed.faces, closed.vertices.shape[1])
    assert found.closed_manifold and found.components == 2 and found.euler == 4 and found.pinched_vertices == 0
    copies = np.intersect1d(np.flatnonzero(np.all(closed.vertices[0] == first[0], axis=1)), closed.faces)
    assert len(copies) == 2  # vertex 0 and its copy, together in both frames
    np.testing.assert_array_equal(closed.vertices[1, copies], frames[1, [0, 0]])
    assert not closed.observed[1, copies].any() and closed.observed[0, copies].all()
    assert not (closed.vertices[0] == 3.0).any()  # the flap's own vertices are gone


def test_a_hole_that_cannot_be_filled_stays_open_and_the_rest_of_the_closing_is_done():
    """A hole whose rim has collapsed to a point (no length: the membrane cannot be laid out)
    is left open with a warning, but the flap hanging from the surface is still dropped and
    the pinch it leaves split: the result has no pinched vertex."""
    import trimesh

    sphere = trimesh.creation.icosphere(2)
    count = len(sphere.vertices)
    vertices = np.vstack([sphere.vertices, [[3, 3, 3], [3, 3, 4]]])
    vertices[sphere.faces[0]] = vertices[sphere.faces[0]].mean(axis=0)  # the hole's rim, one point
    flap = [[5, count, count + 1]]  # a triangle hanging from the sphere by vertex 5
    faces = np.vstack([sphere.faces[1:], flap])
    block = Block(faces, vertices[None], np.ones((1, len(vertices)), dtype=bool))
    closed = close_small_holes(block, 0.25, 1.0, Options().open_handles)
    found = topology(closed.faces, closed.vertices.shape[1])
    assert found.boundary_loops == 1 and found.pinched_vertices == 0 and found.components == 1
    assert len(closed.faces) == len(sphere.faces) - 1
