"""The garment truth scenes (issue 54): boundary loops, folds that come and go, the photo."""

import json

import numpy as np
import pytest
from PIL import Image

from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.meshes import face_areas
from fourd.synth.garments import pattern_outline, pattern_photo
from fourd.synth.scenes import scene
from fourd.synth.write import write_synth


@pytest.mark.parametrize("name, loops", [("tshirt", 4), ("dress", 2)])
def test_every_frame_has_the_garments_boundary_loops(name, loops):
    truth = scene(name, frames=5)
    assert len(boundary_loops(truth.faces, truth.vertex_count)) == loops  # one connectivity


@pytest.mark.parametrize("name", ["tshirt", "dress"])
def test_folds_come_and_go_deeper_than_half_a_percent_of_the_diagonal(name):
    folded, smooth = scene(name, frames=9), scene(name, frames=9, fold_depth=0.0)
    diagonal = folded.diagonal()
    depth = np.linalg.norm(folded.vertices - smooth.vertices, axis=2).max(axis=1) / diagonal
    assert depth.max() > 0.005
    if name == "tshirt":  # arms up and the body straight: no folds in the first frame
        assert depth[0] < 1e-9 and depth[2] > 0.005


@pytest.mark.parametrize("name", ["tshirt", "dress"])
def test_the_photo_is_the_garment_laid_flat(name, tmp_path):
    truth = scene(name, frames=1)
    outline = pattern_outline(name)
    x, y = outline[:, 0], outline[:, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    assert area > 0  # counter-clockwise
    # front and back laid on each other: twice the outline is the garment's area
    assert abs(2 * area / face_areas(truth.rest, truth.faces).sum() - 1) < 0.1
    image, calibration = pattern_photo(outline)
    white = (image.astype(float) / 255).sum() / calibration["pixels_per_unit"] ** 2
    assert abs(white / area - 1) < 0.02


def test_synth_writes_the_photo_beside_the_scans(tmp_path):
    from fourd import synth

    truth = scene("dress", frames=2, around=40, down=16)
    scans = synth.scan(truth, resolution=48)
    write_synth(truth, scans, tmp_path / "dress", pattern=pattern_outline("dress", with_openings=True))
    image = np.asarray(Image.open(tmp_path / "dress" / "pattern.png"))
    calibration = json.loads((tmp_path / "dress" / "pattern.json").read_text())
    assert image.ndim == 2 and image.max() == 255
    assert np.allclose(calibration["outline"], pattern_outline("dress"))
    assert len(calibration["openings"]) == 2  # the waist and the hem
