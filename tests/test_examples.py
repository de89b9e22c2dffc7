"""Smoke test of every script in ``examples/``: each runs to completion with a tiny step budget."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPTS = sorted(p.name for p in EXAMPLES.glob("[!_]*.py"))


def test_every_example_is_listed() -> None:
    assert {"fixed_and_random_gamma.py", "shipped_policy.py", "mo_gymnasium_vector_reward.py", "sb3_ppo.py",
            "pettingzoo_parallel.py", "custom_track.py"} <= set(SCRIPTS)


@pytest.mark.parametrize("script", SCRIPTS)
def test_example_runs(script: str, tmp_path: Path) -> None:
    env = dict(os.environ, SOFAR_EXAMPLE_STEPS="5", MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(EXAMPLES / script)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{script} failed:\n{proc.stdout}\n{proc.stderr}"
    assert proc.stdout.strip(), f"{script} printed nothing"
