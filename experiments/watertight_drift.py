"""Question: why does the watertight composition (flow's field + kinematic's sliding) drift
more than ``kinematic`` on held-out crane stretches (crane-130 last frame 0.0289 against
0.0178)? Its template, the flow field between frames, or the sliding's projection of the
smoothed frames?

Runs kinematic's ``animate`` with each ingredient swapped, on one bench scene, and prints
correspondence mean / last frame (20k samples):

    python experiments/watertight_drift.py crane-130

Answer (7df00f4): the closed template. The open template on the same flow surfaces measures
0.0119 / 0.0195, the closed one 0.0209 / 0.0271 with or without the projection and with
either method's frames (table in benchmarks/METHODS.md, "watertight and auto").
"""

from __future__ import annotations

import sys

import numpy as np

from fourd import synth
from fourd.bench.suite import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.geometry.neighbors import point_spacing
from fourd.methods import flow, kinematic
from fourd.metrics import evaluate


def scans_of(label: str):
    scene = next(s for s in STANDARD_SCENES + HELD_OUT_SCENES if s.key == label)
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, **{**PROTOCOL, **scene.scan})
    return truth, scans


def main(label: str) -> None:
    truth, scans = scans_of(label)
    flowed = flow.run(scans, flow.Options())
    distance = flow.surface_distance(flowed)
    points, normals = flowed.frame_points, flowed.frame_normals
    kpoints, knormals = kinematic.prepare_frames(scans, kinematic.Options())
    spacing = point_spacing(points[0])
    times = np.asarray(scans.times, float)
    mpu = kinematic_field(scans, kpoints, knormals)
    variants = {
        "kinematic (MPU field, open template, its own frames)": dict(
            field=mpu, points=kpoints, normals=knormals, closed=False, project=False),
        "watertight (flow distance, closed template, flow frames, projection)": dict(
            field=distance, points=points, normals=normals, closed=True, project=True),
        "flow distance, closed, flow frames, no projection": dict(
            field=distance, points=points, normals=normals, closed=True, project=False),
        "flow distance, closed, kinematic frames, projection": dict(
            field=distance, points=kpoints, normals=knormals, closed=True, project=True),
        "flow distance, open template, kinematic frames": dict(
            field=distance, points=kpoints, normals=knormals, closed=False, project=False),
        "MPU field, open template, flow frames": dict(
            field=mpu, points=points, normals=normals, closed=False, project=False),
    }
    for name, v in variants.items():
        anim = kinematic.animate(
            v["field"], list(v["points"]), list(v["normals"]), times, spacing=spacing,
            options=kinematic.Options(), closed=v["closed"],
            bounds=distance.bounds() if v["closed"] else None, project_smoothed=v["project"],
        )
        m = evaluate(anim, truth, samples=20000, seed=0)
        print(f"{name}: corr {m['correspondence_mean']:.4f} / {m['correspondence_last']:.4f}, "
              f"Chamfer {m['chamfer']:.4f}, c95 {m['completeness_95']:.4f}", flush=True)


def kinematic_field(scans, points, normals):
    from fourd.methods.kinematic.field import fit_windows, space_time_points
    from fourd.methods.kinematic.mpu4d import MPUOptions

    options = kinematic.Options()
    times = np.asarray(scans.times, float)
    spacing = point_spacing(points[0], seed=options.seed)
    unit = float(np.median(np.diff(times)))
    delta = spacing * options.time_scale
    stp = space_time_points([p[::2] for p in points], [n[::2] for n in normals], times,
                            delta=delta, time_origin=times[0], time_unit=unit)
    return fit_windows(stp, times, mpu_options=MPUOptions(error=2.0 * spacing),
                       window=0, overlap=2, time_origin=times[0], time_scale=delta / unit)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "crane-130")
