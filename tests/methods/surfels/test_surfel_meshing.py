"""Meshing the surfels (sec. 3.3): a sphere of exact surfels meshes to a closed surface close
to the sphere, a square patch to an open patch clipped at its border; the reference mesh is
carried rigidly by a rigid motion, smoothly by a bend, and the observed flags follow the
surfels'."""

import numpy as np
import pytest

from fourd.geometry.meshes import face_adjacency, vertex_components
from fourd.methods.surfels import sample_surfels, surfel_state
from fourd.methods.surfels.meshing import (
    MeshingOptions,
    bind_vertices,
    carry,
    mesh_frame,
    surfel_frames,
    surfel_mesh,
)

EPS = 0.1


def _sphere(count, radius=1.0):
    """Fibonacci points on a sphere and their outward normals."""
    i = np.arange(count) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / count)
    azimuth = np.pi * (1.0 + np.sqrt(5.0)) * i
    normals = np.stack(
        [np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1
    )
    return radius * normals, normals


def _patch(half=1.0, spacing=EPS):
    g = np.arange(-half, half + 1e-9, spacing)
    x, y = np.meshgrid(g, g, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    return points, np.tile([0.0, 0.0, 1.0], (len(points), 1))


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def _rotations_y(angles):
    """Rotations about y [..., 3, 3] by ``angles`` [...]."""
    c, s = np.cos(angles), np.sin(angles)
    out = np.zeros(np.shape(angles) + (3, 3))
    out[..., 0, 0], out[..., 0, 2], out[..., 1, 1] = c, s, 1.0
    out[..., 2, 0], out[..., 2, 2] = -s, c
    return out


def _bend(points, radius):
    """The plane z = 0 rolled onto the cylinder of ``radius`` about the axis (0, y, radius):
    positions, normals and the rotation about y of each point."""
    angle = points[:, 0] / radius
    bent = np.stack([radius * np.sin(angle), points[:, 1], radius * (1.0 - np.cos(angle))], axis=1)
    turn = _rotations_y(-angle)  # the x axis onto the tangent (cos, 0, sin)
    return bent, turn[:, :, 2], turn


def test_sphere_meshes_closed_and_close_to_the_sphere():
    positions, normals = _sphere(int(4 * np.pi / EPS**2))
    mesh = mesh_frame(positions, normals, EPS)
    radius = np.linalg.norm(mesh.vertices, axis=1)
    # the blend of tangent planes moves a sphere outwards by about sigma^2 / R (0.052-0.061)
    assert np.abs(radius - 1.0).max() < 0.1 * EPS
    assert radius.min() > 1.0
    # watertight and consistently oriented: every directed edge once, its twin once
    directed = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len(np.unique(directed, axis=0)) == len(directed)
    assert set(map(tuple, directed)) == set(map(tuple, directed[:, ::-1]))
    assert len(face_adjacency(mesh.faces)[0]) * 2 == len(directed)
    assert vertex_components(mesh.faces, len(mesh.vertices))[0] == 1
    euler = len(mesh.vertices) - len(directed) // 2 + len(mesh.faces)
    assert euler == 2
    # outward: the triangles' normals agree with the radial direction
    v = mesh.vertices[mesh.faces]
    face_normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert np.all(np.einsum("ij,ij->i", face_normals, v.mean(axis=1)) > 0)
    assert mesh.support.min() >= MeshingOptions().clip


def test_irregular_surfels_on_a_sphere_mesh_closed():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(30000, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    surfels = points[sample_surfels(points, EPS)]
    mesh = mesh_frame(surfels, surfels, EPS)
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert vertex_components(mesh.faces, len(mesh.vertices))[0] == 1
    radius = np.linalg.norm(mesh.vertices, axis=1)
    assert 0.0 < radius.min() - 1.0 and radius.max() - 1.0 < 0.1 * EPS  # 0.04-0.07 measured


def test_square_patch_meshes_open_and_clipped_at_its_border():
    positions, normals = _patch()
    mesh = mesh_frame(positions, normals, EPS)
    v = mesh.vertices
    assert np.abs(v[:, 2]).max() < 1e-6 * EPS  # the blend of one plane is that plane
    assert np.abs(v[:, :2]).max() < 1.0 + EPS  # 0.78 EPS beyond the last surfels
    # covers the patch: the mesh's area is at least the square's
    t = v[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    assert 4.0 <= area < (2.0 + 2 * EPS) ** 2
    # open: a boundary loop (edges of one face) near the patch's edge, none inside
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() == 2
    border = np.unique(unique[counts == 1])
    assert len(border) > 0
    assert np.abs(v[border, :2]).max(axis=1).min() > 1.0 - EPS
    assert vertex_components(mesh.faces, len(v))[0] == 1


@pytest.mark.parametrize("reference", ["local", "median"])
def test_a_sparser_half_is_measured_against_its_own_sampling(reference):
    """A patch sampled EPS / 2 apart on one half and EPS on the other: against the median
    weight sum the sparse half (a quarter of the weight) falls under the clipping and is
    lost; against the weight of the surfels around each point it is kept whole."""
    dense, normals = _patch(half=1.0, spacing=EPS / 2)
    sparse, _ = _patch(half=1.0, spacing=EPS)
    positions = np.r_[dense[dense[:, 0] < 0], sparse[sparse[:, 0] >= 0]]
    normals = np.tile([0.0, 0.0, 1.0], (len(positions), 1))
    mesh = mesh_frame(positions, normals, EPS, options=MeshingOptions(clip_reference=reference))
    t = mesh.vertices[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    sparse_area = area[t[:, :, 0].mean(axis=1) > 0].sum()
    if reference == "local":
        assert sparse_area >= 1.8  # 1.90 measured: the half is 2.0 between its surfels
    else:
        assert sparse_area < 0.5  # 0 measured


def test_a_patch_with_holes_meshes_without_a_pinched_vertex():
    """The clipping around holes can leave two fans of faces meeting at one vertex (one such
    pinch on this patch before): each fan gets its own copy, at the same place, with the
    same weight."""
    from fourd.geometry.fans import pinched_vertices

    positions, normals = _patch()
    keep = np.random.default_rng(0).random(len(positions)) < 0.6
    mesh = mesh_frame(positions[keep], normals[keep], EPS)
    assert len(mesh.faces) > 1000
    assert len(pinched_vertices(mesh.faces)) == 0
    assert len(mesh.support) == len(mesh.vertices) and mesh.support.min() >= MeshingOptions().clip
    assert np.abs(mesh.vertices[:, 2]).max() < 1e-6 * EPS


def test_bad_input_raises():
    positions, normals = _patch(half=0.1)
    with pytest.raises(ValueError, match="sampling"):
        mesh_frame(positions, normals, 0.0)
    with pytest.raises(ValueError, match="normals"):
        mesh_frame(positions, normals[:-1], EPS)
    with pytest.raises(ValueError, match="clip"):
        MeshingOptions(clip=1.5)
    with pytest.raises(ValueError, match="reference"):
        surfel_mesh(surfel_state(positions, normals), EPS, reference=1)


def test_rigid_motion_moves_the_mesh_rigidly():
    positions, normals = _sphere(800)
    rng = np.random.default_rng(3)
    turns = [np.eye(3)] + [_rotation(rng.normal(size=3), a) for a in (0.4, 1.1)]
    shifts = [np.zeros(3), np.array([0.3, -0.2, 0.5]), np.array([-1.0, 2.0, 0.25])]
    p = np.stack([positions @ r.T + c for r, c in zip(turns, shifts, strict=True)])
    n = np.stack([normals @ r.T for r in turns])
    steps = np.stack([turns[t + 1] @ turns[t].T for t in range(2)])
    state = surfel_state(p, n, np.broadcast_to(steps[:, None], (2, len(positions), 3, 3)))
    for reference in (0, 1):
        anim = surfel_mesh(state, 0.12, reference=reference, times=[0.0, 0.5, 2.0])
        assert anim.vertices.shape[0] == 3
        assert np.array_equal(anim.rest, anim.vertices[reference])
        base = (anim.rest - shifts[reference]) @ turns[reference]
        for t in range(3):
            truth = base @ turns[t].T + shifts[t]
            assert np.abs(anim.vertices[t] - truth).max() < 1e-9 * np.abs(truth).max()
        assert anim.observed.all()
        assert np.array_equal(anim.times, [0.0, 0.5, 2.0])


def test_frames_compose_the_local_rotations_and_follow_the_normals():
    positions, normals = _patch(half=0.3)
    angles = np.array([0.0, 0.2, 0.5])
    turns = _rotations_y(angles)
    p = np.einsum("tab,sb->tsa", turns, positions)
    n = np.einsum("tab,sb->tsa", turns, normals)
    steps = np.stack([turns[1] @ turns[0].T, turns[2] @ turns[1].T])
    exact = surfel_state(p, n, np.broadcast_to(steps[:, None], (2, len(positions), 3, 3)))
    frames = surfel_frames(exact, 2, align_normals=False)
    assert np.allclose(frames, np.einsum("tab,cb->tac", turns, turns[2])[:, None], atol=1e-12)
    # identity rotations: the normals alone give the turn about y (the least rotation)
    lazy = surfel_state(p, n)
    assert np.allclose(surfel_frames(lazy, 2), frames, atol=1e-12)


@pytest.mark.parametrize("rotations", ["exact", "identity"])
def test_bend_carries_the_mesh_onto_the_bent_surface_smoothly(rotations):
    positions, normals = _patch(half=0.6)
    radii = [np.inf, 2.0, 0.8]
    frames = [(positions, normals, np.broadcast_to(np.eye(3), (len(positions), 3, 3)))]
    frames += [_bend(positions, r) for r in radii[1:]]
    p = np.stack([f[0] for f in frames])
    n = np.stack([f[1] for f in frames])
    steps = np.stack([frames[t + 1][2] @ np.swapaxes(frames[t][2], 1, 2) for t in range(2)])
    # identity: the least rotations onto the normals give the bend's turns about y alone
    anim = surfel_mesh(surfel_state(p, n, steps if rotations == "exact" else None), EPS)
    rest = anim.rest
    lengths = [
        np.linalg.norm(v[anim.faces[:, [1, 2, 0]]] - v[anim.faces], axis=2) for v in anim.vertices
    ]
    for t, radius in enumerate(radii):
        v = anim.vertices[t]
        if np.isinf(radius):
            assert np.array_equal(v, rest)
            continue
        # distance to the cylinder, and where on it (the arc length along x is kept)
        off_axis = np.hypot(v[:, 0], v[:, 2] - radius)
        assert np.abs(off_axis - radius).max() < 0.1 * EPS  # 0.053 at radius 0.8
        arc = radius * np.arctan2(v[:, 0], radius - v[:, 2])
        assert np.abs(arc - rest[:, 0]).max() < 0.02 * EPS
        assert np.abs(v[:, 1] - rest[:, 1]).max() < 1e-9
        # smooth: the bend keeps lengths along the surface, so does the mesh (to 1 %)
        ratio = lengths[t] / lengths[0]
        assert 0.99 < ratio.min() and ratio.max() < 1.01


def test_observed_flags_follow_the_surfels():
    positions, normals = _patch(half=1.0)
    p = np.stack([positions + [0.0, 0.0, 0.1 * t] for t in range(3)])
    n = np.stack([normals] * 3)
    observed = np.ones((3, len(positions)), dtype=bool)
    observed[1, positions[:, 0] > 0.2] = False  # frame 1 lost the right side
    observed[2, :] = False  # frame 2 saw nothing
    anim = surfel_mesh(surfel_state(p, n), EPS, observed=observed)
    x = anim.rest[:, 0]
    assert anim.observed[0].all()
    assert anim.observed[1, x < 0.1].all()
    assert not anim.observed[1, x > 0.3].any()
    assert not anim.observed[2].any()
    assert np.allclose(anim.vertices[2] - anim.rest, [0.0, 0.0, 0.2], atol=1e-12)
    with pytest.raises(ValueError, match="observed"):
        surfel_mesh(surfel_state(p, n), EPS, observed=observed[:2])


def test_binding_is_a_partition_of_unity_and_carry_is_exact_at_the_reference():
    positions, normals = _sphere(600)
    mesh = mesh_frame(positions, normals, 0.15)
    binding = bind_vertices(mesh.vertices, positions, normals, 0.15)
    sums = np.bincount(binding.vertex, binding.weight, minlength=len(mesh.vertices))
    assert np.allclose(sums, 1.0, atol=1e-12)
    state = surfel_state(positions, normals)
    assert np.allclose(carry(binding, state, 0)[0], mesh.vertices, atol=1e-12)
    with pytest.raises(ValueError, match="no surfel"):
        bind_vertices(np.array([[5.0, 0.0, 0.0]]), positions, normals, 0.15)
