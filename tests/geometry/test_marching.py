import numpy as np
import trimesh

from fourd.geometry.marching import compact, marching_cubes


def _sphere_field(n=40, radius=0.7):
    g = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    return np.sqrt(x**2 + y**2 + z**2) - radius, g[1] - g[0]


def test_sphere_is_closed_outward_and_has_the_right_volume():
    values, step = _sphere_field()
    vertices, faces = marching_cubes(values, origin=np.full(3, -1.0), spacing=step)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight
    assert abs(mesh.volume - 4 / 3 * np.pi * 0.7**3) < 0.01 * 4 / 3 * np.pi * 0.7**3
    assert np.all(np.abs(np.linalg.norm(vertices, axis=1) - 0.7) < 0.2 * step)


def test_cell_mask_opens_the_surface_where_there_is_no_data():
    values, step = _sphere_field()
    mask = np.ones(np.array(values.shape) - 1, dtype=bool)
    mask[:, :, 20:] = False
    vertices, faces = marching_cubes(values, origin=np.full(3, -1.0), spacing=step, cell_mask=mask)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert not mesh.is_watertight
    assert vertices[:, 2].max() <= -1 + 20 * step + 1e-9


def test_no_crossing_gives_empty_mesh_and_compact_reindexes():
    vertices, faces = marching_cubes(np.ones((4, 4, 4)), origin=np.zeros(3), spacing=1.0)
    assert vertices.shape == (0, 3) and faces.shape == (0, 3)
    v, f = compact(np.arange(15.0).reshape(5, 3), np.array([[4, 2, 0]]))
    assert np.array_equal(f, [[2, 1, 0]]) and np.array_equal(v[:, 0], [0, 6, 12])
