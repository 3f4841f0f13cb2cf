"""Atomic output leaves nothing behind when it is interrupted, even by a signal that arrives
inside ``mkstemp`` after the temporary file exists and before its name is known (a SIGTERM
sent as a cache entry's write starts: the CLI's kill test caught it)."""

import os
import tempfile

import pytest

from fourd.io.atomic import atomic_dir, atomic_path


def _interrupted_after_creating(make):
    def interrupted(*args, **kwargs):
        made = make(*args, **kwargs)
        if isinstance(made, tuple):
            os.close(made[0])
        raise KeyboardInterrupt  # the signal's handler, before the name is returned

    return interrupted


def test_a_write_interrupted_inside_mkstemp_leaves_no_temporary_file(tmp_path, monkeypatch):
    target = tmp_path / "entry.npz"
    target.write_bytes(b"old")
    monkeypatch.setattr(tempfile, "mkstemp", _interrupted_after_creating(tempfile.mkstemp))
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry.npz"]
    assert target.read_bytes() == b"old"


def test_a_folder_interrupted_inside_mkdtemp_leaves_no_temporary_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "mkdtemp", _interrupted_after_creating(tempfile.mkdtemp))
    with pytest.raises(KeyboardInterrupt):
        with atomic_dir(tmp_path / "out"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_a_write_interrupted_while_writing_leaves_the_target_and_nothing_else(tmp_path):
    target = tmp_path / "mesh.obj"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    with atomic_path(target) as tmp:
        tmp.write_text("whole")
    assert [p.name for p in tmp_path.iterdir()] == ["mesh.obj"] and target.read_text() == "whole"
