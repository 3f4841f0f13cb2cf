
import numpy as np
import pytest
import trimesh
from PIL import Image
from viz_shapes import ink, rotating_sphere

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence
from fourd.viz import render as R


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
