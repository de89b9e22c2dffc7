"""The configuration reference of the documentation site, generated from the dataclasses.

Every configuration dataclass of ``sofar_env`` and ``sofar_agents`` (a dataclass whose name ends in
``Config``, ``Params`` or ``Weights``) gets a section with one table row per field: key, type, default,
unit, accepted values and the field's docstring (its pointer to a decision page, ``docs/decisions/NAME.md``,
as a link). The environment's classes come first, in the order of
the ``config`` mapping (``EnvConfig`` and the sub-configurations below it, each with its key path); the
others (``PASTAConfig``, the track builder's ``BuildConfig``, ...) follow. The unit is the field's
declared unit, else the first bracketed unit of its docstring (``[m/s]``); the accepted values are the
field's declared domain, where it has one.

Used by ``docs/_ext/hooks.py`` (the ``<!-- config-reference -->`` marker of ``docs/reference/config.md``)
at every build, so the page cannot fall behind the code; ``python docs/_ext/config_reference.py``
prints the Markdown.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re
import types
import typing
from typing import Any

PACKAGES = ("sofar_env", "sofar_agents")
SUFFIXES = ("Config", "Params", "Weights")
ROLE = re.compile(r":(?:py:)?[a-z]+:`~?\.?([^`]+)`")
DECISION = re.compile(r"``docs/decisions/([a-z0-9-]+)\.md``")
"""A docstring's pointer to its decision page (``docs/decisions/NAME.md``), linked from the reference page."""
UNIT = re.compile(r"\[((?:1/)?[A-Za-z%°][A-Za-z0-9/^*%°.]*|-)\]")


def _docs(cls: type) -> dict[str, str]:
    """The attribute docstrings of ``cls`` (the string literal under each field)."""
    import ast

    try:
        tree = ast.parse(inspect.getsource(cls).lstrip())
    except (OSError, TypeError, SyntaxError):
        return {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    out = {}
    for node, nxt in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(nxt, ast.Expr)
                and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str)):
            out[node.target.id] = inspect.cleandoc(nxt.value.value)
    return out


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def config_classes() -> list[tuple[type, str | None]]:
    """Every configuration dataclass with its key path in an environment's ``config`` (None: not part of it)."""
    from sofar_env.config import EnvConfig

    tree: list[tuple[type, str | None]] = []

    def walk(cls: type, path: str) -> None:
        if any(c is cls for c, _ in tree):
            return
        tree.append((cls, path))
        for f in dataclasses.fields(cls):
            value = _default(f)
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                walk(type(value), f"{path}.{f.name}" if path else f.name)

    walk(EnvConfig, "")
    others = {}
    for name in PACKAGES:
        pkg = importlib.import_module(name)
        for info in pkgutil.walk_packages(pkg.__path__, name + "."):
            if info.name.endswith("__main__"):
                continue
            module = importlib.import_module(info.name)
            for obj in vars(module).values():
                if (inspect.isclass(obj) and dataclasses.is_dataclass(obj) and obj.__module__ == module.__name__
                        and obj.__name__.endswith(SUFFIXES) and not any(c is obj for c, _ in tree)):
                    others[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return tree + [(others[k], None) for k in sorted(others, key=lambda k: k.rsplit(".", 1)[-1])]


def anchor(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _type(tp: Any, known: dict[type, str]) -> str:
    if tp is type(None):
        return "None"
    if tp is Ellipsis:
        return "..."
    if tp is Any:
        return "Any"
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type(a, known) for a in typing.get_args(tp))
    if origin is typing.Literal:
        return " | ".join(repr(a) for a in typing.get_args(tp))
    if origin is not None:
        name = getattr(origin, "__name__", str(origin))
        return f"{name}[{', '.join(_type(a, known) for a in typing.get_args(tp))}]"
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _value(value: Any) -> str:
    if value is dataclasses.MISSING:
        return "required"
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        cls = type(value)
        try:
            base = cls()
        except TypeError:
            base = None
        changed = [f"{f.name}={_value(getattr(value, f.name))}" for f in dataclasses.fields(cls)
                   if base is None or getattr(value, f.name) != getattr(base, f.name)]
        return f"{cls.__name__}({', '.join(changed)})"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, tuple):
        inner = ", ".join(_value(v) for v in value)
        return f"({inner},)" if len(value) == 1 else f"({inner})"
    return repr(value)


def _text(doc: str) -> str:
    """A docstring as one table cell: roles as code, decision pages as links, one line, pipes escaped."""
    doc = ROLE.sub(lambda m: f"`{m.group(1).rsplit('.', 1)[-1] if m.group(0).find('~') >= 0 else m.group(1)}`",
                   doc)
    doc = DECISION.sub(lambda m: f"[{m.group(1)}](../decisions/{m.group(1)}.md)", doc)
    return " ".join(doc.split()).replace("|", "\\|")


def _code(text: str) -> str:
    text = text.replace("|", "\\|")
    return f"`{text}`" if "`" not in text else f"`` {text} ``"


def _section(cls: type, path: str | None, known: dict[type, str]) -> list[str]:
    doc = inspect.cleandoc(cls.__doc__ or "").split("\n\n")[0]
    where = ("the top level of `config`" if path == "" else f"`config` key `{path}`") if path is not None else None
    lines = [f"### {cls.__name__} {{ #{anchor(cls)} }}", "",
             f"`{anchor(cls)}`" + (f", {where}" if where else "") + ".", ""]
    if doc and not doc.startswith(cls.__name__ + "("):
        lines += [_text(doc), ""]
    lines += ["| key | type | default | unit | values | description |", "|---|---|---|---|---|---|"]
    hints = typing.get_type_hints(cls)
    docs = _docs(cls)
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        domain = f.metadata.get("domain")
        text = docs.get(f.name, "")
        unit = getattr(domain, "unit", "") or ""
        if not unit:
            m = UNIT.search(text)
            unit = m.group(1) if m else ""
        values = domain.describe() if domain is not None and hasattr(domain, "describe") else ""
        tp = hints.get(f.name, f.type)
        type_cell = _code(_type(tp, known))
        nested = tp if isinstance(tp, type) and tp in known else None
        if nested is not None:
            type_cell = f"[{type_cell}](#{known[nested]})"
        key = f"[](){{ #{anchor(cls)}.{f.name} }}`{f.name}`"
        default = _default(f)
        default_cell = _code(_value(default))
        if type(default) in known and nested is None:  # a sub-configuration typed loosely (e.g. a preset name too)
            default_cell = f"[{default_cell}](#{known[type(default)]})"
        lines.append(f"| {key} | {type_cell} | {default_cell} | {unit} | {_text(values)} | {_text(text)} |")
    return lines + [""]


def render() -> str:
    """The Markdown of the reference: one section per configuration dataclass."""
    classes = config_classes()
    known = {cls: anchor(cls) for cls, _ in classes}
    lines = ["## The environment's configuration", "",
             "The `config` mapping of `gymnasium.make` (and the keyword arguments of the same names), from the top "
             "level down:", ""]
    for cls, path in classes:
        if path is not None:
            depth = 0 if path == "" else path.count(".") + 1
            key = "top level" if path == "" else f"`{path}`"
            lines.append(f"{'    ' * depth}- {key}: [{cls.__name__}](#{anchor(cls)})")
    lines.append("")
    for cls, path in classes:
        if path is not None:
            lines += _section(cls, path, known)
    lines += ["## Other configuration", "",
              "Configuration dataclasses outside the environment's `config` (training, the track builder, ...).", ""]
    for cls, path in classes:
        if path is None:
            lines += _section(cls, path, known)
    return "\n".join(lines)


if __name__ == "__main__":
    print(render())
