"""The peers of ``../shared/BASELINES.md``, for extra rows in ``fourd bench --baselines``.

What users would pick instead of fourd, with exactly the settings BASELINES.md lists:

1. :func:`poisson_per_frame`: per-frame screened Poisson (Open3D): statistical outlier removal
   (20 neighbours, 2.0 standard deviations), normals from 30 neighbours oriented towards the
   cameras and made consistent, Poisson depth 8, scale 1.1, vertices under the 5% density
   quantile removed. No correspondences (a :class:`~fourd.MeshSequence`).
2. :func:`template_nicp`: the frame-0 Poisson mesh decimated to 9,000 faces, fitted to each next
   frame from the previous result with trimesh's ``nricp_amberg`` (or ``nricp_sumner``): an
   :class:`~fourd.AnimatedMesh`.

Open3D is an optional extra (``pip install 'fourd[baselines]'``); these functions raise
:class:`ImportError` with that hint when it is missing.

References
----------
Kazhdan, Hoppe: Screened Poisson surface reconstruction, ACM TOG 32(3), 2013.
Amberg, Romdhani, Vetter: Optimal step nonrigid ICP algorithms for surface registration,
CVPR 2007. Sumner, Popovic: Deformation transfer for triangle meshes, SIGGRAPH 2004.
"""

from __future__ import annotations

import logging

import numpy as np

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.progress import progress
from fourd.sequence import Frame, PointCloudSequence

log = logging.getLogger("fourd.bench.peers")

#: BASELINES.md settings.
OUTLIER_NEIGHBOURS, OUTLIER_STD = 20, 2.0
NORMAL_NEIGHBOURS = 30
POISSON_DEPTH, POISSON_SCALE = 8, 1.1
DENSITY_QUANTILE = 0.05
TEMPLATE_FACES = 9000
#: ``nricp`` match threshold as a fraction of the frame's diagonal (trimesh's default 0.1 is an
#: absolute length: 4% of crane's diagonal, which this keeps for every scene).
MATCH_THRESHOLD = 0.04


def _open3d():
    try:
        import open3d
    except ImportError as error:
        raise ImportError(
            "the Open3D peers need open3d: pip install 'fourd[baselines]' (or pip install open3d)"
        ) from error
    return open3d


def _cleaned_cloud(frame: Frame):
    """The frame as an Open3D cloud after statistical outlier removal, with oriented normals."""
    o3d = _open3d()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(frame.points))
    cloud, _ = cloud.remove_statistical_outlier(nb_neighbors=OUTLIER_NEIGHBOURS, std_ratio=OUTLIER_STD)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=NORMAL_NEIGHBOURS))
    points = np.asarray(cloud.points)
    normals = np.asarray(cloud.normals)
    if frame.sensors is not None and len(frame.sensors):
        # Towards the camera the normal faces most directly (the one that can have seen it).
        directions = frame.sensors[None, :, :] - points[:, None, :]
        directions /= np.linalg.norm(directions, axis=2, keepdims=True)
        cosines = np.einsum("pd,pkd->pk", normals, directions)
        best = cosines[np.arange(len(points)), np.argmax(np.abs(cosines), axis=1)]
        normals = np.where(best[:, None] < 0, -normals, normals)
        cloud.normals = o3d.utility.Vector3dVector(normals)
    cloud.orient_normals_consistent_tangent_plane(NORMAL_NEIGHBOURS)
    if frame.sensors is not None and len(frame.sensors):
        # Consistency propagation may flip everything: keep the orientation the cameras agree with.
        normals = np.asarray(cloud.normals)
        directions = frame.sensors[None, :, :] - points[:, None, :]
        agree = np.einsum("pd,pkd->pk", normals, directions).max(axis=1) > 0
        if agree.mean() < 0.5:
            cloud.normals = o3d.utility.Vector3dVector(-normals)
    return cloud


def poisson_frame(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """Screened Poisson mesh ``(vertices [N, 3], faces [F, 3])`` of one frame (BASELINES.md peer 1)."""
    o3d = _open3d()
    cloud = _cleaned_cloud(frame)
    mesh, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        cloud, depth=POISSON_DEPTH, scale=POISSON_SCALE
    )
    densities = np.asarray(densities)
    mesh.remove_vertices_by_mask(densities < np.quantile(densities, DENSITY_QUANTILE))
    mesh.remove_unreferenced_vertices()
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)


def poisson_per_frame(seq: PointCloudSequence) -> MeshSequence:
    """Per-frame screened Poisson (Open3D), the settings of BASELINES.md peer 1."""
    _open3d()
    meshes = [poisson_frame(frame) for frame in progress(seq.frames, desc="poisson", total=len(seq))]
    return MeshSequence(tuple(meshes), seq.times)


def template_nicp(seq: PointCloudSequence, *, variant: str = "amberg") -> AnimatedMesh:
    """Template + non-rigid ICP (BASELINES.md peer 2): frame 0's Poisson mesh decimated to
    9,000 faces, fitted to each next frame's cleaned points from the previous fit with
    ``trimesh.registration.nricp_amberg`` (``variant="amberg"``) or ``nricp_sumner``."""
    import trimesh
    from trimesh.registration import nricp_amberg, nricp_sumner

    o3d = _open3d()
    vertices, faces = poisson_frame(seq.frames[0])
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces))
    mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=TEMPLATE_FACES)
    mesh.remove_unreferenced_vertices()
    template = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles), process=True)
    frames = [template.vertices.copy()]
    current = template
    for frame in progress(seq.frames[1:], desc=f"nicp-{variant}", total=len(seq) - 1):
        target = np.asarray(_cleaned_cloud(frame).points)
        threshold = MATCH_THRESHOLD * float(np.linalg.norm(np.ptp(target, axis=0)))
        if variant == "amberg":
            fitted = nricp_amberg(current, target, distance_threshold=threshold, use_faces=False)
        elif variant == "sumner":
            fitted = nricp_sumner(current, target, distance_threshold=threshold, use_faces=False)
        else:
            raise ValueError(f"variant must be 'amberg' or 'sumner', got {variant!r}")
        fitted = np.asarray(fitted, dtype=np.float64)
        frames.append(fitted)
        current = trimesh.Trimesh(fitted, template.faces, process=False)
    return AnimatedMesh(template.faces, np.stack(frames), seq.times, rest=template.vertices)


def template_nicp_sumner(seq: PointCloudSequence) -> AnimatedMesh:
    """:func:`template_nicp` with ``nricp_sumner`` (the second NICP row of BASELINES.md)."""
    return template_nicp(seq, variant="sumner")
