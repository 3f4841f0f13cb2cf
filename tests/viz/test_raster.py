"""The software rasteriser: coverage, light, depth, texture carried by correspondence, speed."""

import math
import time

import numpy as np
import pytest
import trimesh
from viz_shapes import ink, rotating_sphere

from fourd.animation import MeshSequence
from fourd.errors import InputError
from fourd.viz import raster as R
from fourd.viz import texture as tex
from fourd.viz.camera import Camera, fit_camera


def test_sphere_covers_its_projected_disc():
    s = trimesh.creation.icosphere(4)
    camera = Camera(eye=[0, 0, 5.0], target=[0, 0, 0], fov=30.0)
    image = R.render_mesh(s.vertices, s.faces, camera=camera, width=200, height=200)
    assert image.shape == (200, 200, 3) and image.dtype == np.uint8
    # silhouette of a unit sphere seen from distance 5: angular radius asin(1/5)
    focal = 100 / math.tan(math.radians(15))
    radius_px = focal * math.tan(math.asin(1 / 5))
    area = ink(image).sum()
    assert 0.93 * math.pi * radius_px**2 < area < 1.03 * math.pi * radius_px**2
    ys, xs = np.nonzero(ink(image))
    assert abs(xs.mean() - 99.5) < 1.0 and abs(ys.mean() - 99.5) < 1.0


def test_lit_side_is_brighter_than_the_far_side():
    s = trimesh.creation.icosphere(4)
    camera = Camera(eye=[0, 0, 5.0], target=[0, 0, 0], fov=30.0)
    image = R.render_mesh(
        s.vertices,
        s.faces,
        camera=camera,
        width=200,
        height=200,
        texture="none",
        light=[-1.0, 0.0, 0.3],
    ).astype(float)
    left, right = image[100, 70].sum(), image[100, 130].sum()
    assert left > right + 30


def test_nearer_triangle_wins_the_depth_test():
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    vertices = np.concatenate([square, square * 0.5 + [0, 0, 1.0]])  # smaller square nearer
    faces = np.concatenate([faces, faces + 4])
    colors = np.array([[1.0, 0, 0]] * 4 + [[0, 1.0, 0]] * 4)
    camera = Camera(eye=[0, 0, 6.0], target=[0, 0, 0], fov=40.0)
    for order in (faces, faces[::-1]):  # independent of drawing order
        image = R.render_mesh(
            vertices,
            order,
            camera=camera,
            width=101,
            height=101,
            vertex_colors=colors,
            texture="none",
            ambient=1.0,
        )
        centre, corner = image[50, 50], image[50, 31]
        assert centre[1] > 200 and centre[0] < 30  # green (near)
        assert corner[0] > 200 and corner[1] < 30  # red (far)


def test_checker_is_carried_by_correspondence_but_world_fixed_without_it():
    anim = rotating_sphere(frames=2, degrees=30.0)
    seq = MeshSequence(tuple(anim.frame(i) for i in range(2)))
    camera = fit_camera(anim.bounds())

    def frames_of(result):
        return [
            R.render_mesh(
                result.frame(i)[0],
                result.frame(i)[1],
                camera=camera,
                width=160,
                height=160,
                texture_coords=tex.texture_coordinates(result, i),
            )
            for i in range(2)
        ]

    a0, a1 = frames_of(anim)
    s0, s1 = frames_of(seq)
    changed_anim = np.any(np.abs(a0.astype(int) - a1) > 40, axis=-1).mean()
    changed_seq = np.any(np.abs(s0.astype(int) - s1) > 40, axis=-1).mean()
    assert changed_anim > 0.05  # the rotation shows: checks move with the surface
    assert changed_seq < 0.2 * changed_anim  # world-space checks stay (silhouette is the same)
    # crisp two-tone checks: both check colours appear
    light = np.all(np.abs(a0.astype(float) - tex.CHECK_LIGHT * 255) < 90, axis=-1).sum()
    dark = np.all(np.abs(a0.astype(float) - tex.CHECK_DARK * 255) < 90, axis=-1).sum()
    assert light > 200 and dark > 200


def test_filled_regions_are_tinted_blue():
    s = trimesh.creation.icosphere(3)
    camera = Camera(eye=[0, 0, 5.0], target=[0, 0, 0])
    filled = (s.vertices[:, 1] > 0.3).astype(float)
    plain = R.render_mesh(s.vertices, s.faces, camera=camera, width=120, height=120, texture="none")
    tinted = R.render(
        camera=camera,
        width=120,
        height=120,
        vertices=s.vertices,
        faces=s.faces,
        texture="none",
        filled=filled,
    )
    top, bottom = tinted[35, 60].astype(int), tinted[85, 60].astype(int)
    assert top[2] > top[0] + 40  # blue where filled in
    assert np.array_equal(tinted[85, 60], plain[85, 60])  # untouched where observed
    assert bottom[0] >= bottom[2]


def test_render_points_and_empty_faces():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(500, 3))
    image = R.render_points(pts, width=120, height=100)
    assert image.shape == (100, 120, 3)
    assert 0.01 < ink(image).mean() < 0.6
    as_mesh = R.render_mesh(pts, np.zeros((0, 3), int), width=120, height=100)
    assert ink(as_mesh).any()
    with pytest.raises(InputError):
        R.render_points(np.zeros((0, 3)))


def test_invalid_inputs_raise_input_error():
    s = trimesh.creation.icosphere(1)
    with pytest.raises(InputError, match="faces"):
        R.render_mesh(s.vertices, s.faces + 1000)
    with pytest.raises(InputError, match="vertex_colors"):
        R.render_mesh(s.vertices, s.faces, vertex_colors=np.ones((3, 3)))
    with pytest.raises(InputError, match="texture"):
        R.render_mesh(s.vertices, s.faces, texture="plaid")
    with pytest.raises(InputError, match="width"):
        R.render_mesh(s.vertices, s.faces, width=0)
    with pytest.raises(InputError, match="fov"):
        Camera(eye=[0, 0, 1], target=[0, 0, 0], fov=0.0)


def test_twenty_thousand_faces_render_well_under_a_second():
    s = trimesh.creation.icosphere(5)  # 20480 faces
    assert len(s.faces) >= 20000
    coords = s.vertices * 4
    R.render_mesh(s.vertices, s.faces, texture_coords=coords)  # JIT warm-up (cached on disk)
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        image = R.render_mesh(s.vertices, s.faces, texture_coords=coords, width=512, height=512)
        best = min(best, time.perf_counter() - start)
    assert ink(image).mean() > 0.2
    assert best < 1.0, f"{best:.3f} s for 20k faces at 512^2"
