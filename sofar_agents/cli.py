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
from collections.abc import Sequence
from typing import Any

__all__ = ["dataclass_field_docs", "add_dataclass_options", "plain_text"]

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


def add_dataclass_options(parser: argparse.ArgumentParser, cls: type, title: str,
                          choices: dict[str, Sequence[str]] | None = None) -> None:
    """One ``--field-name`` option per dataclass field, help from the field docstring (as plain text).

    Defaults are ``None`` so that only the options actually given are applied. ``choices`` maps a
    field name to its valid values (taken from a registry, e.g. the stack presets), listed in the help.
    """
    group = parser.add_argument_group(title)
    docs = dataclass_field_docs(cls)
    hints = typing.get_type_hints(cls)
    choices = choices or {}
    for f in dataclasses.fields(cls):
        tp = _unwrap_optional(hints[f.name])
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
            kw["nargs"] = "+"
            kw["type"] = typing.get_args(tp)[0]
        else:
            kw["type"] = tp
        group.add_argument("--" + f.name.replace("_", "-"), **kw)
