"""The files beside the frames of an input folder: ``times.txt`` and ``sensors.json``."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from fourd.errors import InputError


def read_times(path: str | os.PathLike, count: int | None = None) -> np.ndarray:
    """Read ``times.txt``: one number per frame (whitespace separated; ``#`` starts a comment).

    Raises InputError when a value is not a finite number, when the count differs from
    ``count``, or when the times do not increase strictly.
    """
    path = Path(path)
    from fourd.io.meshfiles import read_text

    values = []
    for line in read_text(path).splitlines():
        values.extend(line.split("#", 1)[0].split())
    try:
        times = np.array(values, dtype=np.float64)
    except ValueError:
        bad = next(v for v in values if not _is_number(v))
        raise InputError(f"{bad!r} is not a number", path) from None
    if not np.isfinite(times).all():
        raise InputError("times must be finite numbers", path)
    if count is not None and len(times) != count:
        raise InputError(f"has {len(times)} times but there are {count} frames", path)
    steps = np.diff(times)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise InputError(
            f"times must increase strictly: time {i + 2} ({times[i + 1]}) follows {times[i]}", path
        )
    return times


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def sensor_table(value, path: Path, where: str) -> np.ndarray | None:
    """``value`` as a ``[K, 3]`` table of finite sensor positions (None when empty); ``where``
    names it in the error."""
    try:
        table = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where} must be a list of [x, y, z] positions", path) from None
    if table.size == 0:
        return None
    if table.ndim != 2 or table.shape[1] != 3:
        raise InputError(
            f"{where} must be a list of [x, y, z] positions, got shape {list(table.shape)}", path
        )
    if not np.isfinite(table).all():
        raise InputError(f"{where} holds NaN or infinite positions", path)
    return table


def read_sensors(path: str | os.PathLike, count: int) -> list[np.ndarray | None]:
    """Read ``sensors.json``: ``{"sensors": [[x,y,z], ...]}`` (the same scanners for every
    frame) or ``{"frames": [[[x,y,z], ...], ...]}`` (one list per frame; an empty list means
    unknown for that frame). Returns one ``[K, 3]`` array (or None) per frame."""
    path = Path(path)
    from fourd.io.meshfiles import read_text

    try:
        data = json.loads(read_text(path))
    except json.JSONDecodeError as error:
        raise InputError(f"is not valid JSON ({error.msg} at line {error.lineno})", path) from None
    if not isinstance(data, dict) or not ({"sensors", "frames"} & set(data)):
        raise InputError(
            'expected {"sensors": [[x, y, z], ...]} or {"frames": [[[x, y, z], ...], ...]}', path
        )
    if "frames" in data:
        frames = data["frames"]
        if not isinstance(frames, list) or len(frames) != count:
            have = len(frames) if isinstance(frames, list) else "no list of"
            raise InputError(f'"frames" has {have} entries but there are {count} frames', path)
        return [sensor_table(item, path, f'"frames"[{i}]') for i, item in enumerate(frames)]
    table = sensor_table(data["sensors"], path, '"sensors"')
    return [table] * count
