"""fourd: animated meshes from time-varying point clouds.

A small real run (``method="kinematic"`` or ``"flow"`` give correspondences; the README has the
figures of each):

>>> import fourd, pathlib, tempfile
>>> truth = fourd.synth.scene("squash-ball", frames=3)
>>> scans = fourd.synth.scan(truth, cameras=3, noise=0.002, resolution=48)
>>> anim = fourd.reconstruct(scans, method="perframe")
>>> report = fourd.evaluate(anim, truth, samples=2000)
>>> report["chamfer"] < 0.05
True
>>> with tempfile.TemporaryDirectory() as folder:
...     fourd.save(anim, pathlib.Path(folder) / "ball.glb").name
'ball.glb'
"""

from __future__ import annotations

from fourd import appearance, deform, synth
from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.methods import available_methods, reconstruct
from fourd.sequence import Frame, PointCloudSequence

__version__ = "0.1.0"


def load_sequence(path) -> PointCloudSequence:
    """Read a folder of frame files (or one ``.npz`` with ``points [T, P, 3]``); see the README."""
    from fourd.io.frames import load_sequence as _load

    return _load(path)


def open_sequence(path) -> FrameSource:
    """A folder of frame files read a frame at a time when asked (a :class:`FrameSource`, for
    whole captures that do not fit in memory; :func:`fourd.methods.kinematic.reconstruct_streamed`)."""
    from fourd.io.frames import open_sequence as _open

    return _open(path)


def save(result, path, **options):
    """Write an :class:`AnimatedMesh` or :class:`MeshSequence`; the format follows the extension
    (``.npz``, ``.glb``, ``.usd/.usda/.usdc``, ``.abc``, ``.pc2``, or a folder). Options go to
    :func:`fourd.io.results.save` (``mesh_format``, ``fps``, ``time_unit``, ``interpolation``,
    ``up``, ``scale``)."""
    from fourd.io.results import save as _save

    return _save(result, path, **options)


def load_result(path):
    """Read a result written by :func:`save` (``.npz``, ``.abc``, or a folder of per-frame
    meshes)."""
    from fourd.io.results import load_result as _load

    return _load(path)


def evaluate(result, truth, **options) -> dict:
    """Metrics of ``result`` against the ground-truth :class:`AnimatedMesh` ``truth``
    (see :func:`fourd.metrics.evaluate`)."""
    from fourd.metrics import evaluate as _evaluate

    return _evaluate(result, truth, **options)


__all__ = [
    "AnimatedMesh",
    "Frame",
    "FrameSource",
    "InputError",
    "MeshSequence",
    "PointCloudSequence",
    "appearance",
    "available_methods",
    "deform",
    "evaluate",
    "load_result",
    "load_sequence",
    "open_sequence",
    "reconstruct",
    "save",
    "synth",
]
