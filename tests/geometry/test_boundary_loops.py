import numpy as np

from fourd.geometry.boundary_loops import boundary_edges, boundary_loops


def test_an_open_tube_has_two_loops_in_order_and_a_closed_mesh_none():
    around = 10
    t = np.linspace(0, 2 * np.pi, around, endpoint=False)
    vertices = np.concatenate([np.column_stack([np.cos(t), np.sin(t), np.full(around, h)]) for h in (0, 1)])
    faces = []
    for i in range(around):
        a, b = i, (i + 1) % around
        faces += [[a, b, b + around], [a, b + around, a + around]]
    loops = boundary_loops(np.array(faces), len(vertices))
    assert len(loops) == 2 and all(len(loop) == around for loop in loops)
    for loop in loops:  # consecutive loop vertices are joined by a boundary edge
        edges = {tuple(e) for e in boundary_edges(np.array(faces), len(vertices))}
        assert all((int(a), int(b)) in edges for a, b in zip(loop, np.roll(loop, -1), strict=True))
    tetrahedron = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]])
    assert boundary_loops(tetrahedron, 4) == []


def test_two_triangles_touching_at_a_vertex_give_two_loops():
    faces = np.array([[0, 1, 2], [0, 3, 4]])  # a bow tie at vertex 0
    loops = boundary_loops(faces, 5)
    assert sorted(len(loop) for loop in loops) == [3, 3]
    assert sum(len(loop) for loop in loops) == len(boundary_edges(faces, 5))
