"""The registry of reconstruction methods.

Each method module exposes ``Options`` (a frozen dataclass with documented defaults),
``reconstruct(seq, options) -> AnimatedMesh | MeshSequence`` and a module-level constant
``MIN_FRAMES`` (1 for per-frame methods, 2 for sequence methods); a method with figures of
its own (flow's mass conservation error) also has ``reconstruct_with_diagnostics(seq,
options) -> (result, dict)``, which ``fourd bench`` reports. Modules are imported only
when used, so a broken or slow-to-import method never affects the others.
"""

from __future__ import annotations

import importlib
import logging
from types import ModuleType

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.options import make_options
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods")

#: name -> module path, in order of preference for the default method.
METHODS: dict[str, str] = {
    "kinematic": "fourd.methods.kinematic",
    "flow": "fourd.methods.flow",
    "perframe": "fourd.methods.perframe",
}

#: The method ``fourd reconstruct`` and ``fourd demo`` use when none is named.
DEFAULT_METHOD = "perframe"


def available_methods() -> list[str]:
    """Names of the methods whose module imports on this installation."""
    names = []
    for name in METHODS:
        try:
            method_module(name)
        except InputError:
            continue
        names.append(name)
    return names


def method_module(name: str) -> ModuleType:
    """The module implementing method ``name``; :class:`InputError` for an unknown name."""
    if name not in METHODS:
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    try:
        return importlib.import_module(METHODS[name])
    except ModuleNotFoundError as error:
        if error.name == METHODS[name]:
            raise InputError(f"method {name!r} is not available in this version") from None
        raise


def method_options(name: str, values: dict | None = None):
    """The method's ``Options`` built from ``values`` (strings are converted by field type)."""
    return make_options(method_module(name).Options, values, method=name)


def reconstruct(
    seq: PointCloudSequence, method: str | None = None, options=None, **values
) -> AnimatedMesh | MeshSequence:
    """Reconstruct ``seq`` with ``method`` (default :data:`DEFAULT_METHOD`).

    Options are either an ``Options`` instance of that method or keyword values.
    """
    module, options = _method_and_options(seq, method, options, values)
    return module.reconstruct(seq, options)


def reconstruct_with_diagnostics(
    seq: PointCloudSequence, method: str | None = None, options=None, **values
) -> tuple[AnimatedMesh | MeshSequence, dict]:
    """:func:`reconstruct`, plus the method's own figures as a dict of floats (e.g. ``flow``:
    ``mass_conservation_error``). A method module that has such figures defines
    ``reconstruct_with_diagnostics(seq, options) -> (result, dict)``; the others give ``{}``.
    """
    module, options = _method_and_options(seq, method, options, values)
    hook = getattr(module, "reconstruct_with_diagnostics", None)
    if hook is None:
        return module.reconstruct(seq, options), {}
    return hook(seq, options)


def _method_and_options(seq, method, options, values):
    name = method or DEFAULT_METHOD
    module = method_module(name)
    if options is None:
        options = method_options(name, values)
    elif values:
        raise InputError("give either an Options instance or keyword options, not both")
    if not isinstance(seq, PointCloudSequence):
        raise InputError(f"expected a PointCloudSequence, got {type(seq).__name__}")
    minimum = getattr(module, "MIN_FRAMES", 1)
    if len(seq) < minimum:
        raise InputError(f"method {name!r} needs at least {minimum} frames, the input has {len(seq)}")
    log.info("reconstructing %d frames with %s", len(seq), name)
    return module, options
