"""Key paths into a scenario mapping: ``track.ballast.voids[0].gaps``.

The one place that turns a key path into tokens and walks a raw (validated) scenario
mapping with them: overrides (``--set``), sweeps (``--vary``), the cause registry and the
calibration's parameters all use it.
"""
from __future__ import annotations

import re
from typing import Any, Mapping

KEY_PATH = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*(\.[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*)*\Z")


class KeyPathError(ValueError):
    """Not a key path like ``track.ballast.voids[0].gaps``."""


def tokens(key: str) -> tuple[str | int, ...]:
    """``"a.b[0].c"`` -> ``("a", "b", 0, "c")``.

    Raises
    ------
    KeyPathError
        ``key`` is not a key path.
    """
    key = key.strip() if isinstance(key, str) else key
    if not isinstance(key, str) or not KEY_PATH.match(key):
        raise KeyPathError(f"{key!r} is not a key path like track.ballast.voids[0].gaps")
    out: list[str | int] = []
    for part in key.split("."):
        name, *indices = re.split(r"\[", part)
        out.append(name)
        out.extend(int(i.rstrip("]")) for i in indices)
    return tuple(out)


def get(raw: Mapping, key: str) -> Any:
    """The value at ``key`` in ``raw``; ``None`` when the path is absent."""
    node: Any = raw
    for tok in tokens(key):
        try:
            node = node[tok]
        except (KeyError, IndexError, TypeError):
            return None
    return node


def set(raw: dict, key: str, value: Any) -> None:  # noqa: A001 - the pair get/set reads as the API
    """Set ``key`` in ``raw`` in place; every container on the path must exist."""
    toks = tokens(key)
    node: Any = raw
    for tok in toks[:-1]:
        node = node[tok]
    node[toks[-1]] = value


__all__ = ["KEY_PATH", "KeyPathError", "tokens", "get", "set"]
