"""Small handles (topological noise) found as balls that are not disks, and opened."""

import numpy as np
import trimesh
from skimage.measure import marching_cubes

from fourd.geometry.handles import ball_euler, capped_genus, open_small_handles
from fourd.geometry.hole_filling import fill_holes
from fourd.metrics.topology import topology


def _body_with_an_arch(n=72):
    """A unit sphere with a thin arch on top (a ring of tube radius 0.045 half sunk into it: one
    small handle, genus 1) and a thin finger below (tube radius 0.04, 0.35 long), meshed by
    marching cubes at a spacing of 0.039."""
    x = np.linspace(-1.4, 1.4, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    distance = np.sqrt(X**2 + Y**2 + Z**2) - 1.0
    ring = np.sqrt(Y**2 + (Z - 1.0) ** 2) - 0.22
    distance = np.minimum(distance, np.sqrt(ring**2 + X**2) - 0.045)
    finger = np.maximum(np.sqrt(X**2 + Y**2) - 0.04, np.maximum(Z + 0.5, -Z - 1.35))
    distance = np.minimum(distance, finger)
    vertices, faces, _, _ = marching_cubes(distance, 0.0, spacing=(x[1] - x[0],) * 3)
    return vertices + x[0], faces[:, ::-1].astype(np.int64)


def _pinched(faces):
    """Vertices whose faces form more than one fan (joined by the sides through the vertex)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from fourd.geometry.meshes import face_adjacency

    faces = np.asarray(faces)
    pairs, sides = face_adjacency(faces)
    links = []
    for (f, g), side in zip(pairs.tolist(), sides.tolist(), strict=True):
        for v in side:
            a = 3 * f + faces[f].tolist().index(v)
            b = 3 * g + faces[g].tolist().index(v)
            links.append((a, b))
    links = np.array(links).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(3 * len(faces),) * 2)
    _, label = connected_components(graph, directed=False)
    fans = {}
    for c, v in enumerate(faces.ravel().tolist()):
        fans.setdefault(v, set()).add(label[c])
    return [v for v, found in fans.items() if len(found) > 1]


def _genus(faces, count):
    found = topology(faces, count)
    assert found.closed_manifold and found.oriented, found
    assert not _pinched(faces)
    return (2 * found.components - found.euler) // 2, found


def test_a_small_handle_is_cut_out_and_a_thin_finger_is_not():
    """The arch's balls and the finger's are annuli (not disks); cutting the arch's pillar
    leaves one piece and lowers the genus, cutting the finger would split it off and is
    refused. Capped, the surface is a sphere again: one piece, genus 0, Euler characteristic 2
    (a pinched vertex left by the cut would raise it)."""
    vertices, faces = _body_with_an_arch()
    assert _genus(faces, len(vertices))[0] == 1
    euler = ball_euler(faces, len(vertices), 4)
    assert (euler[vertices[:, 2] > 0.95] <= 0).any() and (euler[vertices[:, 2] < -1.0] <= 0).any()
    keep = open_small_handles(vertices, faces, hops=4)
    cut = faces[~keep]
    assert 0 < len(cut) < 0.02 * len(faces)
    assert (vertices[cut].mean(axis=1)[:, 2] > 0.9).all()  # only at the arch
    filled = fill_holes(vertices, faces[keep])
    genus, found = _genus(filled.faces, len(filled.vertices))
    assert genus == 0 and found.components == 1 and found.euler == 2
    assert np.argmin(vertices[:, 2]) in faces[keep]  # the finger's tip is still there


def test_a_surface_of_genus_zero_keeps_every_face():
    sphere = trimesh.creation.icosphere(3)
    assert capped_genus(sphere.faces, len(sphere.vertices)) == 0
    assert (ball_euler(sphere.faces, len(sphere.vertices), 4) == 1).all()
    assert open_small_handles(sphere.vertices, sphere.faces).all()
    holed = sphere.faces[sphere.vertices[sphere.faces].mean(axis=1)[:, 2] < 0.7]
    assert capped_genus(holed, len(sphere.vertices)) == 0  # a hole is not a handle
    assert open_small_handles(sphere.vertices, holed).all()


def test_a_thin_ring_is_a_handle_everywhere_and_opens_into_a_sphere():
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.05, major_sections=64, minor_sections=6)
    count = len(torus.vertices)
    assert capped_genus(torus.faces, count) == 1
    assert (ball_euler(torus.faces, count, 3) == 0).all()  # every ball wraps the tube: an annulus
    keep = open_small_handles(torus.vertices, torus.faces, hops=3)
    filled = fill_holes(torus.vertices, torus.faces[keep])
    genus, found = _genus(filled.faces, len(filled.vertices))
    assert genus == 0 and found.components == 1


def test_two_spheres_touching_at_a_vertex_have_no_handle():
    """A pinch (two fans of faces at one vertex) counts as two vertices: the two spheres are
    genus 0, not a surface of Euler characteristic 3, and nothing is cut."""
    from fourd.geometry.fans import fan_count

    sphere = trimesh.creation.icosphere(2)
    count = len(sphere.vertices)
    other = sphere.faces + count
    other[other == count] = 0  # the second sphere's first vertex is the first sphere's
    faces = np.vstack([sphere.faces, other])
    assert fan_count(sphere.faces) == count and fan_count(faces) == 2 * count
    assert capped_genus(faces, 2 * count) == 0
    assert open_small_handles(np.zeros((2 * count, 3)), faces).all()
    assert _pinched(faces) == [0]
