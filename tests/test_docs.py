"""The documentation site builds with ``mkdocs build --strict`` (warnings, e.g. broken references, fail)."""

from __future__ import annotations

import os
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
    config_page = (site / "reference" / "config" / "index.html").read_text(encoding="utf-8")
    assert 'id="sofar_env.config.EnvConfig.reward_mode"' in config_page
    env_page = (site / "envs" / "paper" / "index.html").read_text(encoding="utf-8")
    assert "<table" in env_page  # the env docstring's spec tables render
