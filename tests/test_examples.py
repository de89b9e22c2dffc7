"""Smoke test of every script in ``examples/``: each runs to completion with a tiny step budget, copied alone
into an empty folder (an example needs nothing but the installed packages)."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPTS = sorted(p.name for p in EXAMPLES.glob("*.py"))


def test_every_example_is_listed() -> None:
    assert {"fixed_and_random_gamma.py", "shipped_policy.py", "mo_gymnasium_vector_reward.py", "sb3_ppo.py",
            "pettingzoo_parallel.py", "custom_track.py"} <= set(SCRIPTS)


@pytest.mark.parametrize("script", SCRIPTS)
def test_example_runs(script: str, tmp_path: Path) -> None:
    copy = shutil.copy(EXAMPLES / script, tmp_path / script)  # alone: no sibling module to import
    env = dict(os.environ, SOFAR_EXAMPLE_STEPS="5", MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(copy)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{script} failed:\n{proc.stdout}\n{proc.stderr}"
    assert proc.stdout.strip(), f"{script} printed nothing"


@pytest.mark.parametrize("script", SCRIPTS)
def test_example_imports_only_installed_packages(script: str) -> None:
    tree = ast.parse((EXAMPLES / script).read_text(encoding="utf-8"))
    siblings = {p.stem for p in EXAMPLES.glob("*.py")}
    for node in ast.walk(tree):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
            [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        for name in names:
            assert name.split(".")[0] not in siblings and (name == "__future__" or not name.startswith("_")), (
                script, name)
