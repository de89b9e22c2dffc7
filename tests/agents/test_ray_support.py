"""A private local Ray instance chooses token authentication explicitly, so Ray prints no warning about it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

pytest.importorskip("ray")

MODE = "from sofar_agents.ray_support import require_ray; require_ray(local={local}); import os; " \
       "print(os.environ.get('RAY_AUTH_MODE'))"


def _run(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if k != "RAY_AUTH_MODE"}
    return subprocess.run([sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True,
                          timeout=300, check=True)


def test_the_mode_is_set_for_a_local_instance_only_and_never_overridden() -> None:
    assert _run(MODE.format(local=True)).stdout.strip() == "token"
    assert _run(MODE.format(local=False)).stdout.strip() == "None"  # joining a cluster: the user's choice
    assert _run(MODE.format(local=True), RAY_AUTH_MODE="disabled").stdout.strip() == "disabled"


def test_a_local_instance_starts_without_the_token_warning(tmp_path) -> None:
    code = ("from sofar_agents.ray_support import init_ray; init_ray(None, 1); import ray; "
            "print(ray.get(ray.remote(lambda: 7).remote())); ray.shutdown()")
    proc = _run(code, HOME=str(tmp_path))  # a fresh home: no token yet, as on a new machine
    assert proc.stdout.strip().endswith("7")
    assert "Token authentication" not in proc.stderr, proc.stderr
