"""The documentation site's generated parts, checked without building it: the configuration reference covers
every configuration dataclass (types, defaults, units), the docstrings' Sphinx roles become cross-references,
and the pages that quote generated files name files that exist."""

from __future__ import annotations

import dataclasses
import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXT = ROOT / "docs" / "_ext"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"sofar_docs_{name}", EXT / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def reference():
    module = _load("config_reference")
    return module, module.config_classes(), module.render()


def test_the_reference_covers_every_configuration_dataclass(reference) -> None:
    module, classes, markdown = reference
    from sofar_env.config import EnvConfig

    names = {cls.__name__ for cls, _ in classes}
    assert {"EnvConfig", "RewardWeights", "RaceConfig", "VehicleParams", "OpponentConfig", "PaceConfig", "LineConfig",
            "DefenceConfig", "TrafficConfig", "DynamicParams", "SensorConfig", "StackConfig", "MPCConfig",
            "BarrierParams", "MIQPConfig", "PASTAConfig", "BuildConfig"} <= names
    # every sub-configuration reachable from EnvConfig is there, with its key path
    paths = {cls: path for cls, path in classes}
    stack = [(EnvConfig, "")]
    while stack:
        cls, path = stack.pop()
        assert paths.get(cls) == path, (cls, path)
        for f in dataclasses.fields(cls):
            value = module._default(f)
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                stack.append((type(value), f"{path}.{f.name}" if path else f.name))
    # one section per class and one row per field: key, type, default (unit and values where known)
    for cls, _ in classes:
        assert f"### {cls.__name__} {{ #{module.anchor(cls)} }}" in markdown, cls
        for f in dataclasses.fields(cls):
            if f.init:
                row = re.search(rf"^\| \[\]\(\){{ #{re.escape(module.anchor(cls))}\.{f.name} }}`{f.name}` \| (.+)$",
                                markdown, re.M)
                assert row, (cls, f.name)
                type_cell, default_cell = row.group(1).split(" | ")[:2]
                assert type_cell.strip() and default_cell.strip(), (cls, f.name)
    assert "| `dt` |" not in markdown  # keys carry their anchors
    assert re.search(r"`duration` \| `float` \| `200.0` \| s \|", markdown)  # type, default and unit of a field


def test_the_reference_page_is_generated() -> None:
    page = (ROOT / "docs" / "reference" / "config.md").read_text(encoding="utf-8")
    assert "<!-- config-reference -->" in page
    assert "::: sofar_env.config.EnvConfig" not in page  # not a hand-kept list of classes


def test_pages_quote_files_that_exist() -> None:
    hooks = _load("hooks")
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for match in hooks.INCLUDE.finditer(page.read_text(encoding="utf-8")):
            assert (ROOT / match["path"]).is_file(), (page, match["path"])
    results = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    for table in ("results/table1.md", "results/table2.md", "results/paper_stack/table1.md"):
        assert f"<!-- include: {table} -->" in results
    for image in re.findall(r"\]\((img/results/[^)]+)\)", results):
        folder, name = image[len("img/"):].rsplit("/", 1)
        assert folder in hooks.FIGURES and (ROOT / folder / name).is_file(), image
    assert "img/results/figures/distance_vs_gamma.png" in results


def test_sphinx_roles_become_cross_references() -> None:
    griffe = pytest.importorskip("griffe")
    roles = _load("sphinx_roles")
    loader = griffe.GriffeLoader()
    loader.load("sofar_env")
    jit = loader.modules_collection.get_member("sofar_env._jit")
    suffixes = roles._paths(loader.modules_collection)
    out = roles.convert("See :func:`kernel`, :class:`~sofar_env.tracks.Track` and :mod:`sofar_env.compile`.\n\n"
                        "Usage::\n\n    python -m sofar_env.compile\n", jit, loader.modules_collection, suffixes)
    assert '<autoref identifier="sofar_env._jit.kernel" optional><code>kernel</code></autoref>' in out
    assert '<autoref identifier="sofar_env.tracks.track.Track" optional><code>Track</code></autoref>' in out
    assert '<autoref identifier="sofar_env.compile" optional><code>sofar_env.compile</code></autoref>' in out
    assert "Usage:\n\n    python" in out and not roles.ROLE.search(out)
