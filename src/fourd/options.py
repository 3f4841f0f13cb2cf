"""Building a method's frozen ``Options`` dataclass from keyword arguments or ``key=value`` text."""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any

from fourd.errors import InputError

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


def _convert(text: str, annotation, key: str):
    """Convert ``text`` to the type named by a dataclass field annotation."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if text.lower() in {"none", "null", ""}:
            return None
        errors = []
        for arg in args:
            try:
                return _convert(text, arg, key)
            except InputError as error:
                errors.append(str(error))
        raise InputError(errors[0])
    if origin is typing.Literal:
        choices = typing.get_args(annotation)
        if text not in choices:
            raise InputError(f"option {key} must be one of {', '.join(map(str, choices))}, got {text!r}")
        return text
    if origin in (tuple, list):
        inner = typing.get_args(annotation)[0] if typing.get_args(annotation) else str
        parts = [p for p in text.replace(",", " ").split() if p]
        return tuple(_convert(p, inner, key) for p in parts)
    try:
        if annotation is bool:
            if text.lower() in _TRUE:
                return True
            if text.lower() in _FALSE:
                return False
            raise ValueError(text)
        if annotation is int:
            return int(text)
        if annotation is float:
            return float(text)
    except ValueError:
        raise InputError(f"option {key} expects {annotation.__name__}, got {text!r}") from None
    return text


def make_options(options_class, values: Mapping[str, Any] | None = None, *, method: str = ""):
    """Instantiate ``options_class`` from ``values``; string values are converted by field type.

    Raises :class:`InputError` for an unknown key, listing the valid ones.
    """
    values = dict(values or {})
    fields = {f.name: f for f in dataclasses.fields(options_class)}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        where = f" for method {method}" if method else ""
        raise InputError(
            f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}{where}; "
            f"valid keys: {', '.join(sorted(fields))}"
        )
    hints = typing.get_type_hints(options_class)
    converted = {}
    for key, value in values.items():
        converted[key] = _convert(value, hints[key], key) if isinstance(value, str) else value
    try:
        return options_class(**converted)
    except (TypeError, ValueError) as error:
        raise InputError(f"invalid options{' for ' + method if method else ''}: {error}") from None


def parse_assignments(assignments: list[str]) -> dict[str, str]:
    """Parse ``["key=value", ...]`` (the command line's ``--set``) into a dict of strings."""
    result = {}
    for item in assignments:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--set expects key=value, got {item!r}")
        result[key.strip()] = value.strip()
    return result
