"""Atomic output: write to a temporary name beside the target, then rename."""

from __future__ import annotations

import contextlib
import glob
import os
import secrets
import shutil
import tempfile
from pathlib import Path

from fourd.errors import InputError


def _permissions(path: Path, mode: int) -> None:
    """Give a temporary output the permissions a normally created file would have."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, mode & ~umask)


def _check_parent(path: Path) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.exists():
        raise InputError("the output folder does not exist", parent)
    if not os.access(parent, os.W_OK):
        raise InputError("the output folder is not writable", parent)


def _unique_prefix(name: str) -> str:
    """A temporary name's prefix no other write shares, chosen before anything is created."""
    return f".{name}.{secrets.token_hex(4)}."


def _remove_started(folder: Path, prefix: str) -> None:
    """Remove what a write with ``prefix`` left in ``folder``: found by its prefix, not by the
    name ``mkstemp`` returned, since a signal (Ctrl-C, SIGTERM) can interrupt ``mkstemp``
    after it created the file and before it returned its name."""
    for leftover in Path(folder or ".").glob(glob.escape(prefix) + "*"):
        with contextlib.suppress(OSError):
            if leftover.is_dir() and not leftover.is_symlink():
                shutil.rmtree(leftover, ignore_errors=True)
            else:
                leftover.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str | None = None):
    """Yield a temporary file path in the target's folder; rename it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is left untouched. ``suffix``
    defaults to the target's own suffix so that libraries choosing a format by extension work.
    """
    path = Path(path)
    _check_parent(path)
    suffix = path.suffix if suffix is None else suffix
    prefix = _unique_prefix(path.stem)
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=f".part{suffix}", dir=path.parent or ".")
        os.close(fd)
        yield Path(tmp)
        _permissions(Path(tmp), 0o666)
        os.replace(tmp, path)
    except BaseException:
        _remove_started(path.parent, prefix)
        raise


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike):
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` (an old folder
    of that name is removed only after the new one is complete)."""
    path = Path(path)
    _check_parent(path)
    if path.exists() and not path.is_dir():
        raise InputError("exists and is not a folder", path)
    prefix = _unique_prefix(path.name)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=".part", dir=path.parent or "."))
        yield tmp
        _permissions(tmp, 0o777)
        if path.exists():
            old = path.with_name(f".{path.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        _remove_started(path.parent, prefix)
        raise
