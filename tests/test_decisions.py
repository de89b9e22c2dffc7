"""Decision pages: every ``docs/decisions/NAME.md`` a docstring points to exists, every decision page is in the
site's navigation, and the configuration reference links the pointers."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
POINTER = re.compile(r"docs/decisions/([a-z0-9-]+)\.md")


def _pointers() -> dict[str, list[str]]:
    found: dict[str, list[str]] = {}
    for package in ("sofar_env", "sofar_agents"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for name in POINTER.findall(path.read_text(encoding="utf-8")):
                found.setdefault(name, []).append(str(path.relative_to(ROOT)))
    return found


def test_every_pointer_names_a_page() -> None:
    pointers = _pointers()
    assert pointers, "no docstring points to a decision page"
    for name, files in pointers.items():
        assert (ROOT / "docs" / "decisions" / f"{name}.md").is_file(), (name, files)


def test_every_page_is_in_the_navigation() -> None:
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in sorted((ROOT / "docs" / "decisions").glob("*.md")):
        assert f"decisions/{page.name}" in nav, page.name


def test_the_configuration_reference_links_the_pointers() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("config_reference", ROOT / "docs" / "_ext" / "config_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = module.render()
    assert "[stall-rule](../decisions/stall-rule.md)" in text
    assert "``docs/decisions/" not in text
