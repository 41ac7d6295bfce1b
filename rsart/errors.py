"""Errors raised by rsart.

Every reader validates its input completely and raises one :class:`ValidationError`
that lists *every* problem, each tagged with the JSON path (or file path) it concerns,
e.g. ``joints[1].axis: zero-length vector``.
"""
from __future__ import annotations

from dataclasses import dataclass


class RsartError(Exception):
    """Base class of every error rsart raises on purpose (the CLI prints these without a traceback)."""


@dataclass(frozen=True)
class Problem:
    """One problem found in an input: ``path`` (JSON path such as ``joints[1].axis``, or a file path) and a message."""

    path: str
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message}" if self.path else self.message


class ValidationError(RsartError):
    """An input is invalid; ``problems`` lists every problem found (never just the first)."""

    def __init__(self, problems: list[Problem], source: str | None = None):
        self.problems = list(problems)
        self.source = source
        head = f"{source}: " if source else ""
        n = len(self.problems)
        lines = [f"{head}{n} problem{'s' if n != 1 else ''} found"] + [f"  - {p}" for p in self.problems]
        super().__init__("\n".join(lines))


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
