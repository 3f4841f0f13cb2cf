"""Stage results on disk, keyed by their inputs and options, so an interrupted run resumes.

A method given ``cache_dir`` stores each finished unit of work (a frame's mesh, a slid frame)
as ``<cache_dir>/<stage>-<key>.npz``; on a rerun with the same inputs and options it loads
those instead of recomputing. Files are written atomically, so a crash never leaves a
half-written entry.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from fourd.io.atomic import atomic_path


def stage_key(*parts) -> str:
    """A short stable hash of arrays, dataclass options, numbers and strings."""
    digest = hashlib.sha1()
    for part in parts:
        if isinstance(part, np.ndarray):
            digest.update(str((part.dtype, part.shape)).encode())
            digest.update(np.ascontiguousarray(part).tobytes())
        elif dataclasses.is_dataclass(part):
            fields = {f.name: getattr(part, f.name) for f in dataclasses.fields(part)}
            fields.pop("cache_dir", None)
            digest.update(json.dumps(fields, sort_keys=True, default=repr).encode())
        else:
            digest.update(repr(part).encode())
    return digest.hexdigest()[:20]


@dataclasses.dataclass(frozen=True)
class StageCache:
    """Read and write stage results under ``folder`` (``None``: a cache that stores nothing)."""

    folder: str | os.PathLike | None

    def _path(self, stage: str, key: str) -> Path:
        return Path(self.folder) / f"{stage}-{key}.npz"

    def load(self, stage: str, key: str) -> dict[str, np.ndarray] | None:
        if self.folder is None:
            return None
        path = self._path(stage, key)
        if not path.exists():
            return None
        try:
            with np.load(path) as data:
                return {name: data[name] for name in data.files}
        except (OSError, ValueError):
            return None

    def save(self, stage: str, key: str, arrays: dict[str, np.ndarray]) -> None:
        if self.folder is None:
            return
        Path(self.folder).mkdir(parents=True, exist_ok=True)
        with atomic_path(self._path(stage, key)) as tmp:
            np.savez(tmp, **arrays)
