"""The documentation site builds with ``mkdocs build --strict`` (warnings, e.g. broken references, fail), with no\nraw Sphinx role in its pages, the whole configuration reference and the results' tables and figures."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs")
pytest.importorskip("mkdocstrings")
pytest.importorskip("material")

ROOT = Path(__file__).resolve().parents[1]


def test_mkdocs_build_strict(tmp_path: Path) -> None:
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    from sofar_env.config import EnvConfig, RaceConfig

    env_config, race_config = (f"{c.__module__}.{c.__qualname__}" for c in (EnvConfig, RaceConfig))
    config_page = (site / "reference" / "config" / "index.html").read_text(encoding="utf-8")
    assert f'id="{env_config}.reward_mode"' in config_page
    env_page = (site / "envs" / "paper" / "index.html").read_text(encoding="utf-8")
    assert "<table" in env_page  # the env docstring's spec tables render

    # the docstrings' Sphinx roles render as links or code, never as raw roles
    raw = re.compile(r":(?:class|func|meth|mod|attr|data|obj|exc):(?:<code>|`)")
    for page in site.rglob("*.html"):
        found = raw.search(page.read_text(encoding="utf-8"))
        assert found is None, (page.relative_to(site), found)
    assert f'href="../../reference/config/#{env_config}"' in env_page  # a role linked to its target

    # every configuration class has its section, every key a row with its type and default
    for cls in ("EnvConfig", "RaceConfig", "OpponentConfig", "StackConfig", "MPCConfig", "MIQPConfig", "SensorConfig",
                "DynamicParams", "BarrierParams", "PASTAConfig"):
        assert f">{cls}<" in config_page, cls
    assert f'id="{race_config}.duration"' in config_page

    # the results page shows the tables and figures of results/
    results_page = (site / "results" / "index.html").read_text(encoding="utf-8")
    assert results_page.count("<table>") >= 5 and "Table II" in results_page
    for image in ("figures/distance_vs_gamma.png", "figures/gamma_hist.png", "paper_stack/figures/gamma_hist.png"):
        assert f'src="../img/results/{image}"' in results_page and (site / "img" / "results" / image).is_file()
