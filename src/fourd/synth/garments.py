"""Garment truth scenes (issue 54): a T-shirt and a dress worn by a moving body, with dynamic
folds, and the flat pattern each is cut from.

Like every procedural scene, a garment starts from one good-quality mesh (its rest shape) whose
vertices move analytically per frame, so vertex ``i`` is the true correspondence in every
frame. The body is not part of the scene (only the garment is scanned); its motion is what
moves the garment:

- ``tshirt``: a torso tube with two sleeves (the smooth union of a rounded elliptic cylinder and
  a horizontal capsule, marching-cubed and relaxed), cut open at the neck, the waist and both
  sleeve ends: four boundary loops. The arms swing down and up about the shoulders (the sleeves
  close on the torso, hiding the underarms), the upper body twists and sways. Folds: rings
  around the sleeves that come and go with the arms, diagonal twist folds across the lower
  torso that follow the twist.
- ``dress``: a flared elliptic tube from the waist to the hem (a regular grid around and down):
  two boundary loops. The skirt twirls and swings, increasingly towards the hem, and vertical
  flutes travel around it.

The folds are displacements along the rest surface's normal made before the pose is applied,
so they deform with the garment; their depth is given as a fraction of the scene's bounding-box
diagonal (``fold_depth``) so that "folds deeper than 0.5% of the diagonal" can be asked of the
truth. :func:`pattern_outline` gives the flat outline of each garment laid out (the photo that
the thesis' section 3.7 builds its template from), in the garment's units.

Conventions as in :mod:`fourd.synth.scenes`: Y up, about 1-1.5 units across, frame times
``0 .. T-1``.
"""

from __future__ import annotations

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.geometry.normals import vertex_normals

__all__ = ["GARMENT_SCENES", "PHOTO_PIXELS_PER_UNIT", "dress", "pattern_outline", "pattern_photo", "tshirt"]

#: Resolution of the garment's photo (:func:`pattern_photo`), pixels per garment unit.
PHOTO_PIXELS_PER_UNIT = 400

#: Garment scene name -> one-line description.
GARMENT_SCENES: dict[str, str] = {
    "tshirt": "a T-shirt on a moving body: arms swinging, torso twisting, folds coming and going "
    "(four boundary loops)",
    "dress": "a flared dress twirling and swinging, flutes travelling around it (two boundary loops)",
}

# the T-shirt's shape (rest pose, Y up, the shirt facing +Z)
_TORSO_RADII = (0.30, 0.19)  # x, z of the torso's elliptic cross-section
_TORSO_TOP = 0.30
_WAIST = -0.55
_SLEEVE_HEIGHT = 0.20
_SLEEVE_RADIUS = 0.11
_SLEEVE_END = 0.58
_SHOULDER = 0.30  # |x| of the shoulder pivots (the torso's side)
_NECK_RADII = (0.13, 0.10)
_NECK_BELOW = 0.12  # the neck cut removes faces above this height inside the neck ellipse

# the dress's shape
_DRESS_WAIST, _DRESS_HEM = 0.35, -0.55
_DRESS_WAIST_RADIUS, _DRESS_FLARE = 0.16, 0.28
_DRESS_DEPTH = 0.8  # z radius / x radius


def _smooth_min(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def _smooth_max(a, b, k):
    return -_smooth_min(-a, -b, k)


def _tshirt_field(points: np.ndarray) -> np.ndarray:
    """Approximate signed distance of the T-shirt's closed body (torso and arms, uncut)."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    rx, rz = _TORSO_RADII
    across = (np.sqrt((x / rx) ** 2 + (z / rz) ** 2) - 1.0) * min(rx, rz)
    centre, half = 0.5 * (_TORSO_TOP + _WAIST - 0.2), 0.5 * (_TORSO_TOP - _WAIST + 0.2)
    torso = _smooth_max(across, np.abs(y - centre) - half, 0.06)
    along = np.clip(x, -_SLEEVE_END - 0.12, _SLEEVE_END + 0.12)
    arms = np.sqrt((x - along) ** 2 + (y - _SLEEVE_HEIGHT) ** 2 + z**2) - _SLEEVE_RADIUS
    return _smooth_min(torso, arms, 0.05)


def _cut(vertices: np.ndarray, faces: np.ndarray, removed: np.ndarray):
    """The mesh without the faces ``removed`` (bool [F]) and the vertices only they used."""
    kept = faces[~removed]
    used = np.unique(kept)
    index = np.full(len(vertices), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return vertices[used], index[kept]


def _tshirt_rest(spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The T-shirt's rest mesh ``(vertices [N, 3], faces [F, 3])``, four boundary loops."""
    from fourd.geometry.boundary_loops import boundary_loops
    from fourd.geometry.meshes import remove_small_components, vertex_adjacency
    from fourd.synth.scenes import _implicit_mesh, _numerical_gradient, _project

    reach = _SLEEVE_END + 0.25
    lower = np.array([-reach, _WAIST - 0.3, -0.3])
    upper = np.array([reach, _TORSO_TOP + 0.2, 0.3])
    vertices, faces = _implicit_mesh(_tshirt_field, lower, upper, spacing)
    centres = vertices[faces].mean(axis=1)
    nx, nz = _NECK_RADII
    neck = (centres[:, 1] > _NECK_BELOW) & ((centres[:, 0] / nx) ** 2 + (centres[:, 2] / nz) ** 2 < 1)
    removed = (centres[:, 1] < _WAIST) | (np.abs(centres[:, 0]) > _SLEEVE_END) | neck
    vertices, faces = _cut(vertices, faces, removed)
    vertices, faces = remove_small_components(vertices, faces, min_fraction=0.05)
    vertices, faces = _without_ears(vertices, faces)
    # the cut edges follow the triangles: put their vertices on the cutting surfaces, then even
    # out the triangles along them (boundary vertices along their loop, the rings inside them
    # tangentially, kept on the shirt's surface)
    loops = boundary_loops(faces, len(vertices))
    kinds = []
    for loop in loops:
        ring = vertices[loop]
        if np.all(ring[:, 1] < _WAIST + 2 * spacing):
            kinds.append("waist")
        elif np.all(np.abs(ring[:, 0]) > _SLEEVE_END - 2 * spacing):
            kinds.append("sleeve")
        else:
            kinds.append("neck")

    def snap():
        for loop, kind in zip(loops, kinds, strict=True):
            ring = vertices[loop]
            if kind == "waist":
                vertices[loop, 1] = _WAIST
            elif kind == "sleeve":
                vertices[loop, 0] = np.sign(ring[:, 0]) * _SLEEVE_END
            else:  # radially onto the neck's elliptic cylinder
                scale = np.sqrt((ring[:, 0] / nx) ** 2 + (ring[:, 2] / nz) ** 2)
                vertices[loop, 0] /= scale
                vertices[loop, 2] /= scale

    adjacency = vertex_adjacency(faces, len(vertices))
    on_boundary = np.zeros(len(vertices), dtype=bool)
    on_boundary[np.concatenate(loops)] = True
    near = on_boundary.copy()
    for _ in range(3):
        near |= (adjacency @ near.astype(float)) > 0
    inner = np.flatnonzero(near & ~on_boundary)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    eps = 1e-4 * spacing
    snap()
    for _ in range(10):
        for loop in loops:
            vertices[loop] = 0.5 * vertices[loop] + 0.25 * (np.roll(vertices[loop], 1, 0) + np.roll(vertices[loop], -1, 0))
        snap()
        delta = (adjacency @ vertices)[inner] / degree[inner, None] - vertices[inner]
        normal = _numerical_gradient(_tshirt_field, vertices[inner], eps)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        delta -= (delta * normal).sum(axis=1, keepdims=True) * normal
        vertices[inner] = _project(_tshirt_field, vertices[inner] + 0.5 * delta, eps, 2)
    return vertices, faces


def _without_ears(vertices: np.ndarray, faces: np.ndarray):
    """The mesh without the faces that have two sides on the boundary (ears of a cut: once
    their corners are put on the cutting surface they would be flat)."""
    from fourd.geometry.boundary_loops import boundary_edges

    for _ in range(10):
        edges = boundary_edges(faces, len(vertices))
        keys = set(map(tuple, np.sort(edges, axis=1).tolist()))
        sides = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=2), axis=2)
        on = np.array([[tuple(side) in keys for side in face] for face in sides.tolist()])
        ears = on.sum(axis=1) >= 2
        if not ears.any():
            break
        vertices, faces = _cut(vertices, faces, ears)
    return vertices, faces


def _rotation_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rotation_y(angles):
    """Rotations about Y, ``[M, 3, 3]`` for ``angles [M]``."""
    c, s = np.cos(angles), np.sin(angles)
    zero, one = np.zeros_like(angles), np.ones_like(angles)
    return np.stack([np.stack([c, zero, s], -1), np.stack([zero, one, zero], -1), np.stack([-s, zero, c], -1)], 1)


def tshirt(
    frames: int,
    seed: int,
    *,
    arm_swing: float = 35.0,
    twist: float = 20.0,
    fold_depth: float = 0.008,
    spacing: float = 0.02,
) -> AnimatedMesh:
    """The T-shirt scene (see the module docstring). ``arm_swing`` and ``twist`` are degrees
    (the arms swing from 10 degrees below horizontal down by ``arm_swing`` and back, twice; the
    upper body twists by up to ``twist``), ``fold_depth`` is the folds' amplitude as a fraction
    of the bounding-box diagonal, ``spacing`` the rest mesh's edge length."""
    from fourd.synth.scenes import _phases, _smoothstep

    rest, faces = _tshirt_rest(spacing)
    normals = vertex_normals(rest, faces)
    diagonal = float(np.linalg.norm(np.ptp(rest, axis=0)))
    depth = fold_depth * diagonal
    x, y, z = rest[:, 0], rest[:, 1], rest[:, 2]
    side = np.sign(x)
    # how much each vertex follows its arm: beyond the torso's side, and only above the armpit
    armpit = _SLEEVE_HEIGHT - _SLEEVE_RADIUS - 0.06
    sleeve = _smoothstep((np.abs(x) - (_SHOULDER - 0.03)) / 0.10) * _smoothstep((y - armpit) / 0.08)
    around = np.arctan2(z / _TORSO_RADII[1], x / _TORSO_RADII[0])  # radians around the torso
    lower_torso = (1 - sleeve) * _smoothstep(np.clip((0.05 - y) / 0.25, 0.0, 1.0)) * _smoothstep(
        np.clip((y - _WAIST) / 0.08, 0.0, 1.0)
    )
    sleeve_band = sleeve * _smoothstep(np.clip((_SLEEVE_END - 0.03 - np.abs(x)) / 0.06, 0.0, 1.0))
    height = (y - _WAIST) / (_TORSO_TOP - _WAIST)
    vertices = np.empty((frames, len(rest), 3))
    for t, s in enumerate(_phases(frames)):
        swing = 0.5 - 0.5 * np.cos(4 * np.pi * s)  # 0 -> 1 -> 0, twice
        turn = np.sin(2 * np.pi * s)
        ring_folds = swing * sleeve_band * np.sin(2 * np.pi * (np.abs(x) - _SHOULDER) / 0.075)
        # a whole number of diagonal folds around the torso, leaning with the twist
        twist_folds = abs(turn) * lower_torso * np.sin(11 * around + np.sign(turn) * 2 * np.pi * 0.8 * y / 0.14)
        folded = rest + (depth * (ring_folds + twist_folds))[:, None] * normals
        # the arms about their shoulders, blended over the shoulder (linear blend skinning)
        angle = np.radians(-10.0 - arm_swing * swing)
        posed = folded.copy()
        for sign in (-1.0, 1.0):
            pivot = np.array([sign * _SHOULDER, _SLEEVE_HEIGHT, 0.0])
            rotated = (folded - pivot) @ _rotation_z(sign * angle).T + pivot
            weight = np.where(side == sign, sleeve, 0.0)[:, None]
            posed = posed * (1 - weight) + rotated * weight
        # the upper body twists about Y, more towards the shoulders, and the body sways
        rotations = _rotation_y(np.radians(twist * turn) * np.clip(height, 0.0, 1.2))
        posed = np.einsum("nij,nj->ni", rotations, posed)
        posed[:, 0] += 0.04 * np.sin(2 * np.pi * s)
        vertices[t] = posed
    return AnimatedMesh(faces, vertices, rest=rest)


def _dress_rest(around: int, down: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The dress's rest grid: vertices, faces, angle around [N] and fraction down [N]."""
    angle = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    fraction = np.linspace(0.0, 1.0, down)
    a, f = np.meshgrid(angle, fraction, indexing="ij")
    a, f = a.ravel(), f.ravel()
    radius = _DRESS_WAIST_RADIUS + _DRESS_FLARE * f**1.3
    y = _DRESS_WAIST + (_DRESS_HEM - _DRESS_WAIST) * f
    vertices = np.stack([radius * np.cos(a), y, -_DRESS_DEPTH * radius * np.sin(a)], axis=1)
    i, j = np.meshgrid(np.arange(around), np.arange(down - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    p = i * down + j
    q = ((i + 1) % around) * down + j
    faces = np.concatenate([np.stack([p, p + 1, q], 1), np.stack([q, p + 1, q + 1], 1)]).astype(np.int64)
    return vertices, faces, a, f


def dress(
    frames: int,
    seed: int,
    *,
    twirl: float = 30.0,
    swing: float = 0.08,
    flutes: int = 8,
    fold_depth: float = 0.012,
    around: int = 120,
    down: int = 48,
) -> AnimatedMesh:
    """The dress scene (see the module docstring): ``twirl`` degrees of turn at the hem,
    ``swing`` units of sideways swing at the hem, ``flutes`` vertical folds around it whose
    depth at the hem is ``fold_depth`` of the bounding-box diagonal, travelling half a flute
    around over the sequence; ``around`` x ``down`` grid vertices."""
    from fourd.synth.scenes import _phases

    rest, faces, angle, fraction = _dress_rest(around, down)
    normals = vertex_normals(rest, faces)
    # outward: the grid's winding decides; make the normals point away from the axis
    outward = np.einsum("nj,nj->n", normals, rest * [1, 0, 1]) >= 0
    normals[~outward] *= -1
    diagonal = float(np.linalg.norm(np.ptp(rest, axis=0)))
    depth = fold_depth * diagonal
    vertices = np.empty((frames, len(rest), 3))
    for t, s in enumerate(_phases(frames)):
        phase = np.sin(2 * np.pi * s)
        wave = np.sin(flutes * angle - np.pi * s) * fraction**1.5 * (0.6 + 0.4 * abs(phase))
        folded = rest + (depth * wave)[:, None] * normals
        posed = np.einsum("nij,nj->ni", _rotation_y(np.radians(twirl * phase) * fraction**2), folded)
        posed[:, 0] += swing * fraction**2 * np.sin(2 * np.pi * s + 0.5)
        vertices[t] = posed
    return AnimatedMesh(faces, vertices, rest=rest)


def pattern_outline(name: str, *, with_openings: bool = False):
    """The flat outline ``[K, 2]`` (x right, y up, garment units, counter-clockwise) of garment
    ``name`` laid out flat, front on top of back: each tube flattened to half its girth (the
    photo of section 3.7). An approximation from the garment's analytic parts: the torso and
    the sleeves as rectangles of half their girth, a neck notch, the dress a trapezoid.
    With ``with_openings``, also the openings (the garment's boundaries, where front and back
    are not sewn together): a list of polylines ``[M, 2]`` along the outline (the user's brush
    strokes of section 3.7)."""
    if name == "tshirt":
        rx, rz = _TORSO_RADII
        h = ((rx - rz) / (rx + rz)) ** 2
        girth = np.pi * (rx + rz) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))
        half = 0.25 * girth  # half the torso's flat width
        sleeve = 0.5 * np.pi * _SLEEVE_RADIUS  # the sleeve's flat width
        top, bottom = _TORSO_TOP, _WAIST
        reach = half + (_SLEEVE_END - _SHOULDER)
        neck = np.linspace(0.0, np.pi, 17)
        notch = np.stack([_NECK_RADII[0] * np.cos(neck), top - 0.6 * _NECK_RADII[1] * np.sin(neck)], 1)
        right = [[half, bottom], [half, top - 2 * sleeve], [reach, top - 2 * sleeve], [reach, top]]
        left = [[-reach, top], [-reach, top - 2 * sleeve], [-half, top - 2 * sleeve], [-half, bottom]]
        outline = np.concatenate([right, notch, left]).astype(np.float64)
        openings = [outline[[-1, 0]], outline[2:4], notch, outline[-4:-2]]  # waist, sleeves, neck
        return (outline, openings) if with_openings else outline
    if name == "dress":
        def half_girth(radius):
            a, b = radius, _DRESS_DEPTH * radius
            h = ((a - b) / (a + b)) ** 2
            return 0.5 * np.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))

        fraction = np.linspace(0.0, 1.0, 13)
        y = _DRESS_WAIST + (_DRESS_HEM - _DRESS_WAIST) * fraction
        width = np.array([half_girth(_DRESS_WAIST_RADIUS + _DRESS_FLARE * f**1.3) for f in fraction])
        right = np.stack([0.5 * width, y], 1)[::-1]
        left = np.stack([-0.5 * width, y], 1)
        outline = np.concatenate([right, left]).astype(np.float64)
        openings = [outline[[len(right) - 1, len(right)]], outline[[-1, 0]]]  # waist, hem
        return (outline, openings) if with_openings else outline
    raise ValueError(f"no pattern for {name!r}; garments: {', '.join(GARMENT_SCENES)}")


def pattern_photo(outline: np.ndarray, openings=None, *, pixels_per_unit: float = PHOTO_PIXELS_PER_UNIT,
                  margin: float = 0.05):
    """The photo of a garment laid out flat: ``(image uint8 [H, W], calibration)``, white
    garment on black, and a JSON-able dict with ``pixels_per_unit``, ``origin`` (garment
    coordinates of the top-left pixel's centre; image rows go down, y up), the ``outline`` and
    the ``openings`` (polylines in garment units, when given).
    """
    import cv2

    outline = np.asarray(outline, dtype=np.float64)
    lower, upper = outline.min(axis=0) - margin, outline.max(axis=0) + margin
    width, height = np.ceil((upper - lower) * pixels_per_unit).astype(int) + 1
    origin = np.array([lower[0], upper[1]])
    pixels = np.empty_like(outline)
    pixels[:, 0] = (outline[:, 0] - origin[0]) * pixels_per_unit
    pixels[:, 1] = (origin[1] - outline[:, 1]) * pixels_per_unit
    image = np.zeros((height, width), dtype=np.uint8)
    cv2.fillPoly(image, [np.rint(pixels * 16).astype(np.int32)], 255, lineType=cv2.LINE_AA, shift=4)
    calibration = {"pixels_per_unit": float(pixels_per_unit), "origin": origin.tolist(), "outline": outline.tolist()}
    if openings is not None:
        calibration["openings"] = [np.asarray(o, dtype=np.float64).tolist() for o in openings]
    return image, calibration
