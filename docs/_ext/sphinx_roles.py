"""Griffe extension of the documentation site: the docstrings' Sphinx roles as cross-references.

The package's docstrings use reStructuredText roles (``:class:`~sofar_env.tracks.Track```,
``:func:`warm_up```, ``:meth:`~.model.relevant_slots```), which ``help()`` and editors read well but
mkdocstrings-python does not render. When the packages are loaded, every role becomes an optional
autorefs cross-reference: a link where the target is documented on the site, code text where it is
not (never a raw role, and never a broken link). The target is resolved as Sphinx resolves it: a
dotted path as written, a name in the scope of the documented object (its members, its module's
names and imports), a leading dot searching the enclosing modules. The title follows Sphinx: the
path as written, or its last part after ``~``. rST literal-block markers (``Usage::``) lose one colon.

Loaded by ``mkdocs.yml`` (``plugins.mkdocstrings.handlers.python.options.extensions``); no package
code depends on it.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?P<role>class|func|meth|mod|attr|data|obj|exc|const):`(?P<body>[^`]+)`")
LITERAL_MARKER = re.compile(r"(?<=\S)::(?=\n\s*\n)")
"""``text::`` before a blank line: rST's marker of the literal block that follows (Markdown indents it)."""


def _exists(collection: Any, path: str) -> bool:
    try:
        collection.get_member(path)
    except Exception:  # noqa: BLE001  (not loaded, not found, an unresolvable alias: not a known target)
        return False
    return True


def _canonical(collection: Any, path: str) -> str:
    """The path where the object of ``path`` is defined (an import's target), else ``path``."""
    try:
        obj = collection.get_member(path)
        return obj.final_target.path if obj.is_alias else obj.path
    except Exception:  # noqa: BLE001  (an alias to an object not loaded: keep the path as written)
        return path


def _paths(collection: Any) -> dict[str, list[str]]:
    """Every loaded object's path (not an alias's), by each of its dotted suffixes."""
    index: dict[str, list[str]] = {}
    stack = list(collection.members.values())
    while stack:
        obj = stack.pop()
        if obj.is_alias:
            continue
        parts = obj.path.split(".")
        for i in range(1, len(parts)):
            index.setdefault(".".join(parts[i:]), []).append(obj.path)
        stack.extend(obj.members.values())
    return index


def resolve(target: str, obj: Any, collection: Any, suffixes: dict[str, list[str]] | None = None) -> str:
    """The full path of a role's ``target`` written in the docstring of ``obj`` (``suffixes``: the loaded
    paths by suffix, the last resort for a name that is not in scope, when it names one object)."""
    if target.startswith("."):
        name = target.lstrip(".")
        scope = obj if obj.is_module else obj.module
        candidates = []
        while scope is not None:
            candidates.append(f"{scope.path}.{name}")
            scope = scope.parent
        return next((c for c in candidates if _exists(collection, c)), candidates[0] if candidates else name)
    first, _, rest = target.partition(".")
    try:
        base = obj.resolve(first)
    except Exception:  # noqa: BLE001  (not a name in scope: an absolute path)
        base = first
    path = f"{base}.{rest}" if rest else base
    if _exists(collection, path):
        return path
    if _exists(collection, target):
        return target
    found = sorted(set((suffixes or {}).get(target, ())))
    return found[0] if len(found) == 1 else path


def convert(text: str, obj: Any, collection: Any, suffixes: dict[str, list[str]] | None = None) -> str:
    """``text`` with every role replaced by an optional autorefs cross-reference (module docstring)."""

    def role(m: re.Match) -> str:
        body = m["body"].strip()
        title, target = None, body
        titled = re.fullmatch(r"(?s)(.*\S)\s*<([^<>]+)>", body)
        if titled:
            title, target = titled.group(1), titled.group(2)
        short = target.startswith("~")
        target = target.lstrip("~")
        shown = title or (target.lstrip(".").rsplit(".", 1)[-1] if short else target.lstrip("."))
        path = _canonical(collection, resolve(target, obj, collection, suffixes))
        return (f'<autoref identifier="{html.escape(path, quote=True)}" optional>'
                f"<code>{html.escape(shown)}</code></autoref>")

    return LITERAL_MARKER.sub(":", ROLE.sub(role, text))


class SphinxRoles(griffe.Extension):
    """Converts the roles of every docstring of a loaded package (see the module docstring)."""

    def on_package(self, *, pkg: Any, loader: Any, **kwargs: Any) -> None:
        collection = loader.modules_collection
        suffixes = _paths(collection)
        stack = [pkg]
        seen: set[int] = set()
        while stack:
            obj = stack.pop()
            if id(obj) in seen or obj.is_alias:
                continue
            seen.add(id(obj))
            if obj.docstring is not None:
                obj.docstring.value = convert(obj.docstring.value, obj, collection, suffixes)
            stack.extend(obj.members.values())
