"""MkDocs hooks of the documentation site (``mkdocs.yml``: ``hooks``).

* ``<!-- config-reference -->`` in a page becomes the configuration reference generated from the
  dataclasses (``config_reference.py``), at every build;
* ``<!-- include: PATH level=N -->`` becomes the Markdown file ``PATH`` of the repository, its top heading at
  level ``N`` (default 3) and the others below it, so that a page quotes a generated file
  (``results/first_ten_minutes.md``, the results tables) instead of a copy of its numbers;
* the figures of ``results/`` are published as ``img/results/<folder>/<name>.png``.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ("results/figures", "results/paper_stack/figures", "results/interactive_dense/figures",
           "results/reference_numerics")
"""Folders of ``results/`` whose PNG files the site publishes."""
INCLUDE = re.compile(r"^<!-- include: (?P<path>\S+)(?: level=(?P<level>[1-6]))? -->$", re.M)
CONFIG_MARKER = "<!-- config-reference -->"


def _config_reference() -> str:
    spec = importlib.util.spec_from_file_location("sofar_docs_config_reference", Path(__file__).with_name(
        "config_reference.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.render()


def _include(match: re.Match) -> str:
    path = ROOT / match["path"]
    text = path.read_text(encoding="utf-8")  # a missing file fails the build
    levels = [len(m) for m in re.findall(r"^(#+) ", text, flags=re.M)]
    shift = int(match["level"] or 3) - min(levels) if levels else 0
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m[1]) + shift) + " ", text, flags=re.M).rstrip("\n")


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = INCLUDE.sub(_include, markdown)
    if CONFIG_MARKER in markdown:
        markdown = markdown.replace(CONFIG_MARKER, _config_reference())
    return markdown


def on_files(files, config):
    for folder in FIGURES:
        for png in sorted((ROOT / folder).glob("*.png")):
            files.append(File.generated(config, f"img/{folder}/{png.name}", abs_src_path=str(png)))
    return files
