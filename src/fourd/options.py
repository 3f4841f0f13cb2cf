"""Building a method's frozen ``Options`` dataclass from keyword arguments or ``key=value`` text."""

from __future__ import annotations

import dataclasses
import inspect
import logging
import re
import types
import typing
from collections.abc import Mapping
from typing import Any

from fourd.errors import InputError

log = logging.getLogger("fourd.options")

#: Old option names still accepted (with a warning) by :func:`make_options`: old -> new.
RENAMED = {"normal_k": "normals_k"}

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

    Raises :class:`InputError` for an unknown key, listing the valid ones. An old name of
    :data:`RENAMED` is taken as its new one, with a warning.
    """
    values = dict(values or {})
    fields = {f.name: f for f in dataclasses.fields(options_class)}
    for old, new in RENAMED.items():
        if old in values and old not in fields and new in fields:
            if new in values:
                raise InputError(f"option {old} is the old name of {new}: give only {new}")
            log.warning("option %s is now called %s", old, new)
            values[new] = values.pop(old)
    unknown = sorted(set(values) - set(fields))
    if unknown:
        where = f" for method {method}" if method else ""
        raise InputError(
            f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}{where}; "
            f"valid keys: {', '.join(sorted(fields))}"
            + (f" (fourd options {method} says what each does)" if method else "")
        )
    hints = typing.get_type_hints(options_class)
    converted = {}
    for key, value in values.items():
        converted[key] = _convert(value, hints[key], key) if isinstance(value, str) else value
    try:
        return options_class(**converted)
    except (TypeError, ValueError) as error:
        raise InputError(f"invalid options{' for ' + method if method else ''}: {error}") from None


def with_overrides(options_class, options=None, *, what: str, **overrides):
    """``options`` (default ``options_class()``) with the fields in ``overrides`` replaced;
    :class:`InputError` naming the unknown ones (``unknown {what} option(s) ...; valid: ...``)."""
    valid = {f.name for f in dataclasses.fields(options_class)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        raise InputError(
            f"unknown {what} option(s) {', '.join(unknown)}; valid: {', '.join(sorted(valid))}"
        )
    base = options_class() if options is None else options
    return dataclasses.replace(base, **overrides) if overrides else base


def parse_assignments(assignments: list[str]) -> dict[str, str]:
    """Parse ``["key=value", ...]`` (the command line's ``--set``) into a dict of strings."""
    result = {}
    for item in assignments:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--set expects key=value, got {item!r}")
        result[key.strip()] = value.strip()
    return result


@dataclasses.dataclass(frozen=True)
class OptionDoc:
    """One documented option of a method: its name, type as written in the docstring, default
    value and description (the docstring's text, whitespace collapsed); ``entry`` names every
    field the same docstring entry describes (``a, b : float``), itself included."""

    name: str
    type: str
    default: Any
    description: str
    entry: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        """The description without reStructuredText markup (``x`` -> x, :func:`~.a.b` -> b)."""
        text = re.sub(r":\w+:`~?\.?(?:[\w.]*\.)?([\w]+)`", r"\1", self.description)
        return text.replace("``", "")

    @property
    def summary(self) -> str:
        """The first sentence of :attr:`text`; a long parenthesis in it is cut at its first
        ``;`` (the measurements that follow are in the whole text)."""
        text = self.text
        match = re.search(r"(?<![ .][a-z])\.(\s|$)", text)
        return _shorten_parentheses(text if match is None else text[: match.start() + 1])


def _shorten_parentheses(text: str, longest: int = 100) -> str:
    """Cut each top-level parenthesis of ``text`` longer than ``longest`` characters after its
    first clause (``(64 in the paper; 32 here: ...)`` -> ``(64 in the paper; ...)``)."""
    out, depth, start = [], 0, 0
    for i, char in enumerate(text):
        if char == "(":
            if depth == 0:
                out.append(text[start:i])
                start = i
            depth += 1
        elif char == ")" and depth:
            depth -= 1
            if depth == 0:
                inner = text[start + 1:i]
                cut = re.search(r"[;:] ", inner)
                if len(inner) > longest and cut:
                    inner = inner[: cut.start() + 1] + " ..."
                out.append(f"({inner})")
                start = i + 1
    out.append(text[start:])
    return "".join(out)


def option_docs(options_class) -> list[OptionDoc]:
    """The options of ``options_class`` in field order, described by the ``Attributes`` section
    of its numpy-style docstring (an entry may name several fields: ``a, b : float``). A field
    the docstring does not describe gets an empty description."""
    doc = inspect.cleandoc(options_class.__doc__ or "")
    lines = doc.splitlines()
    start = next((i + 2 for i, line in enumerate(lines[:-1])
                  if line.strip() == "Attributes" and set(lines[i + 1].strip()) == {"-"}), len(lines))
    entries: dict[str, tuple[str, list[str], tuple[str, ...]]] = {}
    current: list[str] | None = None
    for i in range(start, len(lines)):
        line = lines[i]
        if i + 1 < len(lines) and line.strip() and set(lines[i + 1].strip()) == {"-"}:
            break  # the next section
        header = re.match(r"^([A-Za-z_][\w, ]*?) : (.*)$", line)
        if header:
            current = []
            names = [name.strip() for name in header.group(1).split(",")]
            types_ = [t.strip() for t in header.group(2).split(",")]
            if len(types_) != len(names):  # `a, b : float`: one type for all
                types_ = [header.group(2).strip()] * len(names)
            for name, type_text in zip(names, types_, strict=True):
                entries[name] = (type_text, current, tuple(names))
        elif current is not None and line.strip():
            current.append(line.strip())
    result = []
    fields = [field.name for field in dataclasses.fields(options_class)]
    # a subclass (a composition's options) describes its own fields; the rest come from its bases
    inherited = {}
    for base in options_class.__mro__[1:]:
        if dataclasses.is_dataclass(base) and base.__doc__:
            for doc in option_docs(base):
                inherited.setdefault(doc.name, (doc.type, [doc.description] if doc.description else [], doc.entry))
    for field in dataclasses.fields(options_class):
        fallback = inherited.get(field.name, (str(field.type), [], (field.name,)))
        type_text, text, names = entries.get(field.name, fallback)
        default = field.default if field.default is not dataclasses.MISSING else None
        entry = tuple(name for name in names if name in fields) or (field.name,)
        result.append(OptionDoc(field.name, type_text, default, " ".join(text), entry))
    return result


def format_options(
    options_class, common: tuple[str, ...] | None = None, *, everything: bool = False,
    method: str = "", width: int = 96,
) -> str:
    """The text of ``fourd options METHOD``.

    The ``common`` options (a method's ``COMMON_OPTIONS``; None: all of them) come first,
    each with its whole description; the others follow under a heading with ``everything``,
    else only their names. Fields described by one docstring entry (``a, b : float``) are
    shown together, with their description once.
    """
    import textwrap

    docs = option_docs(options_class)
    by_name = {doc.name: doc for doc in docs}
    common = tuple(by_name) if common is None else tuple(common)
    unknown = [name for name in common if name not in by_name]
    if unknown:
        raise ValueError(f"common options {unknown} are not fields of {options_class.__name__}")

    def groups(names) -> list[list[OptionDoc]]:
        """The entries of ``names``, in order, each entry once with all of its fields."""
        seen: set[str] = set()
        out = []
        for name in names:
            if name in seen:
                continue
            group = [by_name[n] for n in by_name[name].entry]
            seen.update(doc.name for doc in group)
            out.append(group)
        return out

    def block(group: list[OptionDoc]) -> str:
        head = ", ".join(f"{doc.name} = {doc.default!r}  ({doc.type})" for doc in group)
        body = textwrap.fill(group[0].text or "(undocumented)", width=width,
                             initial_indent="      ", subsequent_indent="      ")
        return f"  {head}\n{body}"

    first = groups(common)
    shown = {doc.name for group in first for doc in group}
    rest = groups(name for name in by_name if name not in shown)
    call = f"fourd options {method}" if method else "fourd options METHOD"
    set_hint = f"fourd reconstruct --method {method} --set KEY=VALUE" if method else "--set KEY=VALUE"
    title = f"options of method {method}" if method else f"options of {options_class.__name__}"
    blocks = [f"{title} ({set_hint}):"]
    if rest and everything:
        blocks.append("the options to change first:")
    blocks += [block(group) for group in first]
    if rest and everything:
        blocks.append("expert options:")
        blocks += [block(group) for group in rest]
    elif rest:
        names = [doc.name for group in rest for doc in group]
        listing = textwrap.fill(", ".join(names), width=width, initial_indent="  ",
                                subsequent_indent="  ")
        blocks.append(f"{len(names)} expert options ({call} --all describes them):\n{listing}")
    return "\n\n".join(blocks)
