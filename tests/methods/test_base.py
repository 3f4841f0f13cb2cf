"""The method contract (fourd.methods.base) on every registry entry, and the rule that method
packages never import each other."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import fourd
import fourd.methods
from fourd.methods import DEFAULT_METHOD, METHODS, method_module
from fourd.methods.base import check_method_module, diagnostic_figures

#: Registry entries that combine methods: they may import the methods they combine.
COMPOSITIONS = {"auto", "learned", "watertight"}
SOURCE = Path(fourd.methods.__file__).parent


@pytest.mark.parametrize("name", list(METHODS))
def test_every_registry_entry_keeps_the_method_contract(name):
    assert check_method_module(method_module(name)) == []


def test_the_contract_check_names_what_is_missing():
    class Module:
        @dataclasses.dataclass
        class Options:
            x: int = 1

        MIN_FRAMES = 0

    problems = check_method_module(Module)
    assert "Options is not frozen" in problems
    assert any("MIN_FRAMES" in p for p in problems)
    assert any("RESULT" in p for p in problems)
    assert "reconstruct is missing" in problems


def test_the_contract_check_names_a_bad_memory_hook():
    class Module:
        @dataclasses.dataclass(frozen=True)
        class Options:
            resolution: int = 32

        MIN_FRAMES = 1
        RESULT = fourd.AnimatedMesh
        estimate_peak_bytes = 3
        MEMORY_OPTIONS = ("grid",)

        @staticmethod
        def reconstruct(seq, options=None):
            return None

    problems = check_method_module(Module)
    assert "estimate_peak_bytes is not callable" in problems
    assert any("MEMORY_OPTIONS" in p and "grid" in p for p in problems)


def test_the_contract_check_names_a_bad_common_options_list():
    class Module:
        @dataclasses.dataclass(frozen=True)
        class Options:
            resolution: int = 32
            seed: int = 0

        MIN_FRAMES = 1
        RESULT = fourd.AnimatedMesh
        COMMON_OPTIONS = ("resolution", "grid")

        @staticmethod
        def reconstruct(seq, options=None):
            return None

    assert any("COMMON_OPTIONS" in p and "grid" in p for p in check_method_module(Module))
    Module.COMMON_OPTIONS = ("resolution",)
    assert check_method_module(Module) == []


@pytest.mark.parametrize("name", ["flow", "watertight", "auto"])
def test_the_grid_methods_estimate_their_memory(name):
    """The memory hook of every method with a grid: bytes from the options and the data, the
    flow's at the same resolution for the compositions, none for an open surface (auto)."""
    from fourd.methods import flow

    rng = np.random.default_rng(0)
    seq = fourd.PointCloudSequence.from_arrays([rng.normal(size=(500, 3)) for _ in range(3)])
    module = method_module(name)
    options = module.Options(resolution=24)
    assert module.MEMORY_OPTIONS[0] == "resolution"
    estimate = module.estimate_peak_bytes(seq, options)
    assert isinstance(estimate, int)
    assert estimate == flow.estimate_peak_bytes(seq, flow.Options(resolution=24)) > 0
    if name == "auto":
        assert module.estimate_peak_bytes(seq, module.Options(surface="open")) == 0


def test_the_default_method_gives_one_connectivity():
    from fourd import AnimatedMesh

    result = method_module(DEFAULT_METHOD).RESULT
    assert result is AnimatedMesh or AnimatedMesh in result


def test_diagnostics_are_typed_figures():
    @dataclasses.dataclass(frozen=True)
    class Figures:
        error: float
        optional: float | None = None

    assert diagnostic_figures(Figures(0.5)) == {"error": 0.5}
    with pytest.raises(TypeError):
        diagnostic_figures({"error": 0.5})


def _imported_modules(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _package_of(module: str) -> str | None:
    parts = module.split(".")
    if parts[:2] != ["fourd", "methods"] or len(parts) < 3:
        return None
    return parts[2] if parts[2] in METHODS else None


@pytest.mark.parametrize("name", sorted(set(METHODS) - COMPOSITIONS))
def test_no_method_imports_another(name):
    path = SOURCE / name
    files = sorted(path.rglob("*.py")) if path.is_dir() else [SOURCE / f"{name}.py"]
    assert files
    for file in files:
        others = {_package_of(m) for m in _imported_modules(file)} - {None, name}
        assert not others, f"{file.relative_to(SOURCE)} imports the method(s) {sorted(others)}"


def test_the_import_walk_sees_a_cross_import(tmp_path):
    file = tmp_path / "x.py"
    file.write_text("from fourd.methods import kinematic\nimport fourd.methods.flow.post\n")
    packages = {_package_of(m) for m in _imported_modules(file)} - {None}
    assert packages == {"kinematic", "flow"}
