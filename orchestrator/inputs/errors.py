"""Errors that mean "the user gave bad input" (as opposed to a bug).

The command line catches :class:`UserInputError` (and so :class:`ScenarioError`),
prints its one-line message and exits with status 2, without a traceback.
Anything else is a bug and keeps its traceback.
"""
from __future__ import annotations

import difflib
import re
from typing import Iterable

__all__ = ["UserInputError", "UserInputWarning", "ScenarioError", "one_line", "did_you_mean"]


LINE_BREAKS = "\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029"   # every boundary of str.splitlines


def one_line(text: object) -> str:
    """``str(text)`` with every line break (and the blanks around it) folded into one space.

    A line break is any boundary of ``str.splitlines``, not only CR and LF: a scenario value
    may hold a record separator (\\x1e) or a Unicode line separator, which an error
    message quoting a path built from it would otherwise split.
    """
    return re.sub(rf"\s*[{LINE_BREAKS}]+\s*", " ", str(text)).strip()


def did_you_mean(word: object, choices: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices`` (case-insensitive match first), or ''."""
    choices = [str(c) for c in choices]
    word = str(word)
    lowered = {c.lower(): c for c in choices}
    match = lowered.get(word.lower()) or next(iter(difflib.get_close_matches(word, choices, n=1, cutoff=0.6)), None)
    return f" (did you mean {match!r}?)" if match else ""


class UserInputError(ValueError):
    """Bad user input: a value, file or option the user can fix.

    Jobs raise it for input problems found after the scenario was loaded (an
    unknown body in ``--at``, an unreadable measurement file, ...). Its message
    is a single line.
    """

    def __init__(self, message: str):
        super().__init__(one_line(message))


class UserInputWarning(UserWarning):
    """Input that is used, but not all of it or not as given (a measured channel dropped, ...).

    The command line prints it as one line ``turnout: warning: ...``.
    """


class ScenarioError(UserInputError):
    """A scenario (file, dict or override) is invalid.

    Parameters
    ----------
    message : str
        What is wrong and, where possible, what would be right.
    key : str, optional
        Dotted key path of the offending entry, e.g. ``track.ballast.voids[0].gaps``;
        ``None`` when the problem concerns the whole file (missing, not YAML, ...).
    source : str, optional
        Where the scenario came from (the file name as given, or ``"<dict>"``).

    ``str(error)`` is one line: ``"<source>: <key>: <message>"`` (parts that are
    unknown are left out).
    """

    def __init__(self, message: str, key: str | None = None, source: str | None = None):
        self.message = one_line(message)
        self.key = key
        self.source = source
        super().__init__(self.message)

    def __str__(self) -> str:
        parts = [p for p in (self.source, self.key) if p]
        return one_line(": ".join(parts + [self.message]))

    def __reduce__(self):
        # Keep key and source when the error crosses a process boundary
        # (concurrent.futures pickles exceptions raised in workers).
        return (type(self), (self.message, self.key, self.source))

    def with_source(self, source: str | None) -> "ScenarioError":
        """A copy of this error that names ``source`` (keeps an existing source)."""
        return ScenarioError(self.message, self.key, self.source or source)
