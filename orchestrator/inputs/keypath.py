"""Key paths into a scenario mapping: ``track.ballast.voids[0].gaps``.

The one place that turns a key path into tokens (:func:`tokens`), tokens back into a key
path (:func:`join`) and walks a raw scenario mapping with them (:func:`get`, :func:`set`):
overrides (``--set``), sweeps (``--vary``), the cause registry, the calibration's
parameters and the scenario schema's error messages all use it.
"""
from __future__ import annotations

import re
from typing import Any, Mapping, Sequence

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
KEY_PATH = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*(\.[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*)*\Z")


class KeyPathError(ValueError):
    """Not a key path like ``track.ballast.voids[0].gaps``."""


class PathError(LookupError):
    """The mapping has no container where a key path needs one.

    Attributes
    ----------
    toks : tuple of str or int
        The key path's tokens.
    depth : int
        Index of the token that could not be followed: ``toks[:depth]`` leads to
        ``container``, which is not a mapping (a name follows) or not a list long
        enough (an index follows).
    container : object
        What ``toks[:depth]`` leads to (``None`` when it is absent).
    """

    def __init__(self, toks: tuple[str | int, ...], depth: int, container: Any):
        self.toks, self.depth, self.container = toks, depth, container
        super().__init__(f"{join(toks[:depth]) or 'the mapping'} has no {join(toks[depth:depth + 1])!r}")

    def __reduce__(self):
        return (type(self), (self.toks, self.depth, self.container))


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


def join(toks: Sequence[str | int]) -> str:
    """``("a", "b", 0, "c")`` -> ``"a.b[0].c"``: the inverse of :func:`tokens`.

    A name that would be ambiguous written with dots (or holds odd characters) is
    written ``['name']``.
    """
    out = ""
    for tok in toks:
        if isinstance(tok, int):
            out += f"[{tok}]"
        elif _IDENT.match(tok):
            out += f".{tok}" if out else tok
        else:
            out += f"[{tok!r}]"
    return out


def get(raw: Mapping, key: str) -> Any:
    """The value at ``key`` in ``raw``; ``None`` when the path is absent."""
    node: Any = raw
    for tok in tokens(key):
        try:
            node = node[tok]
        except (KeyError, IndexError, TypeError):
            return None
    return node


def set(raw: dict, key: str | Sequence[str | int], value: Any, *,  # noqa: A001 - get/set reads as the API
        create: bool = False) -> None:
    """Set ``key`` (a key path or its tokens) in ``raw`` in place.

    Parameters
    ----------
    raw : dict
        Plain YAML data (dicts and lists).
    key : str or sequence of str or int
        ``"a.b[0].c"`` or ``("a", "b", 0, "c")``.
    value : object
        The new value.
    create : bool
        Create a missing (or null) mapping entry on the path: ``{}`` when a name follows,
        ``[]`` when an index follows. Otherwise every container must exist.

    Raises
    ------
    PathError
        A container on the path is not a mapping where a name follows, or not a list
        long enough where an index follows.
    """
    toks = tokens(key) if isinstance(key, str) else tuple(key)
    node: Any = raw
    for depth, tok in enumerate(toks):
        if isinstance(tok, int):
            if not isinstance(node, list) or not tok < len(node):
                raise PathError(toks, depth, node)
        elif not isinstance(node, dict):
            raise PathError(toks, depth, node)
        if depth == len(toks) - 1:
            node[tok] = value
            return
        if create and isinstance(node, dict) and node.get(tok) is None:
            node[tok] = {} if isinstance(toks[depth + 1], str) else []
        node = node[tok] if isinstance(tok, int) else node.get(tok)


__all__ = ["KEY_PATH", "KeyPathError", "PathError", "tokens", "join", "get", "set"]
