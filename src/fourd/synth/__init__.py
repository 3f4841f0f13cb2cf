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


def long_capture(frames: int, **options):
    """A capture of any length read a frame at a time (a scene played ping-pong, each frame
    scanned when read); see :func:`fourd.synth.whole_capture.long_capture`."""
    from fourd.synth.whole_capture import long_capture as _long_capture

    return _long_capture(frames, **options)
