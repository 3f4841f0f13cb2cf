"""Fans of faces around a vertex: pinches found and split (geometry/fans.py)."""

import numpy as np
import trimesh

from fourd.geometry.fans import corner_fans, fan_count, pinched_vertices, split_pinches
from fourd.metrics.topology import topology


def _fans_by_walking(faces):
    """Reference: per vertex, the pieces of its faces joined by sides through it."""
    counts = {}
    for v in np.unique(faces):
        around = [f for f in range(len(faces)) if v in faces[f]]
        label = {f: f for f in around}

        def root(f, label=label):
            while label[f] != f:
                f = label[f]
            return f

        for i, f in enumerate(around):
            for g in around[i + 1:]:
                if len(set(faces[f]) & set(faces[g])) >= 2:
                    label[root(f)] = root(g)
        counts[int(v)] = len({root(f) for f in around})
    return counts


def _checkered_grid(n=6, seed=0):
    """A grid of quads with some cells removed at random: removed cells meeting diagonally leave
    vertices where two fans touch."""
    rng = np.random.default_rng(seed)
    faces = []
    for i in range(n):
        for j in range(n):
            if rng.random() < 0.35:
                continue
            a, b, c, d = i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j
            faces += [[a, b, c], [a, c, d]]
    return np.array(faces), (n + 1) ** 2


def test_the_fans_match_a_walk_around_each_vertex():
    faces, count = _checkered_grid()
    walked = _fans_by_walking(faces)
    assert fan_count(faces) == sum(walked.values())
    assert pinched_vertices(faces).tolist() == sorted(v for v, k in walked.items() if k > 1)
    assert len(pinched_vertices(faces)) > 0  # the random grid has pinches to find
    labels = corner_fans(faces)
    for v, k in walked.items():
        assert len(np.unique(labels[faces == v])) == k


def test_two_spheres_touching_at_a_vertex_split_into_two_closed_manifolds():
    """Split, the pinch becomes two vertices at the same place: two pieces, each a closed
    manifold sphere, and nothing moved."""
    sphere = trimesh.creation.icosphere(2)
    count = len(sphere.vertices)
    other = sphere.faces + count
    other[other == count] = 0
    faces = np.vstack([sphere.faces, other])
    vertices = np.vstack([sphere.vertices, sphere.vertices + 2 * sphere.vertices[0]])  # touching at vertex 0
    before = topology(faces, 2 * count)
    assert before.pinched_vertices == 1 and not before.closed_manifold
    split, source = split_pinches(faces, 2 * count)
    assert len(source) == 2 * count + 1 and source[-1] == 0
    after = topology(split, len(source))
    assert after.closed_manifold and after.components == 2 and after.euler == 4
    assert np.array_equal(vertices[source][split], vertices[faces])


def test_a_manifold_mesh_is_left_as_it_is():
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    split, source = split_pinches(torus.faces, len(torus.vertices))
    assert np.array_equal(split, torus.faces) and np.array_equal(source, np.arange(len(torus.vertices)))
    assert len(pinched_vertices(torus.faces)) == 0
    assert fan_count(torus.faces) == len(torus.vertices)


def test_a_flap_and_a_crumb_are_fragments_and_a_touching_body_and_a_small_object_are_not():
    """A triangle hanging from a sphere by one vertex is a flap; a second sphere touching the
    first at a vertex is a body in contact and stays; a tetrahedron on its own is a crumb beside
    a sphere of 5,120 faces (a thousandth) but an object of its own beside one of 320."""
    from fourd.geometry.fans import fragments

    sphere = trimesh.creation.icosphere(2)
    count = len(sphere.vertices)
    other = sphere.faces + count
    other[other == count] = 0
    flap = [[5, 2 * count, 2 * count + 1]]
    faces = np.vstack([sphere.faces, other, flap])
    assert np.flatnonzero(fragments(faces, 2 * count + 2)).tolist() == [len(faces) - 1]
    assert not fragments(np.vstack([sphere.faces, other]), 2 * count).any()
    tetrahedron = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]])
    for subdivisions, crumb in ((4, True), (2, False)):
        body = trimesh.creation.icosphere(subdivisions)
        faces = np.vstack([body.faces, tetrahedron + len(body.vertices)])
        found = fragments(faces, len(body.vertices) + 4)
        assert found[len(body.faces):].all() == crumb and not found[: len(body.faces)].any()
