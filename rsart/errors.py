"""Errors raised by rsart.

Every reader validates its input completely and raises one :class:`ValidationError`
that lists *every* problem, each tagged with the JSON path (or file path) it concerns,
e.g. ``joints[1].axis: zero-length vector``.

Rendering (the one place it happens): names in error text come from untrusted files (part, object and
file names), so control characters in them (newline, NUL, escape sequences, ...) are shown escaped
(``\\n``, ``\\x00``) by :func:`escape_controls` when an error is turned into text; a message can then
never forge extra lines or terminal codes. One problem is said on one line
(``FILE: path: problem``); several as a count followed by one ``- path: problem`` line each.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

# C0 and C1 control characters, DEL, and the Unicode line/paragraph separators
_CONTROLS = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def escape_controls(text: str) -> str:
    """``text`` with every control character written as an escape (``\\n``, ``\\t``, ``\\x00``, ``\\u2028``)."""
    def esc(m: re.Match) -> str:
        c = m.group()
        return _NAMED.get(c) or (f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}")

    return _CONTROLS.sub(esc, text)


class RsartError(Exception):
    """Base class of every error rsart raises on purpose (the CLI prints these without a traceback).

    ``str(error)`` escapes control characters (see the module docstring)."""

    def __str__(self) -> str:
        return escape_controls(super().__str__())


@dataclass(frozen=True)
class Problem:
    """One problem found in an input: ``path`` (JSON path such as ``joints[1].axis``, or a file path) and a message."""

    path: str
    message: str

    def __str__(self) -> str:
        text = f"{self.path}: {self.message}" if self.path else self.message
        return escape_controls(text)


def format_problems(problems: list[Problem], source: str | None = None) -> str:
    """The text of a refusal: ``SOURCE: path: problem`` for one problem; for several, ``SOURCE: N problems
    found`` and one ``  - path: problem`` line each. Control characters are escaped."""
    head = f"{escape_controls(str(source))}: " if source else ""
    if len(problems) == 1:
        return f"{head}{problems[0]}"
    lines = [f"{head}{len(problems)} problems found"] + [f"  - {p}" for p in problems]
    return "\n".join(lines)


class ValidationError(RsartError):
    """An input is invalid; ``problems`` lists every problem found (never just the first)."""

    def __init__(self, problems: list[Problem], source: str | None = None):
        self.problems = list(problems)
        self.source = source
        super().__init__(format_problems(self.problems, source))

    def __str__(self) -> str:  # already rendered (escaped) by format_problems; its newlines are the layout
        return Exception.__str__(self)


class Problems:
    """Collects problems while validating; ``raise_if_any`` raises one ValidationError with all of them."""

    def __init__(self) -> None:
        self.items: list[Problem] = []

    def add(self, path: str, message: str) -> None:
        self.items.append(Problem(path, message))

    def extend(self, other: "Problems | list[Problem]") -> None:
        self.items.extend(other.items if isinstance(other, Problems) else other)

    def __bool__(self) -> bool:
        return bool(self.items)

    def __len__(self) -> int:
        return len(self.items)

    def raise_if_any(self, source: str | None = None) -> None:
        if self.items:
            raise ValidationError(self.items, source)
