import numpy as np

from fourd import synth
from fourd.geometry.boundary_loops import boundary_loops
from fourd.methods.garment.fit import FitOptions, fit_template


def _tube(around: int = 48, down: int = 20):
    """An open elliptic tube (radii 0.30 and 0.19, 0.9 high, Y up): vertices, faces, and its
    bottom and top loops."""
    angle = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    height = np.linspace(0.0, 0.9, down)
    a, y = np.meshgrid(angle, height, indexing="ij")
    vertices = np.stack([0.30 * np.cos(a.ravel()), y.ravel(), 0.19 * np.sin(a.ravel())], axis=1)
    i, j = np.meshgrid(np.arange(around), np.arange(down - 1), indexing="ij")
    p = (i * down + j).ravel()
    q = (((i + 1) % around) * down + j).ravel()
    faces = np.concatenate([np.stack([p, q, p + 1], 1), np.stack([q, q + 1, p + 1], 1)]).astype(np.int64)
    return vertices, faces, np.arange(around) * down, np.arange(around) * down + down - 1


def _twisted(vertices: np.ndarray, degrees: float) -> np.ndarray:
    """The tube turned about Y by ``degrees`` at its top, in proportion to the height (its
    bottom still)."""
    turn = np.radians(degrees) * vertices[:, 1] / 0.9
    c, s = np.cos(turn), np.sin(turn)
    x, z = vertices[:, 0], vertices[:, 2]
    return np.stack([c * x + s * z, vertices[:, 1], -s * x + c * z], axis=1)


def _follow_the_tshirt(slide: bool) -> float:
    """The generated T-shirt's first frame (1,478 vertices) fitted onto its next five in turn,
    its hems pulled onto the frames' hems: the largest mean error over the frames, in
    diagonals. The torso twists above a still waist while the arms swing down."""
    truth = synth.scene("tshirt", frames=20, spacing=0.04)
    rest, faces = truth.vertices[0], truth.faces
    hems = boundary_loops(faces, len(rest))
    diagonal = float(np.linalg.norm(np.ptp(truth.vertices.reshape(-1, 3), axis=0)))
    current, worst = rest, 0.0
    for frame in truth.vertices[1:6]:
        current = fit_template(rest, faces, current, frame, faces, openings=[(hem, frame[hem]) for hem in hems],
                               options=FitOptions(slide=slide))
        worst = max(worst, float(np.linalg.norm(current - frame, axis=1).mean()) / diagonal)
    return worst


def test_a_twisting_garment_is_followed_when_the_fabric_slides_along_the_data():
    """Held to the closest points themselves, the fit stops where it entered each frame (on
    the surface, slid: 0.027); held only across the surface and across its hems, it follows
    the twist and the swing (0.0047)."""
    sliding, held = _follow_the_tshirt(True), _follow_the_tshirt(False)
    assert sliding < 0.007
    assert held > 3 * sliding


def test_index_matched_opening_goals_carry_a_loop_round():
    """An opening's vertices pulled to their own points (``opening_goals``) turn the tube's top
    with them (the top turns 0.05 at its widest); pulled onto the closest points of the loop
    they slide along it."""
    rest, faces, bottom, top = _tube(around=32, down=10)
    frame = _twisted(rest, 10.0)
    matched = fit_template(rest, faces, rest, frame, faces, openings=[(bottom, frame[bottom])],
                           opening_goals=[(top, frame[top])])
    closest = fit_template(rest, faces, rest, frame, faces, openings=[(bottom, frame[bottom]), (top, frame[top])])
    assert np.linalg.norm(matched[top] - frame[top], axis=1).max() < 0.01
    assert np.linalg.norm(closest[top] - frame[top], axis=1).max() > 0.02
