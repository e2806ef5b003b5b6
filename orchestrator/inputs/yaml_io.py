"""YAML with the scenario rules: YAML 1.2 numbers, no duplicate keys, one-line errors.

PyYAML follows YAML 1.1: ``1e8`` and ``1.2e8`` stay strings (the exponent needs a dot
*and* a sign), and ``1:12`` is the sexagesimal integer 72. :class:`YamlLoader` reads
ints and floats as YAML 1.2 (core schema) does, so ``crossing: 1:12`` is the string
"1:12" and ``stiffness: 1.2e8`` is a float, and it rejects a key given twice in one
mapping. :class:`YamlDumper` writes what the loader reads back unchanged.

Scenario files, sensor layouts, sweep files and override values (``--set``) are all
read with these rules.
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import yaml

from orchestrator.inputs.errors import ScenarioError

__all__ = ["YamlLoader", "YamlDumper", "YamlInt", "YamlFloat", "read_yaml", "dump_yaml",
           "yaml_error_message"]

_INT_TAG, _FLOAT_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"


class YamlLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """SafeLoader with YAML 1.2 numbers and no duplicate keys (see the module docstring).

    On libyaml's parser where PyYAML has it (its wheels do): the same events, nodes and marks,
    parsed ~4x faster (the default layout's 23 sensors: 23 -> 5 ms); the constructors and
    resolvers above it stay these Python ones."""


YamlLoader.yaml_implicit_resolvers = {
    ch: [(tag, rx) for tag, rx in resolvers if tag not in (_INT_TAG, _FLOAT_TAG)]
    for ch, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
YamlLoader.add_implicit_resolver(_INT_TAG, re.compile(r"[-+]?[0-9]+\Z|0o[0-7]+\Z|0x[0-9a-fA-F]+\Z"),
                                 list("-+0123456789"))
YamlLoader.add_implicit_resolver(
    _FLOAT_TAG,
    re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?\Z|[-+]?\.(inf|Inf|INF)\Z|\.(nan|NaN|NAN)\Z"),
    list("-+0123456789."))


class YamlInt(int):
    """An int read from YAML that remembers its text (``yaml_text``)."""


class YamlFloat(float):
    """A float read from YAML that remembers its text: where the schema wants a
    string, the text is used, so ``rail: 60E1`` means "60E1", not 600.0."""


def _construct_int(loader, node):
    """A YAML 1.2 int node -> :class:`YamlInt` (decimal, ``0o`` octal or ``0x`` hex)."""
    text = loader.construct_scalar(node)
    if text.startswith("0o"):
        value = YamlInt(int(text[2:], 8))
    elif text.startswith("0x"):
        value = YamlInt(int(text[2:], 16))
    else:
        value = YamlInt(int(text, 10))
    value.yaml_text = text
    return value


def _construct_float(loader, node):
    """A YAML 1.2 float node -> :class:`YamlFloat` (``.inf``, ``-.inf`` and ``.nan`` included)."""
    text = loader.construct_scalar(node)
    low = text.lower()
    if low.endswith(".inf"):
        value = YamlFloat(-math.inf if low.startswith("-") else math.inf)
    elif low == ".nan":
        value = YamlFloat(math.nan)
    else:
        value = YamlFloat(text)
    value.yaml_text = text
    return value


def _construct_mapping(loader, node, deep=False):
    """A mapping node -> dict; a key given twice is an error naming both lines."""
    # Duplicates among the mapping's own keys; keys brought in by a merge (<<: *anchor)
    # may legitimately be overridden, so they are not compared.
    seen = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=deep)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(None, None, "a mapping key must be a scalar",
                                                    key_node.start_mark) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r} (first at line {seen[key] + 1})", key_node.start_mark)
        seen[key] = key_node.start_mark.line
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


class YamlDumper(yaml.SafeDumper):
    """SafeDumper that quotes every string :class:`YamlLoader` would read as a number (``"60E1"``)."""


YamlDumper.yaml_implicit_resolvers = {ch: list(r) for ch, r in YamlLoader.yaml_implicit_resolvers.items()}

YamlLoader.add_constructor(_INT_TAG, _construct_int)
YamlLoader.add_constructor(_FLOAT_TAG, _construct_float)
YamlLoader.construct_mapping = _construct_mapping  # type: ignore[assignment]


def yaml_error_message(exc: yaml.YAMLError) -> str:
    """``"line L, column C: invalid YAML: <problem>"`` for a PyYAML error (no position when unknown)."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    problem = getattr(exc, "problem", None) or str(exc)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return f"{where}invalid YAML: {problem}"


def _parse_yaml(text: str, source: str) -> Any:
    """YAML text -> plain data (dicts, lists, scalars) with the scenario rules.

    Raises
    ------
    ScenarioError
        Not valid YAML (with line and column); names ``source``.
    """
    try:
        return yaml.load(text, Loader=YamlLoader)  # noqa: S506 - YamlLoader is a SafeLoader
    except yaml.YAMLError as exc:
        raise ScenarioError(yaml_error_message(exc), source=source) from None


def read_yaml(path: str | os.PathLike) -> Any:
    """Read a YAML file with the scenario rules (YAML 1.2 numbers, no duplicate keys).

    Raises
    ------
    ScenarioError
        File missing or unreadable, or not valid YAML (with line and column).
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError("file not found", source=source) from None
    except IsADirectoryError:
        raise ScenarioError("is a folder, expected a YAML file", source=source) from None
    except UnicodeDecodeError:
        raise ScenarioError("is not a UTF-8 text file", source=source) from None
    except OSError as exc:
        raise ScenarioError(f"cannot read: {exc.strerror or exc}", source=source) from None
    return _parse_yaml(text, source)


def dump_yaml(data: Any) -> str:
    """Plain data -> YAML text that :class:`YamlLoader` reads back to equal data (key order kept)."""
    return yaml.dump(data, Dumper=YamlDumper, sort_keys=False, default_flow_style=None)
