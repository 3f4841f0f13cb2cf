"""Procedural deforming scenes with exact ground truth, and a virtual depth scanner."""

from __future__ import annotations


def scene(name: str, *, frames: int | None = None, seed: int = 0, **options):
    """Ground-truth :class:`~fourd.AnimatedMesh` of scene ``name`` (see :data:`SCENES`)."""
    from fourd.synth.scenes import scene as _scene

    return _scene(name, frames=frames, seed=seed, **options)


def scan(truth, **options):
    """Scan a ground-truth animation with virtual depth cameras; a :class:`~fourd.PointCloudSequence`."""
    from fourd.synth.scanner import scan as _scan

    return _scan(truth, **options)
