"""Command-line options generated from documented dataclasses (used by the ``train/`` scripts).

A dataclass whose fields carry attribute docstrings (a string literal under each
field, as in :class:`sofar_agents.PASTAConfig`) becomes an ``argparse`` group with one
``--field-name`` option per field and the docstring as its help, in plain text
(:func:`plain_text` drops the reStructuredText markup the docstrings use).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import re
import types
import typing
from collections.abc import Callable, Sequence
from typing import Any

from sofar_agents.cli_types import finite_float, nonneg_int

__all__ = ["dataclass_field_docs", "add_dataclass_options", "check_dataclass_options", "plain_text", "DEFAULT_TYPES"]

_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`(~?)([^`<]*?)\s*(?:<([^`>]*)>)?`")
_LITERAL = re.compile(r"``(.+?)``")
_INTERPRETED = re.compile(r"(?<![\w`])`([^`]+)`(?![\w`])")


def plain_text(text: str) -> str:
    """``text`` without reStructuredText inline markup, for a terminal: ``:class:`~a.b.C``` becomes ``C``,
    ``:func:`a.f``` ``a.f``, a role with an explicit title its title, and literals in double or single
    backticks lose the backticks."""

    def role(m: re.Match) -> str:
        tilde, title, target = m.group(1), m.group(2), m.group(3)
        if target is not None and title:
            return title
        name = (target or title).lstrip(".~")
        return name.rsplit(".", 1)[-1] if tilde else name

    text = _ROLE.sub(role, text)
    text = _LITERAL.sub(r"\1", text)
    return _INTERPRETED.sub(r"\1", text)


def dataclass_field_docs(cls: type) -> dict[str, str]:
    """Attribute docstrings (the string literal under each field) of a dataclass.

    Used to build command-line help from the config classes. Returns an empty dict
    when the source is unavailable.
    """
    try:
        tree = ast.parse(inspect.getsource(cls).lstrip())
    except (OSError, TypeError, SyntaxError):
        return {}
    docs: dict[str, str] = {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    for node, nxt in zip(body, body[1:]):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(nxt, ast.Expr)
            and isinstance(nxt.value, ast.Constant)
            and isinstance(nxt.value.value, str)
        ):
            docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


def _unwrap_optional(tp: Any) -> Any:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return tp


DEFAULT_TYPES: dict[type, Callable[[str], Any]] = {int: nonneg_int, float: finite_float}
"""Argument type of an ``int`` or ``float`` field without its own (``Annotated[int, positive_int]``):
whole numbers >= 0 (counts, sizes, seeds) and finite numbers."""


def _field_type(hint: Any) -> tuple[Any, Callable[[str], Any] | None]:
    """``(type, argument type)`` of a field's annotation: ``X | None`` is ``X``, and
    ``Annotated[X, check]`` is ``X`` with the callable ``check`` (which, for a tuple or list, checks each item)."""
    tp = _unwrap_optional(hint)
    check = None
    if typing.get_origin(tp) is typing.Annotated:
        tp, *extras = typing.get_args(tp)
        check = next((e for e in extras if callable(e)), None)
        tp = _unwrap_optional(tp)
    return tp, check


def add_dataclass_options(parser: argparse.ArgumentParser, cls: type, title: str,
                          choices: dict[str, Sequence[str]] | None = None) -> None:
    """One ``--field-name`` option per dataclass field, help from the field docstring (as plain text).

    Defaults are ``None`` so that only the options actually given are applied. ``choices`` maps a
    field name to its valid values (taken from a registry, e.g. the stack presets), listed in the help.
    Numbers are checked by their argument type (:mod:`sofar_agents.cli_types`): the one a field names
    with ``Annotated[int, positive_int]``, else :data:`DEFAULT_TYPES`; a value outside it is a usage
    error (exit status 2), so a 0 or a negative count never reaches the script.
    """
    group = parser.add_argument_group(title)
    docs = dataclass_field_docs(cls)
    hints = typing.get_type_hints(cls, include_extras=True)
    choices = choices or {}
    for f in dataclasses.fields(cls):
        tp, check = _field_type(hints[f.name])
        default = f.default if f.default is not dataclasses.MISSING else None
        text = plain_text(docs.get(f.name, ""))
        if f.name in choices:
            text += f" One of: {', '.join(choices[f.name])}."
        kw: dict[str, Any] = {"default": None, "dest": f.name, "help": f"{text} (default: {default})"}
        if f.name in choices:
            kw["choices"] = tuple(choices[f.name])
        origin = typing.get_origin(tp)
        if tp is bool:
            kw["action"] = argparse.BooleanOptionalAction
        elif origin in (tuple, list):
            item = typing.get_args(tp)[0]
            kw["nargs"] = "+"
            kw["type"] = check or DEFAULT_TYPES.get(item, item)
        else:
            kw["type"] = check or DEFAULT_TYPES.get(tp, tp)
        group.add_argument("--" + f.name.replace("_", "-"), **kw)


def check_dataclass_options(parser: argparse.ArgumentParser, cls: type, values: dict[str, Any]) -> Any:
    """``cls(**values)``, built to check the options of :func:`add_dataclass_options` together.

    The argument types check each value alone; the dataclass's own validation (``__post_init__``) checks
    how they fit together (e.g. ``mu_min <= mu_max``). A ``ValueError`` or ``TypeError`` from it becomes a
    usage error of ``parser`` (message on stderr, exit status 2) instead of a traceback later on.
    """
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        parser.error(str(exc))
