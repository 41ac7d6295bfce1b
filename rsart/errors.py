"""Errors raised by rsart.

Every reader validates its input completely and raises one :class:`ValidationError`
that lists *every* problem, each tagged with the JSON path (or file path) it concerns,
e.g. ``joints[1].axis: zero-length vector``.

Rendering (the one place it happens): names in error text come from untrusted files (part, object and
file names), so control characters in them (newline, NUL, escape sequences, ...) are shown escaped
(``\\n``, ``\\x00``) by :func:`escape_controls` when an error is turned into text; a message can then
never forge extra lines or terminal codes. One problem is said on one line
(``FILE: path: problem``); several as a count followed by one ``- path: problem`` line each.

:func:`guarded` is how every console script of the family ends (exit 2 for these errors, 1 for a bug).
"""
from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from typing import Callable

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


def guarded(call: Callable[[], int | None], prog: str = "", interrupted: str = "interrupted") -> int:
    """Run a console script's work and end it the way every rsart-family command ends (``rsart``,
    ``rsart-eval``, ``pd2gs``, ``rsart-leaderboard``): the exit status of ``call()`` (None = 0); an
    :class:`~rsart.errors.RsartError` or a missing extra -> ``[prog: ]error: ...`` on stderr, exit 2;
    Ctrl-C -> ``interrupted``, exit 130; any other exception (a bug) -> one line naming it, exit 1, with the
    traceback only when ``RSART_DEBUG`` is set."""
    lead = f"{prog}: " if prog else ""
    try:
        return int(call() or 0)
    except RsartError as e:
        print(f"{lead}error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{lead}{interrupted}", file=sys.stderr)
        return 130
    except Exception as e:
        from .extras import from_import_error

        if (err := from_import_error(e)) is not None:  # a module of a missing extra: `pip install 'rsart[X]'`
            print(f"{lead}error: {err}", file=sys.stderr)
            return 2
        if os.environ.get("RSART_DEBUG"):
            raise
        print(f"{lead}internal error (please report; set RSART_DEBUG=1 for the traceback): "
              f"{type(e).__name__}: {escape_controls(str(e))}", file=sys.stderr)
        return 1
