"""Configs that generate their command line (nerfstudio's config -> CLI is the model).

A pd2gs config is a dataclass whose fields carry their type (``Literal[...]`` for a choice), their
default and a docstring (the string literal under the field, as nerfstudio/tyro read them). From
those, :func:`add_option` builds an argparse option (flag, type, choices, help with the default),
so pd2gs/cli.py repeats no choice and no default; :func:`check_choices` (called from each config's
``__post_init__``) refuses a value outside its ``Literal`` with a :class:`ConfigError` naming the field.
"""
from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import textwrap
import types
import typing
from typing import Any, Literal

from rsart.errors import RsartError


class ConfigError(RsartError, ValueError):
    """A config field holds a value it does not allow (the message names the field)."""


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls, include_extras=True)


def _is_union(t: Any) -> bool:
    return typing.get_origin(t) in (typing.Union, types.UnionType)


def _unwrap(t: Any) -> Any:
    """``X | None`` -> X."""
    return next(a for a in typing.get_args(t) if a is not type(None)) if _is_union(t) else t


def choices(cls: type, name: str) -> tuple | None:
    """The allowed values of field ``name`` when its type is a ``Literal`` (or ``Literal | None``), else None."""
    t = _unwrap(_hints(cls)[name])
    return typing.get_args(t) if typing.get_origin(t) is Literal else None


@functools.cache
def field_docs(cls: type) -> dict[str, str]:
    """Field name -> its docstring (the string literal right under the field in the class body)."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__[:-1]):
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body
        for a, b in zip(body, body[1:]):
            if (isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name) and isinstance(b, ast.Expr)
                    and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str)):
                out[a.target.id] = " ".join(b.value.value.split())
    return out


def check_choices(cfg: Any) -> None:
    """Raise :class:`ConfigError` when a ``Literal`` field of ``cfg`` holds a value outside its choices."""
    for f in dataclasses.fields(cfg):
        allowed = choices(type(cfg), f.name)
        value = getattr(cfg, f.name)
        if allowed is not None and value not in allowed and not (value is None and _optional(type(cfg), f.name)):
            raise ConfigError(f"{type(cfg).__name__}.{f.name}={value!r}: choose one of {', '.join(map(str, allowed))}")


def _optional(cls: type, name: str) -> bool:
    t = _hints(cls)[name]
    return _is_union(t) and type(None) in typing.get_args(t)


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def add_option(parser: argparse.ArgumentParser, cls: type, name: str, flag: str | None = None,
               negate: bool = False) -> None:
    """Add ``--flag`` (default ``--field-name``) for field ``name`` of config class ``cls``.

    The option's value is None unless given, so a caller applies only what the user typed and the
    config keeps its own default (named in the help). ``negate``: a boolean field whose default is
    True becomes ``--no-<flag>`` storing False.
    """
    f = next(f for f in dataclasses.fields(cls) if f.name == name)
    t = _unwrap(_hints(cls)[name])
    doc = field_docs(cls).get(name, "").rstrip(".")
    default = _default(f)
    flag = flag or "--" + name.replace("_", "-")
    dest = f"{cls.__name__}.{name}"  # one namespace may hold options of several configs
    if t is bool:
        if negate:
            parser.add_argument("--no-" + flag.removeprefix("--"), dest=dest, action="store_const", const=False,
                                default=None, help=f"turn off: {doc}")
        else:
            parser.add_argument(flag, dest=dest, action="store_const", const=True, default=None, help=doc)
        return
    allowed = choices(cls, name)
    kind = type(allowed[0]) if allowed else t if t in (int, float, str) else str
    metavar = "N" if kind in (int, float) and not allowed else None
    parser.add_argument(flag, dest=dest, type=kind, choices=allowed, default=None, metavar=metavar,
                        help=f"{doc} (default {default})" if doc else f"default {default}")


def overrides(args: argparse.Namespace, cls: type) -> dict[str, Any]:
    """Field name -> value for each field of ``cls`` that the user set on the command line (via :func:`add_option`)."""
    prefix = cls.__name__ + "."
    return {k[len(prefix):]: v for k, v in vars(args).items() if k.startswith(prefix) and v is not None}


def value(args: argparse.Namespace, cls: type, name: str) -> Any:
    """The command-line value of field ``name`` of ``cls`` (added by :func:`add_option`), else its default."""
    v = getattr(args, f"{cls.__name__}.{name}", None)
    return _default(next(f for f in dataclasses.fields(cls) if f.name == name)) if v is None else v
