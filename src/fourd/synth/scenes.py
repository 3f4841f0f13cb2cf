"""Deforming scenes with exact ground truth.

Every procedural scene starts from a good-quality triangle mesh (an icosphere, a relaxed
marching-cubes capsule, a regular grid) whose vertices are moved analytically per frame, so that
vertex ``i`` is the true correspondence in every frame. The exception is ``splitting-blob``, a
true change of topology that no single connectivity can follow: it is a
:class:`~fourd.MeshSequence` of per-frame iso-surfaces, and correspondence metrics are skipped
for it. The shared scenes (``crane`` ...) are read from the shared data folder
(:mod:`fourd.synth.data`).

Conventions: Y is up; procedural scenes are 1-2 units across, centred near the origin; frame
times are ``0 .. T-1``; the default is 20 frames unless the data decides (the shared scenes);
the result is a deterministic function of the name, the frame count, ``seed`` and the options.

Examples
--------
>>> from fourd.synth.scenes import scene
>>> truth = scene("squash-ball", frames=5)
>>> truth.vertices.shape
(5, 10242, 3)
"""

from __future__ import annotations

import inspect
import logging

import numpy as np
import trimesh

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.geometry.marching import marching_cubes
from fourd.geometry.meshes import vertex_adjacency
from fourd.synth.garments import GARMENT_SCENES, dress, tshirt

logger = logging.getLogger("fourd.synth.scenes")

DEFAULT_FRAMES = 20

#: Scene name -> one-line description.
SCENES: dict[str, str] = {
    "rigid-turn": "a bumpy closed blob turning 120 degrees about a tilted axis (rigid motion)",
    "bending-arm": "a capsule arm with surface detail bending 90 degrees at a joint and twisting 60",
    "touching-spheres": "two spheres approaching, touching (0.3% overlap) and separating",
    "waving-sheet": "an open rectangular sheet with a clamped edge and a travelling wave (isometric)",
    "splitting-blob": "one blob pinching into two (topology change; a MeshSequence, no correspondence)",
    "squash-ball": "a ball squashing and stretching at exactly constant volume",
    "crane": "shared data: a performer's 'crane' motion (Vlasic et al. 2008), every 2nd frame",
    "horse-gallop": "shared data: a galloping horse (Sumner & Popovic 2004), 48 frames",
    "elephant-gallop": "shared data: a galloping elephant (Sumner & Popovic 2004), 48 frames",
    "dfaust-hopping": "shared data: a hopping person, 100,000 corresponding points (Dynamic FAUST)",
    **GARMENT_SCENES,
}

#: Scenes whose every frame is a closed (watertight) surface (``horse-gallop`` has two boundary
#: loops, ``waving-sheet`` one; ``dfaust-hopping`` has no faces).
CLOSED_SCENES = frozenset(
    {
        "rigid-turn",
        "bending-arm",
        "touching-spheres",
        "splitting-blob",
        "squash-ball",
        "crane",
        "elephant-gallop",
    }
)

#: Scenes read from the shared data folder.
SHARED_SCENES = frozenset({"crane", "horse-gallop", "elephant-gallop", "dfaust-hopping"})


# --------------------------------------------------------------------------------------------
# small helpers


def _phases(frames: int) -> np.ndarray:
    """Normalised time ``s`` in [0, 1] per frame, float64 [T]."""
    if frames == 1:
        return np.zeros(1)
    return np.linspace(0.0, 1.0, frames)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix [3, 3] of ``angle`` radians about unit ``axis`` (Rodrigues)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def _numerical_gradient(field, points: np.ndarray, eps: float) -> np.ndarray:
    gradient = np.empty_like(points)
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = eps
        gradient[:, axis] = (field(points + step) - field(points - step)) / (2.0 * eps)
    return gradient


def _project(field, points: np.ndarray, eps: float, iterations: int = 4, gradient_of=None):
    """Newton steps moving ``points`` onto the zero set of ``field``."""
    for _ in range(iterations):
        if gradient_of is None:
            gradient = _numerical_gradient(field, points, eps)
        else:
            gradient = gradient_of(points)
        value = field(points)
        points = points - (value / np.maximum((gradient**2).sum(axis=1), 1e-12))[:, None] * gradient
    return points


def _implicit_mesh(
    field,
    lower: np.ndarray,
    upper: np.ndarray,
    spacing: float,
    *,
    relax: int = 12,
    gradient_of=None,
) -> tuple[np.ndarray, np.ndarray]:
    """A good-quality closed mesh of ``field == 0`` (negative inside).

    Marching cubes on a lattice offset by an irrational fraction of a cell (no iso-values exactly
    on grid points), then ``relax`` rounds of tangential Laplacian smoothing, each followed by
    Newton projection back onto the exact surface, which evens out the marching-cubes slivers.
    ``gradient_of(points) -> [M, 3]`` replaces central differences when given.
    """
    offset = spacing * np.array([0.3183, 0.2718, 0.1414])
    origin = np.asarray(lower, dtype=float) - spacing + offset
    counts = np.ceil((np.asarray(upper) - origin) / spacing).astype(int) + 2
    axes = [origin[i] + spacing * np.arange(counts[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = field(grid).reshape(counts)
    vertices, faces = marching_cubes(values, origin=origin, spacing=spacing)
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    vertices, faces = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)
    eps = 1e-4 * spacing
    adjacency = vertex_adjacency(faces, len(vertices))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    for _ in range(relax):
        delta = adjacency @ vertices / degree[:, None] - vertices
        if gradient_of is None:
            normal = _numerical_gradient(field, vertices, eps)
        else:
            normal = gradient_of(vertices)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        delta -= (delta * normal).sum(axis=1, keepdims=True) * normal
        vertices = _project(field, vertices + 0.5 * delta, eps, 2, gradient_of)
    vertices = _project(field, vertices, eps, 3, gradient_of)
    return vertices, faces


def _grid_sheet(width: float, height: float, nu: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """Regular grid over [0, width] x [0, height] (u, v) with alternating diagonals."""
    u, v = np.meshgrid(np.linspace(0, width, nu), np.linspace(0, height, nv), indexing="ij")
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a = i * nv + j
    b = (i + 1) * nv + j
    c = (i + 1) * nv + j + 1
    d = i * nv + j + 1
    flip = (i + j) % 2 == 1
    first = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    second = np.where(flip[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return uv, np.concatenate([first, second]).astype(np.int64)


# --------------------------------------------------------------------------------------------
# procedural scenes


def _rigid_turn(
    frames: int,
    seed: int,
    *,
    angle: float = 120.0,
    subdivisions: int = 5,
    bumps: int = 10,
    amplitude: float = 0.12,
) -> AnimatedMesh:
    """A bumpy sphere (radius about 0.8) turning ``angle`` degrees about a tilted axis.

    The bumps (a seeded sum of ``bumps`` plane waves on the unit sphere, relative amplitude
    ``amplitude``) make the rotation observable. Radial displacement keeps the mesh watertight
    and free of self-intersections.
    """
    rng = np.random.default_rng(seed)
    directions, faces = _icosphere(subdivisions)
    waves = rng.normal(size=(bumps, 3))
    waves /= np.linalg.norm(waves, axis=1, keepdims=True)
    frequency = rng.uniform(2.0, 6.0, size=bumps)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=bumps)
    weight = rng.uniform(0.5, 1.0, size=bumps)
    bump = (weight * np.cos(frequency * (directions @ waves.T) + phase)).sum(axis=1) / weight.sum()
    rest = 0.8 * directions * (1.0 + amplitude * bump)[:, None]
    axis = np.array([0.3, 1.0, 0.2])
    angles = np.deg2rad(angle) * _phases(frames)
    vertices = np.stack([rest @ _rotation(axis, a).T for a in angles])
    return AnimatedMesh(faces, vertices, rest=rest)


def _arm_field(radius: float, half: float, flatten: float):
    knobs = np.array(
        [
            [0.0, -radius, 0.0],
            [0.55 * half, 0.75 * radius, 0.45 * radius],
            [-0.6 * half, 0.2 * radius, -0.8 * radius],
        ]
    )
    heights = np.array([0.08, 0.05, 0.06])
    widths = np.array([0.12, 0.09, 0.1])

    def field(p: np.ndarray) -> np.ndarray:
        q = np.stack([p[:, 0] - np.clip(p[:, 0], -half, half), p[:, 1], p[:, 2] / flatten], 1)
        value = np.linalg.norm(q, axis=1) - radius
        squared = ((p[:, None, :] - knobs[None]) ** 2).sum(axis=2)
        return value - (heights * np.exp(-squared / widths**2)).sum(axis=1)

    return field


def _bending_arm(
    frames: int,
    seed: int,
    *,
    bend: float = 90.0,
    twist: float = 60.0,
    spacing: float = 0.028,
    joint_width: float = 0.4,
) -> AnimatedMesh:
    """A capsule arm along X (length 2, radius 0.25, slightly flattened, three knobs).

    The joint is at the origin; skinning weights rise smoothly from 0 at ``x = -joint_width`` to
    1 at ``x = +joint_width``. A vertex of weight ``w`` is rotated by ``R_z(w * bend) R_x(w *
    twist)`` (angles blended, not matrices, so there is no candy-wrapper collapse); bend and
    twist grow smoothly from 0 to their final values.
    """
    radius, half = 0.25, 0.75
    field = _arm_field(radius, half, 0.8)
    margin = 0.2
    lower = np.array([-half - radius - margin, -radius - margin, -radius - margin])
    rest, faces = _implicit_mesh(field, lower, -lower, spacing)
    weight = _smoothstep((rest[:, 0] + joint_width) / (2.0 * joint_width))
    s = _smoothstep(_phases(frames))
    vertices = np.empty((frames, len(rest), 3))
    x, y, z = rest.T
    for t in range(frames):
        a = weight * np.deg2rad(twist) * s[t]
        b = weight * np.deg2rad(bend) * s[t]
        y1 = y * np.cos(a) - z * np.sin(a)
        z1 = y * np.sin(a) + z * np.cos(a)
        vertices[t] = np.stack(
            [x * np.cos(b) - y1 * np.sin(b), x * np.sin(b) + y1 * np.cos(b), z1], 1
        )
    return AnimatedMesh(faces, vertices, rest=rest)


def _touching_spheres(
    frames: int,
    seed: int,
    *,
    radius: float = 0.5,
    gap: float = 0.7,
    overlap: float = 0.003,
    subdivisions: int = 4,
) -> AnimatedMesh:
    """Two spheres of ``radius`` on the X axis; their surfaces start ``gap`` apart, close in
    until they overlap by ``overlap`` (relative to the radius) at mid-sequence, and separate."""
    unit, faces = _icosphere(subdivisions)
    sphere = radius * unit
    s = _phases(frames)
    closest = radius * (1.0 - overlap / 2.0)
    half = closest + (radius + gap / 2.0 - closest) * (2.0 * s - 1.0) ** 2
    offset = np.zeros((frames, 1, 3))
    offset[:, 0, 0] = half
    left = sphere[None] - offset
    right = sphere[None] + offset
    faces = np.concatenate([faces, faces + len(sphere)])
    rest_half = radius + gap / 2.0
    rest = np.concatenate([sphere - [rest_half, 0, 0], sphere + [rest_half, 0, 0]])
    return AnimatedMesh(faces, np.concatenate([left, right], axis=1), rest=rest)


def _waving_sheet(
    frames: int,
    seed: int,
    *,
    width: float = 2.0,
    height: float = 1.2,
    wavelength: float = 1.0,
    amplitude: float = 0.15,
    travel: float = 0.75,
    resolution: int = 81,
) -> AnimatedMesh:
    """A vertical sheet (``width`` along X, ``height`` along Y) clamped at its left edge, with a
    travelling wave across it that moves ``travel`` wavelengths over the sequence (not a whole
    one by default, so the last frame differs from the first).

    The displacement ``z = A(x) sin(k x - 2 pi travel s)`` depends on x only, and the material
    coordinate is mapped to x by the arc length of that profile, so the motion is an isometry
    (a bending of a plane): lengths along the surface are preserved exactly.
    """
    nv = max(2, int(round(resolution * height / width)))
    uv, faces = _grid_sheet(width, height, resolution, nv)
    fine = np.linspace(0.0, width, 4097)
    k = 2.0 * np.pi / wavelength
    vertices = np.empty((frames, len(uv), 3))
    for t, s in enumerate(_phases(frames)):
        phase = 2.0 * np.pi * travel * s
        profile = amplitude * (fine / width) * np.sin(k * fine - phase)
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(fine), np.diff(profile)))])
        x = np.interp(uv[:, 0], arc, fine)
        z = amplitude * (x / width) * np.sin(k * x - phase)
        vertices[t] = np.stack([x - width / 2.0, uv[:, 1] - height / 2.0, z], axis=1)
    rest = np.stack([uv[:, 0] - width / 2.0, uv[:, 1] - height / 2.0, np.zeros(len(uv))], 1)
    return AnimatedMesh(faces, vertices, rest=rest)


def _splitting_blob(
    frames: int, seed: int, *, sigma: float = 0.45, separation: float = 0.9, spacing: float = 0.025
) -> MeshSequence:
    """Two Gaussian metaballs (width ``sigma``, iso-level 0.5) moving apart from one centre to
    ``+-separation`` along X: one round body whose neck pinches off at about s = 0.56.

    Each frame is the marching-cubes surface of the analytic field on a fixed lattice, its
    vertices Newton-projected onto the exact iso-surface; connectivity differs per frame.
    """
    level = 0.5
    radius = sigma * np.sqrt(np.log(1.0 / level) + np.log(2.0))
    offsets = separation * _smoothstep(_phases(frames))
    margin = radius + 2.0 * spacing
    lower = np.array([-separation - margin, -margin, -margin])
    meshes = []
    for d in offsets:
        centres = np.array([[-d, 0.0, 0.0], [d, 0.0, 0.0]])

        def field(p, centres=centres):
            squared = ((p[:, None, :] - centres[None]) ** 2).sum(axis=2)
            return level - np.exp(-squared / sigma**2).sum(axis=1)

        def gradient(p, centres=centres):
            offset = p[:, None, :] - centres[None]
            weight = np.exp(-(offset**2).sum(axis=2) / sigma**2)
            return (2.0 / sigma**2) * (weight[:, :, None] * offset).sum(axis=1)

        vertices, faces = _implicit_mesh(
            field, lower, -lower, spacing, relax=4, gradient_of=gradient
        )
        meshes.append((vertices, faces))
    return MeshSequence(tuple(meshes))


def _squash_ball(
    frames: int, seed: int, *, radius: float = 0.6, strength: float = 0.4, subdivisions: int = 5
) -> AnimatedMesh:
    """A ball scaled by ``(1/sqrt(a), a, 1/sqrt(a))`` with ``a = exp(strength sin(2 pi s))``:
    stretching up, then squashing, then back; the determinant is 1, so the enclosed volume is
    exactly constant."""
    unit, faces = _icosphere(subdivisions)
    rest = radius * unit
    a = np.exp(strength * np.sin(2.0 * np.pi * _phases(frames)))
    scale = np.stack([1.0 / np.sqrt(a), a, 1.0 / np.sqrt(a)], axis=1)
    return AnimatedMesh(faces, rest[None] * scale[:, None, :], rest=rest)


def _shared(name: str):
    default_step = 2 if name == "crane" else 1

    def build(frames: int | None, seed: int, *, step: int = default_step, start: int = 0):
        from fourd.synth.data import load_shared

        if step < 0 or start < 0:
            raise InputError(f"scene {name}: step and start must be >= 0, got {step}, {start}")
        full = load_shared(name)
        if step == 0:  # the pose of frame ``start`` held still
            if start >= full.frame_count:
                raise InputError(
                    f"scene {name}: frame {start} asked for but only {full.frame_count} exist"
                )
            count = DEFAULT_FRAMES if frames is None else frames
            held = np.repeat(full.vertices[start : start + 1], count, axis=0)
            return AnimatedMesh(full.faces, held, times=np.arange(len(held), dtype=float))
        available = len(range(start, full.frame_count, step))
        if frames is None:
            frames = min(available, DEFAULT_FRAMES) if name == "crane" else available
        if frames > available:
            raise InputError(
                f"scene {name}: {frames} frames asked for but only {available} exist "
                f"from frame {start} with step {step}"
            )
        vertices = full.vertices[start : start + frames * step : step]
        return AnimatedMesh(full.faces, vertices, times=np.arange(frames, dtype=float))

    return build


_BUILDERS = {
    "rigid-turn": _rigid_turn,
    "bending-arm": _bending_arm,
    "touching-spheres": _touching_spheres,
    "waving-sheet": _waving_sheet,
    "splitting-blob": _splitting_blob,
    "squash-ball": _squash_ball,
    "tshirt": tshirt,
    "dress": dress,
}


def scene_options(name: str) -> dict[str, object]:
    """The options scene ``name`` accepts, with their defaults."""
    if name not in SCENES:
        raise InputError(f"unknown scene {name!r}; known scenes: {', '.join(SCENES)}")
    if name in SHARED_SCENES:
        return {"step": 2 if name == "crane" else 1, "start": 0}
    parameters = inspect.signature(_BUILDERS[name]).parameters.values()
    return {p.name: p.default for p in parameters if p.kind is p.KEYWORD_ONLY}


def scene(
    name: str, *, frames: int | None = None, seed: int = 0, **options
) -> AnimatedMesh | MeshSequence:
    """Ground truth of scene ``name``.

    Parameters
    ----------
    name : str
        One of :data:`SCENES`.
    frames : int, optional
        Number of frames. Procedural scenes: default 20, the motion always spans the whole
        sequence (more frames = finer time steps). Shared scenes: the first ``frames`` frames
        after ``start`` and ``step`` (defaults: ``crane`` 20 frames with step 2, the benchmark
        protocol; the others all their frames); ``step=0`` holds the pose of frame ``start``
        still for ``frames`` frames (default 20), a sequence on which nothing may drift.
    seed : int
        Seed of the scene's random choices (the bumps of ``rigid-turn``; other scenes are fully
        analytic and ignore it).
    **options
        Scene parameters, see :func:`scene_options` (e.g. ``angle`` for ``rigid-turn``,
        ``step`` and ``start`` for the shared scenes).

    Returns
    -------
    AnimatedMesh or MeshSequence
        An :class:`~fourd.AnimatedMesh` (vertex ``i`` is the true correspondence; ``rest`` holds
        the undeformed shape for procedural scenes), except ``splitting-blob``: a
        :class:`~fourd.MeshSequence` (topology changes; correspondence metrics do not apply).

    Raises
    ------
    InputError
        Unknown scene or option, a bad frame count, or missing shared data.
    """
    if name not in SCENES:
        raise InputError(f"unknown scene {name!r}; known scenes: {', '.join(SCENES)}")
    if frames is not None and (int(frames) != frames or frames < 1):
        raise InputError(f"scene {name}: frames must be a positive integer, got {frames!r}")
    valid = scene_options(name)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise InputError(
            f"scene {name}: unknown option(s) {', '.join(unknown)}; valid: {', '.join(valid) or 'none'}"
        )
    if name in SHARED_SCENES:
        return _shared(name)(None if frames is None else int(frames), seed, **options)
    frames = DEFAULT_FRAMES if frames is None else int(frames)
    result = _BUILDERS[name](frames, seed, **options)
    logger.debug("scene %s: %d frames", name, result.frame_count)
    return result
