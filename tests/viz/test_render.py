import math
import time

import numpy as np
import pytest
import trimesh
from PIL import Image

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence
from fourd.viz import render as R
from fourd.viz import texture as tex

WHITE = np.array(R.BACKGROUND)


def ink(image):
    """Mask of pixels that are not background."""
    return np.any(image != WHITE, axis=-1)


def rotating_sphere(frames=3, degrees=40.0, subdivisions=3):
    s = trimesh.creation.icosphere(subdivisions)
    out = []
    for t in range(frames):
        a = math.radians(degrees * t)
        rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
        out.append(s.vertices @ rot.T)
    return AnimatedMesh(s.faces, np.stack(out))


def test_sphere_covers_its_projected_disc():
    s = trimesh.creation.icosphere(4)
    camera = R.Camera(eye=[0, 0, 5.0], target=[0, 0, 0], fov=30.0)
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
    camera = R.Camera(eye=[0, 0, 5.0], target=[0, 0, 0], fov=30.0)
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
    camera = R.Camera(eye=[0, 0, 6.0], target=[0, 0, 0], fov=40.0)
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


def test_fit_camera_keeps_the_whole_box_in_view_and_fills_it():
    bounds = np.array([[-2.0, 0.0, -0.5], [3.0, 1.0, 0.5]])
    corners = np.array(
        [[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]]
    )
    for azimuth in (0.0, 35.0, 90.0, 200.0):
        camera = R.fit_camera(bounds, azimuth=azimuth)
        xy, depth = camera.project(corners, 300, 300)
        assert np.all(depth > 0)
        assert np.all((xy >= 0) & (xy <= 300))
        extent = (xy.max(axis=0) - xy.min(axis=0)).max()
        assert extent > 0.6 * 300


def test_checker_is_carried_by_correspondence_but_world_fixed_without_it():
    anim = rotating_sphere(frames=2, degrees=30.0)
    seq = MeshSequence(tuple(anim.frame(i) for i in range(2)))
    camera = R.fit_camera(anim.bounds())

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
    camera = R.Camera(eye=[0, 0, 5.0], target=[0, 0, 0])
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
        R.Camera(eye=[0, 0, 1], target=[0, 0, 0], fov=0.0)


def test_pick_frames():
    assert R.pick_frames(20) == [0, 3, 5, 8, 11, 14, 16, 19]
    assert R.pick_frames(3) == [0, 1, 2]
    assert R.pick_frames(10, [0, -1]) == [0, 9]
    with pytest.raises(InputError, match="out of range"):
        R.pick_frames(4, [4])


def test_contact_sheet_layout_and_errors(tmp_path):
    anim = rotating_sphere(frames=6)
    observed = np.ones((6, anim.vertex_count), bool)
    observed[:, anim.vertices[0, :, 1] > 0.5] = False
    anim = AnimatedMesh(anim.faces, anim.vertices, observed=observed)
    path = R.contact_sheet(anim, tmp_path / "sheet.png", columns=3, tile=96)
    with Image.open(path) as im:
        width, height = im.size
    assert width == 3 * 96 and height > 2 * 96  # 2 rows under a header
    truth = AnimatedMesh(anim.faces, anim.vertices * 1.05)
    err = R.contact_sheet(
        anim, tmp_path / "err.png", truth=truth, error_colors=True, tile=96, frames=[0, 5]
    )
    assert err.exists()
    with pytest.raises(InputError, match="truth"):
        R.contact_sheet(anim, tmp_path / "x.png", error_colors=True)


def test_contact_sheet_of_mesh_sequence_with_input_points(tmp_path):
    anim = rotating_sphere(frames=3)
    seq = MeshSequence(tuple(anim.frame(i) for i in range(3)))
    scans = PointCloudSequence.from_arrays([v[::5] * 1.01 for v in anim.vertices])
    path = R.contact_sheet(seq, tmp_path / "seq.png", input=scans, tile=80, texture="grid")
    with Image.open(path) as im:
        assert im.size[0] == 3 * 80


def test_bench_sheet_turntable_and_gif(tmp_path):
    anim = rotating_sphere(frames=4)
    assert R.bench_sheet(anim, anim, tmp_path / "bench.png", title="scene / method").exists()
    grid = R.turntable(anim, tmp_path / "turn.png", views=4, tile=64)
    with Image.open(grid) as im:
        assert im.size[0] == 4 * 64
    gif = R.render_animation(anim, tmp_path / "anim.gif", size=64)
    with Image.open(gif) as im:
        assert im.n_frames == 4
    turn = R.turntable(anim, tmp_path / "turn.gif", views=5, tile=48)
    with Image.open(turn) as im:
        assert im.n_frames == 5
    with pytest.raises(InputError, match=r"\.gif or \.mp4"):
        R.render_animation(anim, tmp_path / "anim.avi")


def test_mp4_needs_imageio_ffmpeg(tmp_path):
    anim = rotating_sphere(frames=3)
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        with pytest.raises(InputError, match="imageio-ffmpeg"):
            R.render_animation(anim, tmp_path / "a.mp4", size=64)
    else:
        path = R.render_animation(anim, tmp_path / "a.mp4", size=64)
        assert path.stat().st_size > 0


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


def test_point_animation_and_empty_first_frame(tmp_path):
    s = trimesh.creation.icosphere(2)
    points = AnimatedMesh(
        np.zeros((0, 3), int), np.stack([s.vertices + [0.2 * t, 0, 0] for t in range(3)])
    )
    path = R.contact_sheet(points, tmp_path / "points.png", tile=96)
    with Image.open(path) as im:
        tiles = np.asarray(im.convert("RGB"))[-96:]
    assert ink(tiles).mean() > 0.02  # the points are drawn, big enough to see
    empty = (np.zeros((0, 3)), np.zeros((0, 3), int))
    seq = MeshSequence((empty, (s.vertices, s.faces), (s.vertices * 1.2, s.faces)))
    assert R.contact_sheet(seq, tmp_path / "seq.png", tile=64).exists()
