"""Stage results on disk, keyed by their inputs and options, so an interrupted run resumes.

A method given ``cache_dir`` keeps each finished unit of work (a frame's mesh, a prepared
frame, a 4D fit, a slid frame, an IRLS iteration) as ``<cache_dir>/<stage>-<key>.npz``; a
rerun loads those instead of recomputing them. The key hashes everything the entry depends
on: the input data, the options that act on the stage, the keys of the stages before it,
:data:`CACHE_FORMAT` and fourd's version, so a changed option or another version of the code
never reuses a stale entry (it only misses). Entries are written to a temporary name and
renamed (:func:`fourd.io.atomic.atomic_path`): a run killed mid-write leaves no half-written
entry, and an unreadable one counts as missing.

The pieces, used by the methods:

- :func:`stage_key` and :func:`option_values`: the keys;
- :class:`StageCache`: the entries of one folder (``StageCache(None)`` stores nothing);
- :func:`cached`: a stage, loaded or computed and stored;
- :class:`Chain`: a sequential computation whose step k starts from step k - 1's state (the
  sliding's frames, the flow's IRLS iterations), keyed so that an entry is valid only after
  exactly the steps before it;
- :func:`pack_list` / :func:`unpack_list`: a list of optional arrays in one entry;
- :func:`report_resumed` and :func:`counting_resumes`: the "resumed: ... from the cache" line
  and the tally the command line reads to say its timing counts only the work done now.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import hashlib
import json
import logging
import os
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from fourd.io.atomic import atomic_path

log = logging.getLogger("fourd.cache")

#: The layout of keys and entries; raise it when they change, so old entries are not read.
CACHE_FORMAT = 3


def _version() -> str:
    from fourd import __version__

    return __version__


def _update(digest, part) -> None:
    """Feed one key part to ``digest``, tagged with its kind so that different parts cannot
    collide (``("ab", "c")`` and ``("a", "bc")``, an array and its bytes as a string)."""
    if part is None:
        digest.update(b"N;")
    elif isinstance(part, np.ndarray):
        if part.dtype.hasobject:
            raise TypeError("stage_key cannot hash an object array")
        digest.update(f"A{part.dtype.str}{part.shape};".encode())
        digest.update(np.ascontiguousarray(part).data)
    elif dataclasses.is_dataclass(part) and not isinstance(part, type):
        _update(digest, {"<dataclass>": type(part).__qualname__, **option_values(part)})
    elif isinstance(part, Mapping):
        text = json.dumps(
            {str(k): part[k] for k in part}, sort_keys=True, default=_json_default
        )
        digest.update(f"M{len(text)};{text}".encode())
    elif isinstance(part, (list, tuple)):
        digest.update(f"L{len(part)};".encode())
        for item in part:
            _update(digest, item)
    else:
        text = repr(part.item() if isinstance(part, np.generic) else part)
        digest.update(f"S{len(text)};{text}".encode())


def _json_default(value):
    if isinstance(value, np.ndarray):
        if value.size > 64:
            raise TypeError("stage_key: pass large arrays as their own parts, not inside options")
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"<dataclass>": type(value).__qualname__, **option_values(value)}
    return repr(value)


def stage_key(*parts) -> str:
    """A short stable hash (20 hex digits) of arrays, options dataclasses (without their
    ``cache_dir``), mappings, lists and tuples of these, numbers, strings and None, together
    with :data:`CACHE_FORMAT` and fourd's version.

    Examples
    --------
    >>> points = np.zeros((4, 3))
    >>> stage_key(points, 2.0) == stage_key(points.copy(), 2.0) != stage_key(points, 2.5)
    True
    """
    digest = hashlib.sha1()
    _update(digest, ("fourd", _version(), "cache", CACHE_FORMAT))
    for part in parts:
        _update(digest, part)
    return digest.hexdigest()[:20]


def option_values(options, *, without: Sequence[str] = ()) -> dict:
    """The fields of an options dataclass as ``{name: value}``, without ``cache_dir`` (where
    the cache lives changes no result) nor the names in ``without`` (options that act only
    after the stage being keyed). A name in ``without`` that is not a field is an error, so
    a renamed option cannot silently leave a stage's key."""
    fields = {f.name for f in dataclasses.fields(options)}
    unknown = sorted(set(without) - fields)
    if unknown:
        raise ValueError(f"{type(options).__name__} has no options {', '.join(unknown)}")
    skip = set(without) | {"cache_dir"}
    return {name: getattr(options, name) for name in sorted(fields - skip)}


@dataclasses.dataclass(frozen=True)
class StageCache:
    """The stage entries in ``folder`` (``None``: a cache that stores nothing and never
    finds anything)."""

    folder: str | os.PathLike | None = None

    @property
    def enabled(self) -> bool:
        return self.folder is not None

    def path(self, stage: str, key: str) -> Path:
        return Path(self.folder) / f"{stage}-{key}.npz"

    def load(self, stage: str, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``stage`` and ``key``, or None (no entry, or one that
        cannot be read)."""
        if self.folder is None:
            return None
        path = self.path(stage, key)
        if not path.exists():
            return None
        try:
            with np.load(path) as data:
                return {name: data[name] for name in data.files}
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as error:
            log.warning("%s: unreadable cache entry, computed again (%s)", path, error)
            return None

    def save(self, stage: str, key: str, arrays: Mapping[str, np.ndarray]) -> None:
        """Store ``arrays`` under ``stage`` and ``key`` (atomically: all or nothing)."""
        if self.folder is None:
            return
        Path(self.folder).mkdir(parents=True, exist_ok=True)
        with atomic_path(self.path(stage, key)) as tmp:
            np.savez(tmp, **arrays)

    def discard(self, stage: str, key: str) -> None:
        """Remove an entry (a no-op when there is none)."""
        if self.folder is not None:
            with contextlib.suppress(FileNotFoundError):
                os.remove(self.path(stage, key))


def subfolder(cache_dir: str | os.PathLike | None, name: str) -> str | None:
    """The ``cache_dir`` of a composition's sub-method ``name``: a folder of its own in the
    composition's (None without a cache)."""
    return None if cache_dir is None else os.path.join(cache_dir, name)


#: The cache that stores nothing (the default of functions taking a cache).
NO_CACHE = StageCache()


def cached(
    cache: StageCache, stage: str, key: str, compute: Callable[[], Mapping[str, np.ndarray]]
) -> tuple[dict[str, np.ndarray], bool]:
    """A stage's arrays: the entry ``stage``/``key`` of ``cache`` or, when it has none,
    ``compute()``'s, stored there; and whether they came from the cache.

    Examples
    --------
    >>> arrays, resumed = cached(StageCache(None), "square", "k", lambda: {"x": np.ones(2)})
    >>> arrays["x"].tolist(), resumed
    ([1.0, 1.0], False)
    """
    stored = cache.load(stage, key)
    if stored is not None:
        return stored, True
    arrays = dict(compute())
    cache.save(stage, key, arrays)
    return arrays, False


@dataclasses.dataclass(frozen=True)
class Chain:
    """The entries of a sequential computation: step ``k`` starts from the state step
    ``k - 1`` left, so its key hashes step ``k - 1``'s key with step ``k``'s own inputs
    (:meth:`of`); an entry is then valid only after exactly the steps before it.

    Attributes
    ----------
    cache : StageCache
    stage : str
        The entries' stage name.
    keys : tuple of str
        One key per step.
    """

    cache: StageCache
    stage: str
    keys: tuple[str, ...]

    @classmethod
    def of(cls, cache: StageCache, stage: str, base: str, steps: Sequence[Sequence]) -> Chain:
        """The chain of ``len(steps)`` steps after ``base`` (the key of everything before the
        first step), ``steps[k]`` the key parts of step ``k``'s own inputs."""
        keys, key = [], base
        for k, parts in enumerate(steps):
            key = stage_key(key, k, *parts)
            keys.append(key)
        return cls(cache, stage, tuple(keys))

    def __len__(self) -> int:
        return len(self.keys)

    def prefix(self) -> list[dict[str, np.ndarray]]:
        """The entries of steps 0, 1, ... up to the first step without one."""
        entries = []
        for key in self.keys:
            entry = self.cache.load(self.stage, key)
            if entry is None:
                break
            entries.append(entry)
        return entries

    def latest(self) -> tuple[int, dict[str, np.ndarray] | None]:
        """The last step that has an entry and that entry; ``(-1, None)`` for none."""
        for step in range(len(self.keys) - 1, -1, -1):
            entry = self.cache.load(self.stage, self.keys[step])
            if entry is not None:
                return step, entry
        return -1, None

    def save(self, step: int, arrays: Mapping[str, np.ndarray], *, keep_earlier: bool = True):
        """Store step ``step``'s entry; without ``keep_earlier`` the earlier steps' entries go
        (a chain resumed by :meth:`latest` needs only the last one)."""
        self.cache.save(self.stage, self.keys[step], arrays)
        if not keep_earlier:
            for key in self.keys[:step]:
                self.cache.discard(self.stage, key)

    def discard(self) -> None:
        """Remove every entry of the chain."""
        for key in self.keys:
            self.cache.discard(self.stage, key)


def pack_list(name: str, arrays: Sequence[np.ndarray | None]) -> dict[str, np.ndarray]:
    """A list of arrays, some of them None, as entry arrays ``name_count``, ``name_0`` ...
    (:func:`unpack_list` reads them back)."""
    packed = {f"{name}_count": np.array(len(arrays))}
    for i, array in enumerate(arrays):
        if array is not None:
            packed[f"{name}_{i}"] = np.asarray(array)
    return packed


def unpack_list(entry: Mapping[str, np.ndarray], name: str) -> list[np.ndarray | None]:
    """The list :func:`pack_list` stored as ``name`` in ``entry``.

    Examples
    --------
    >>> unpack_list(pack_list("p", [np.zeros(2), None]), "p")
    [array([0., 0.]), None]
    """
    return [entry.get(f"{name}_{i}") for i in range(int(entry[f"{name}_count"]))]


_RESUMED: contextvars.ContextVar[list | None] = contextvars.ContextVar(
    "fourd_cache_resumed", default=None
)


def report_resumed(logger: logging.Logger, what: str) -> None:
    """Log ``resumed: <what> from the cache`` at info level (and count it for
    :func:`counting_resumes`)."""
    logger.info("resumed: %s from the cache", what)
    tally = _RESUMED.get()
    if tally is not None:
        tally.append(what)


@contextlib.contextmanager
def counting_resumes() -> Iterator[list[str]]:
    """Within the block, every :func:`report_resumed` of this thread adds its ``what`` to
    the yielded list: the command line's timing then says it counts only the work done
    now."""
    tally: list[str] = []
    token = _RESUMED.set(tally)
    try:
        yield tally
    finally:
        _RESUMED.reset(token)
