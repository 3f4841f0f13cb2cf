"""Where ``kinematic``'s correspondence error on a scene comes from: does the as-rigid-as-possible
prior prefer the tracked positions or the true ones?

Run: ``.venv/bin/python experiments/arap_basin.py [SCENE] [--frames 11,13,19] [--iterations 40]
[--twists=-60,-30,30,60]`` (default ``crane``; any bench scene, with its own scanner, e.g.
``crane-clean``; about a minute on 2 cores, plus about 15 s per twist and frame).

It reconstructs the scene with ``kinematic``, then maps every template vertex to the truth as
the correspondence metric does (triangle and barycentric coordinates of the closest point of
the truth's frame 0), plus the offset along that triangle's normal, carried to every frame.
Per listed frame it prints

* ``error``: mean distance between tracked and true positions (fraction of the diagonal);
* ``E tracked`` / ``E truth``: the normalised ARAP energy of the tracked and of the true
  positions against the template (:func:`fourd.methods.kinematic.arap.arap_energy`);
* ``relaxed from tracked`` / ``from truth``: error and energy after ``--iterations``
  local / global ARAP steps with every vertex held to the tangent plane of the closest point of
  the *exact* truth surface of that frame (the sliding's constraint (2), without noise), from
  the tracked and from the true positions.

If the tracked positions relax to a lower energy than the truth's while staying far from it,
the prior itself prefers them; if they stay above the truth's energy, the tracking sits in a
wrong local minimum.

Then, per listed frame, the largest connected regions of the template whose error exceeds twice
the frame's mean: their vertex count, centre at frame 0, mean error, and the rotation that best
maps their true onto their tracked positions (degrees) with ``|cos|`` between its axis and the
region's longest principal axis (near 1: a twist of a limb about itself). Needs a scene whose
truth has faces (not ``dfaust-hopping``).

With ``--twists`` (degrees, comma-separated), per listed frame the largest such region of the
tracked positions is turned rigidly by each angle about its longest principal axis through its
centroid and relaxed as above (``--iterations``): ``twist A: error, E``. An angle whose relaxed
energy is below the untwisted one (``twist 0``) means that a search over limb twists, scored by
the ARAP energy alone, would find a better state than the sliding's.
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from fourd import synth
from fourd.bench import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.geometry.meshes import vertex_components
from fourd.geometry.rotations import procrustes
from fourd.methods import reconstruct
from fourd.methods.kinematic.arap import arap_energy, arap_rhs, arap_rotations
from fourd.methods.kinematic.arap_solve import ConstrainedSolver, slide_precompute
from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface


def truth_positions(template: np.ndarray, truth_vertices: np.ndarray, truth_faces: np.ndarray):
    """Positions [T, N, 3] of the ``template`` [N, 3] vertices carried by the truth [T, V, 3]:
    the correspondence metric's binding to the closest point of frame 0
    (:func:`~fourd.metrics.sampling.bind_to_surface`), plus the offset along that triangle's
    normal, so that frame 0 is the template itself."""
    samples = sample_surface(truth_vertices[0], truth_faces, 60_000, np.random.default_rng(0))
    binding = bind_to_surface(template, truth_vertices[0], truth_faces, samples)
    corners = truth_vertices[:, truth_faces[binding.faces]]  # [T, N, 3, 3]
    first, second, third = corners[..., 0, :], corners[..., 1, :], corners[..., 2, :]
    normals = np.cross(second - first, third - first)
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-300)
    on_surface = bound_positions(binding, truth_vertices, truth_faces)
    height = np.einsum("ij,ij->i", template - on_surface[0], normals[0])
    return on_surface + height[None, :, None] * normals


def relax_on_surface(pre, start: np.ndarray, surface: trimesh.Trimesh, iterations: int):
    """``iterations`` ARAP local / global steps from ``start`` [N, 3], every vertex held to the
    tangent plane of its closest point on ``surface`` (re-found each step)."""
    x = start.copy()
    everyone = np.ones(len(x), dtype=bool)
    for _ in range(iterations):
        closest, _, triangle = trimesh.proximity.closest_point(surface, x)
        normals = surface.face_normals[triangle]
        offsets = np.einsum("ij,ij->i", normals, closest)
        solver = ConstrainedSolver(pre, normals, offsets, everyone, 1e-4)
        x = solver.solve(arap_rhs(pre, arap_rotations(pre, x)), x)
    return x


def error_region_masks(faces, tracked, true, diagonal, largest=4, least=20):
    """Masks [N] of the ``largest`` connected regions (at least ``least`` vertices) whose error
    exceeds twice the mean, largest first."""
    error = np.linalg.norm(tracked - true, axis=1) / diagonal
    high = error > 2.0 * error.mean()
    count, labels = vertex_components(faces[high[faces].all(axis=1)], len(tracked))
    sizes = np.bincount(labels[high], minlength=count)
    masks = []
    for region in np.argsort(sizes)[::-1][:largest]:
        members = high & (labels == region)
        if members.sum() < least:
            break
        masks.append(members)
    return masks


def twisted(positions: np.ndarray, members: np.ndarray, degrees: float) -> np.ndarray:
    """``positions`` [N, 3] with the ``members`` [N] turned by ``degrees`` about their longest
    principal axis through their centroid."""
    part = positions[members]
    centre = part.mean(axis=0)
    _, vectors = np.linalg.eigh(np.cov((part - centre).T))
    rotation = Rotation.from_rotvec(np.radians(degrees) * vectors[:, -1]).as_matrix()
    out = positions.copy()
    out[members] = (part - centre) @ rotation.T + centre
    return out


def error_regions(rest, faces, tracked, true, diagonal, largest=4, least=20):
    """Lines describing the ``largest`` connected regions (at least ``least`` vertices) whose
    error exceeds twice the mean; see the module docstring."""
    error = np.linalg.norm(tracked - true, axis=1) / diagonal
    lines = []
    for members in error_region_masks(faces, tracked, true, diagonal, largest, least):
        fit = procrustes(true[members], tracked[members])
        angle = np.degrees(np.arccos(np.clip((np.trace(fit.rotation) - 1.0) / 2.0, -1.0, 1.0)))
        r = fit.rotation
        axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
        axis /= max(float(np.linalg.norm(axis)), 1e-12)
        _, vectors = np.linalg.eigh(np.cov((rest[members] - rest[members].mean(axis=0)).T))
        lines.append(
            f"  region of {members.sum()} vertices at {np.round(rest[members].mean(axis=0), 2)}: "
            f"error {error[members].mean():.4f}, rotation {angle:.0f} deg, "
            f"|cos(axis, region axis)| {abs(float(axis @ vectors[:, -1])):.2f}"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="crane")
    parser.add_argument("--frames", default="11,13,19", help="frame indices, comma-separated")
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--twists", default="", help="degrees, comma-separated (see above)")
    args = parser.parse_args()
    scene = {s.key: s for s in STANDARD_SCENES + HELD_OUT_SCENES}[args.scene]
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, **{**PROTOCOL, **scene.scan})
    result = reconstruct(scans, method="kinematic")
    tracked, faces = np.asarray(result.vertices), np.asarray(result.faces)
    truth_vertices, truth_faces = np.asarray(truth.vertices), np.asarray(truth.faces)
    true = truth_positions(tracked[0], truth_vertices, truth_faces)
    diagonal = float(np.linalg.norm(np.ptp(truth_vertices[0], axis=0)))
    pre = slide_precompute(tracked[0], faces)

    def error(x, k):
        return float(np.linalg.norm(x - true[k], axis=1).mean()) / diagonal

    print(f"{args.scene}: error / E tracked / E truth / relaxed from tracked (error, E) / "
          f"from truth (error, E), {args.iterations} iterations")
    for k in (int(f) for f in args.frames.split(",")):
        surface = trimesh.Trimesh(truth_vertices[k], truth_faces, process=False)
        from_tracked = relax_on_surface(pre, tracked[k], surface, args.iterations)
        from_truth = relax_on_surface(pre, true[k], surface, args.iterations)
        print(f"frame {k}: {error(tracked[k], k):.4f} / {arap_energy(pre, tracked[k]):.4f} / "
              f"{arap_energy(pre, true[k]):.4f} / ({error(from_tracked, k):.4f}, "
              f"{arap_energy(pre, from_tracked):.4f}) / ({error(from_truth, k):.4f}, "
              f"{arap_energy(pre, from_truth):.4f})", flush=True)
        for line in error_regions(tracked[0], faces, tracked[k], true[k], diagonal):
            print(line)
        masks = error_region_masks(faces, tracked[k], true[k], diagonal, largest=1)
        if args.twists and masks:
            for degrees in [0.0] + [float(a) for a in args.twists.split(",")]:
                x = relax_on_surface(
                    pre, twisted(tracked[k], masks[0], degrees), surface, args.iterations
                )
                print(f"  twist {degrees:+.0f}: {error(x, k):.4f}, {arap_energy(pre, x):.4f}",
                      flush=True)


if __name__ == "__main__":
    main()
