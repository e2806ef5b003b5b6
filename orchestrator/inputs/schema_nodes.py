"""Schema nodes: small validators that check one value of plain YAML data and normalise it.

A node's :meth:`Node.check` takes a value, its key path (a tuple of tokens) and a
:class:`Ctx`, and returns the normalised value or raises :class:`Invalid` naming the
path. :class:`Map` holds named :class:`Field` entries (node, default, doc) and may run a
``post`` check across its keys; :meth:`Node.child` walks the schema along a key path
(overrides use it to reject unknown keys before touching the data).

Nothing here knows about scenarios: the scenario's own schema is
:mod:`orchestrator.inputs.schema`.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import numbers
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from orchestrator.inputs.errors import did_you_mean as _hint
from orchestrator.inputs.yaml_io import YamlFloat, YamlInt

__all__ = ["Invalid", "describe", "Ctx", "Node", "Num", "Sign", "Str", "Bool", "Nullable", "List", "ScalarMap",
           "Leaf", "FilePath", "REQUIRED", "SUB", "Field", "Map", "dataclass_defaults", "node_at"]


class Invalid(Exception):
    """Raised inside the schema; turned into a ScenarioError with the source attached.

    Attributes
    ----------
    path : tuple of str or int
        Key path of the offending value (tokens, as :func:`orchestrator.inputs.keypath.tokens`).
    message : str
        What is wrong.
    """

    def __init__(self, path: Sequence[str | int], message: str):
        super().__init__(message)
        self.path = tuple(path)
        self.message = message


def describe(value: Any) -> str:
    """A value as an error message names it: ``null``, ``the string 'x'``, ``a list``, ``1.5``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    if isinstance(value, numbers.Number):
        return repr(value)
    return f"a {type(value).__name__}"


class Ctx:
    """What a check may need besides the value: ``base_dir``, the folder relative paths start from."""

    def __init__(self, base_dir: Path):
        self.base_dir = base_dir


class Node:
    """A schema node: ``check`` validates one value and returns its normalised form."""

    doc = ""

    def check(self, value: Any, path: tuple, ctx: Ctx) -> Any:
        raise NotImplementedError

    def child(self, token: str | int, path: tuple) -> "Node":
        raise Invalid(path, "is a single value: it has no sub-keys or items")


# Strings that read as numbers ("1.2e8", " 30"): refused with a hint to drop the quotes.
_NUMERIC_STR = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?\Z")


class Num(Node):
    """A number (or integer) within optional bounds.

    A string is an error even when it reads as a number (``"1.2e8"``): the scenario
    loader reads YAML 1.2 numbers (``1.2e8`` unquoted is a float), so a quoted number
    is a typing mistake, and wrong types are errors.
    """

    def __init__(self, gt=None, ge=None, lt=None, le=None, integer=False, unit="", why=""):
        self.gt, self.ge, self.lt, self.le, self.integer, self.unit = gt, ge, lt, le, integer, unit
        self.why = why  # appended to a range error, e.g. "(rail pads: 120-1200 MN/m, DESIGN.md §7)"
        bounds = [f"> {gt:g}" if gt is not None else "", f">= {ge:g}" if ge is not None else "",
                  f"< {lt:g}" if lt is not None else "", f"<= {le:g}" if le is not None else ""]
        self.doc = ("integer" if integer else "number") + "".join(f" {b}" for b in bounds if b)

    def check(self, value, path, ctx):
        what = "an integer" if self.integer else "a number"
        if isinstance(value, str) and _NUMERIC_STR.match(value.strip()):
            raise Invalid(path, f"expected {what}, got the string {value!r} (write numbers without quotes)")
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise Invalid(path, f"expected {what}, got {describe(value)}")
        x = float(value)
        if not math.isfinite(x):
            raise Invalid(path, f"must be a finite number, got {x}")
        if self.integer:
            if not x.is_integer():
                raise Invalid(path, f"expected an integer, got {value!r}")
            x = int(value) if isinstance(value, numbers.Integral) else int(x)
        for bound, ok, op in ((self.gt, lambda b: x > b, ">"), (self.ge, lambda b: x >= b, ">="),
                              (self.lt, lambda b: x < b, "<"), (self.le, lambda b: x <= b, "<=")):
            if bound is not None and not ok(bound):
                why = f" {self.why}" if self.why else ""
                raise Invalid(path, f"must be {op} {bound:g}{self.unit}, got {x:g}{why}")
        return x


class Sign(Node):
    """+1 or -1 (a sign convention)."""

    doc = "+1 | -1"

    def check(self, value, path, ctx):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or float(value) not in (1.0, -1.0):
            raise Invalid(path, f"must be +1 or -1, got {describe(value)}")
        return int(value)


class Str(Node):
    """A string, optionally one of ``choices`` or matching ``pattern`` (described by ``pattern_doc``)."""

    def __init__(self, choices: Sequence[str] | None = None, pattern: str | None = None,
                 pattern_doc: str = ""):
        self.choices = tuple(choices) if choices else None
        self.pattern = re.compile(pattern) if pattern else None
        self.pattern_doc = pattern_doc
        self.doc = " | ".join(self.choices) if self.choices else (pattern_doc or "string")

    def check(self, value, path, ctx):
        if isinstance(value, (YamlInt, YamlFloat)):  # e.g. rail: 60E1 (a float in YAML 1.2)
            value = value.yaml_text
        if not isinstance(value, str):
            raise Invalid(path, f"expected {self.doc if self.choices else 'a string'}, got {describe(value)}")
        if self.choices and value not in self.choices:
            allowed = ", ".join(repr(c) for c in self.choices)
            raise Invalid(path, f"must be one of {allowed}; got {value!r}{_hint(value, self.choices)}")
        if self.pattern and not self.pattern.match(value):
            raise Invalid(path, f"expected {self.pattern_doc}, got {value!r}")
        return value


class Bool(Node):
    """``true`` or ``false`` (no 0/1, no strings)."""

    doc = "true | false"

    def check(self, value, path, ctx):
        if not isinstance(value, bool):
            raise Invalid(path, f"expected true or false, got {describe(value)}")
        return value


class Nullable(Node):
    """``null`` or what ``inner`` accepts."""

    def __init__(self, inner: Node):
        self.inner = inner
        self.doc = f"{inner.doc} or null"

    def check(self, value, path, ctx):
        return None if value is None else self.inner.check(value, path, ctx)

    def child(self, token, path):
        return self.inner.child(token, path)


class List(Node):
    """A list of ``item`` values, optionally of exactly ``length`` items."""

    def __init__(self, item: Node, length: int | None = None):
        self.item, self.length = item, length
        self.doc = f"list of {length} {item.doc}" if length else f"list of {item.doc}"

    def check(self, value, path, ctx):
        if not isinstance(value, (list, tuple)):
            raise Invalid(path, f"expected a list, got {describe(value)}")
        if self.length is not None and len(value) != self.length:
            raise Invalid(path, f"expected exactly {self.length} items, got {len(value)}")
        return [self.item.check(v, path + (i,), ctx) for i, v in enumerate(value)]

    def child(self, token, path):
        if not isinstance(token, int):
            raise Invalid(path, f"is a list: use an index such as [0], not .{token}")
        return self.item


class ScalarMap(Node):
    """Free-form mapping name -> scalar (FMU start values)."""

    doc = "mapping name -> number | bool | string"

    def check(self, value, path, ctx):
        if not isinstance(value, Mapping):
            raise Invalid(path, f"expected a mapping, got {describe(value)}")
        out = {}
        for k, v in value.items():
            if not isinstance(k, str) or not k:
                raise Invalid(path, f"keys must be non-empty strings, got {describe(k)}")
            if isinstance(v, bool) or isinstance(v, str):
                out[k] = v
            elif isinstance(v, numbers.Integral):
                out[k] = int(v)
            elif isinstance(v, numbers.Real) and math.isfinite(float(v)):
                out[k] = float(v)
            else:
                raise Invalid(path + (k,), f"expected a number, boolean or string, got {describe(v)}")
        return out

    def child(self, token, path):
        if not isinstance(token, str):
            raise Invalid(path, "is a mapping: use a name, not an index")
        return Leaf()


class Leaf(Node):
    """Anything (a free-form value below a :class:`ScalarMap`; the map checks it)."""

    def check(self, value, path, ctx):
        return value


class FilePath(Node):
    """A file path, resolved against the scenario's folder; must exist."""

    def __init__(self, suffix: str | None = None, keywords: Sequence[str] = ()):
        self.suffix, self.keywords = suffix, tuple(keywords)
        what = f"path to a {suffix} file" if suffix else "path to a file"
        self.doc = " | ".join(self.keywords + (what,))

    def check(self, value, path, ctx):
        if not isinstance(value, str) or not value.strip():
            raise Invalid(path, f"expected {self.doc}, got {describe(value)}")
        if value in self.keywords:
            return value
        if self.suffix and not value.lower().endswith(self.suffix):
            raise Invalid(path, f"expected {self.doc}, got {value!r}{_hint(value, self.keywords)}")
        try:   # the operating system may refuse the name itself (too long, a NUL byte)
            p = Path(os.path.expanduser(value))
            p = (p if p.is_absolute() else ctx.base_dir / p).resolve()
            found, is_file = p.exists(), p.is_file()
        except (OSError, ValueError) as exc:
            raise Invalid(path, f"{value[:60]!r}{'...' if len(value) > 60 else ''} is not a usable path "
                                f"({getattr(exc, 'strerror', None) or exc})") from None
        if not found:
            raise Invalid(path, f"file not found: {value!r} (looked for {p})")
        if not is_file:
            raise Invalid(path, f"{value!r} is a folder, expected a file")
        return str(p)


REQUIRED = object()  # Field.default: the key must be given
SUB = object()  # Field.default: fill from the sub-mapping's own defaults


@dataclass
class Field:
    """One key of a :class:`Map`: its node, default (or :data:`REQUIRED` / :data:`SUB`) and doc."""

    node: Node
    default: Any = REQUIRED
    doc: str = ""  # unit / meaning, for scenario_keys()


class Map(Node):
    """A mapping with known keys (:class:`Field` each); ``post(out, given, path, ctx)`` checks across keys."""

    doc = "mapping"

    def __init__(self, fields: dict[str, Field], post: Callable | None = None):
        self.fields, self.post = fields, post

    def check(self, value, path, ctx):
        if not isinstance(value, Mapping):
            raise Invalid(path, f"expected a mapping, got {describe(value)}")
        for k in value:
            if not isinstance(k, str):
                raise Invalid(path, f"keys must be strings, got {describe(k)}")
            if k not in self.fields:
                raise Invalid(path + (k,), _unknown(k, self.fields))
        out = {}
        for name, f in self.fields.items():
            if name in value:
                out[name] = f.node.check(value[name], path + (name,), ctx)
            elif f.default is REQUIRED:
                raise Invalid(path + (name,), "required key is missing")
            elif f.default is SUB:
                out[name] = f.node.check({}, path + (name,), ctx)
            else:
                out[name] = copy.deepcopy(f.default)
        if self.post is not None:
            out = self.post(out, value, path, ctx)
        return out

    def child(self, token, path):
        if not isinstance(token, str):
            raise Invalid(path, "is a mapping: use a key, not an index")
        if token not in self.fields:
            raise Invalid(path + (token,), _unknown(token, self.fields))
        return self.fields[token].node


def _unknown(key: str, known: Iterable[str]) -> str:
    """The message for an unknown key: a "did you mean" hint, or the allowed keys."""
    known = list(known)
    hint = _hint(key, known)
    if hint:
        return f"unknown key {key!r}{hint}"
    return f"unknown key {key!r}; allowed here: {', '.join(known)}"


def dataclass_defaults(cls) -> dict[str, Any]:
    """Default value of every field of dataclass ``cls`` (default_factory called)."""
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def node_at(root: Node, toks: Sequence[str | int]) -> Node:
    """The node of ``root``'s schema that key path ``toks`` leads to.

    Raises
    ------
    Invalid
        A token the schema does not have there (unknown key, index into a mapping, ...).
    """
    node = root
    for i, tok in enumerate(toks):
        node = node.child(tok, tuple(toks[:i]))
    return node
