"""fourd learn-material and fourd deform: files in, files out, bad files named."""

import json

import numpy as np
import pytest
from deform_shapes import tube

from fourd import AnimatedMesh, save
from fourd.cli import main
from fourd.deform import Deformer, load_material, rotation_about
from fourd.io.meshfiles import read_obj, write_obj


def test_learn_a_material_from_a_result_and_pose_the_mesh_with_it(tmp_path):
    vertices, faces, start, end = tube(rings=21)
    deformer = Deformer(vertices, faces, anchors=np.r_[start, end])
    poses = np.stack([deformer.pose(np.stack([np.eye(3)] * 12 + [rotation_about([0, 0, 1], a)] * 12))
                      for a in (0.0, 0.3, 0.6)])
    save(AnimatedMesh(faces=faces, vertices=poses, rest=vertices), tmp_path / "result.npz")
    assert main(["learn-material", str(tmp_path / "result.npz"), "-o", str(tmp_path / "m.npz")]) == 0
    material = load_material(tmp_path / "m.npz")
    assert len(material.shearing) == len(faces)

    write_obj(tmp_path / "tube.obj", vertices, faces)
    anchors = {"anchors": [{"face": int(f)} for f in start]
               + [{"face": int(f), "axis": [0, 0, 1], "degrees": 20} for f in end]}
    (tmp_path / "anchors.json").write_text(json.dumps(anchors))
    assert main(["deform", str(tmp_path / "tube.obj"), "--anchors", str(tmp_path / "anchors.json"),
                 "--material", str(tmp_path / "m.npz"), "-o", str(tmp_path / "posed.obj")]) == 0
    posed = read_obj(tmp_path / "posed.obj").vertices
    tip = len(vertices) - 1
    assert posed[tip, 1] > 0.3  # the free end swung up about z
    assert np.allclose(posed[:12], vertices[:12], atol=0.05)  # the start ring stays


@pytest.mark.parametrize(
    "content, message",
    [("{", "not JSON"), ('{"anchors": []}', "nothing to deform"), ('{"anchors": [{"face": 99999}]}', "out of range"),
     ('{"anchors": [{"face": 0, "rotation": [1, 2]}]}', "three numbers")],
)
def test_a_bad_anchors_file_is_named_with_its_problem(tmp_path, capsys, content, message):
    vertices, faces, _, _ = tube(rings=5)
    write_obj(tmp_path / "tube.obj", vertices, faces)
    (tmp_path / "a.json").write_text(content)
    assert main(["deform", str(tmp_path / "tube.obj"), "--anchors", str(tmp_path / "a.json"),
                 "-o", str(tmp_path / "out.obj")]) == 2
    error = capsys.readouterr().err
    assert "a.json" in error and message in error
    assert not (tmp_path / "out.obj").exists()


def test_the_viewer_colours_a_result_by_its_learned_stiffness(tmp_path):
    from fourd.viz.viewer import read_viewer_data

    vertices, faces, start, end = tube(rings=21)
    deformer = Deformer(vertices, faces, anchors=np.r_[start, end])
    poses = np.stack([deformer.pose(np.stack([np.eye(3)] * 12 + [rotation_about([0, 0, 1], a)] * 12))
                      for a in (0.0, 0.5)])
    save(AnimatedMesh(faces=faces, vertices=poses, rest=vertices), tmp_path / "r.npz")
    assert main(["learn-material", str(tmp_path / "r.npz"), "-o", str(tmp_path / "m.npz")]) == 0
    assert main(["view", str(tmp_path / "r.npz"), "--material", str(tmp_path / "m.npz"),
                 "-o", str(tmp_path / "v")]) == 0
    data = read_viewer_data(tmp_path / "v" / "index.html")
    assert data["hasErrors"] and data["errorLabel"].startswith("stiffness")
