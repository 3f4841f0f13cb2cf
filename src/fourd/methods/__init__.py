"""The registry of reconstruction methods.

Each method module keeps the contract of :mod:`fourd.methods.base` (``Options``,
``reconstruct``, ``MIN_FRAMES``, ``RESULT``, optional typed diagnostics). Modules are
imported only when used, so a broken or slow-to-import method never affects the others.
Method packages never import each other; a combination of methods (``watertight``,
``auto``) is a module of its own here that calls their public functions.
"""

from __future__ import annotations

import importlib
import logging
from types import ModuleType

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.methods.base import Reconstruction
from fourd.options import make_options
from fourd.preflight import check_input
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods")

#: name -> module path, in order of preference for the default method.
METHODS: dict[str, str] = {
    "auto": "fourd.methods.auto",
    "kinematic": "fourd.methods.kinematic",
    "flow": "fourd.methods.flow",
    "surfels": "fourd.methods.surfels",
    "watertight": "fourd.methods.watertight",
    "learned": "fourd.methods.learned",
    "garment": "fourd.methods.garment",
    "assembly": "fourd.methods.assembly",
    "perframe": "fourd.methods.perframe",
}

#: The method ``fourd reconstruct`` and ``fourd demo`` use when none is named.
DEFAULT_METHOD = "auto"

#: Old spellings still accepted: (method, option, value) -> the method that replaced them
#: (the option is dropped, the other options carry over).
ALIASES: dict[tuple[str, str, str], str] = {
    ("flow", "coherent", "true"): "watertight",
}


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
    name, values = resolve_alias(name, values)
    return make_options(method_module(name).Options, values, method=name)


def resolve_alias(name: str, values: dict | None) -> tuple[str, dict]:
    """``(method, values)`` with an old spelling (:data:`ALIASES`) replaced by its method:
    ``("flow", {"coherent": "true", "resolution": 64})`` -> ``("watertight", {"resolution":
    64})``; a false value of the old option is dropped."""
    values = dict(values or {})
    for (old, option, value), new in ALIASES.items():
        if name == old and option in values:
            given = str(values.pop(option)).strip().lower()
            if given in (value, "1", "yes", "on"):
                log.warning("%s:%s=%s is now the method %r", old, option, value, new)
                return new, values
    return name, values


def reconstruct(
    seq: PointCloudSequence,
    method: str | None = None,
    options=None,
    *,
    check_memory: bool = True,
    **values,
) -> AnimatedMesh | MeshSequence:
    """Reconstruct ``seq`` with ``method`` (default :data:`DEFAULT_METHOD`).

    Options are either an ``Options`` instance of that method or keyword values. Before the
    method runs, :func:`fourd.preflight.check_input` checks the input against them (frames
    with too few points, output times outside the input's, and, unless ``check_memory`` is
    False, the estimated memory against the machine's).
    """
    module, options = _method_and_options(seq, method, options, values, check_memory)
    return module.reconstruct(seq, options)


def reconstruct_with_diagnostics(
    seq: PointCloudSequence,
    method: str | None = None,
    options=None,
    *,
    check_memory: bool = True,
    **values,
) -> Reconstruction:
    """:func:`reconstruct`, plus the method's own figures: a :class:`~.base.Reconstruction`
    whose ``diagnostics`` is the method's typed figures (``flow``:
    :class:`~fourd.methods.flow.FlowDiagnostics`), or None for a method without any."""
    module, options = _method_and_options(seq, method, options, values, check_memory)
    hook = getattr(module, "reconstruct_with_diagnostics", None)
    if hook is None:
        return Reconstruction(module.reconstruct(seq, options), None)
    return hook(seq, options)


def _method_and_options(seq, method, options, values, check_memory=True):
    name = method or DEFAULT_METHOD
    if options is None:
        name, values = resolve_alias(name, values)
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
    check_input(seq, name, module, options, memory=check_memory)
    log.info("reconstructing %d frames with %s", len(seq), name)
    return module, options
