"""A training run that fails before its first update (here: at its first reset) writes nothing into --out, so
the corrected command runs there without --force; a run stopped during its first rollout writes no final
checkpoint either."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

ROOT = Path(__file__).resolve().parents[2]
REAL_ENV_ID = "SOfAR-LagunaSeca-v0"


def _run(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, f"train/{script}", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, env=dict(os.environ))


# (script, options that make the first reset fail, the error it reports, the corrected options)
CASES = [
    ("pasta.py", ["--rho-values", "5"], "rho must be a number in [0, 2]", ["--rho-values", "0.5"]),
    ("pasta.py", ["--rho-min", "2.5", "--rho-max", "3"], "rho must be a number in [0, 2]", []),
    ("ppo.py", ["--rho-values", "5"], "rho must be a number in [0, 2]", ["--rho-values", "0.5"]),
]


@pytest.mark.parametrize(("script", "bad", "error", "fixed"), CASES,
                         ids=[f"{c[0]} {' '.join(c[1])}" for c in CASES])
def test_a_run_failing_at_its_first_reset_writes_nothing(tmp_path: Path, script: str, bad: list[str], error: str,
                                                         fixed: list[str]) -> None:
    import sofar_env  # noqa: F401  (registers the SOfAR ids, whose reset checks rho)

    if REAL_ENV_ID not in gym.registry:
        pytest.skip("needs the SOfAR environment (its reset checks rho)")
    out = tmp_path / "run"
    common = ["--env-id", REAL_ENV_ID, "--n-steps", "64", "--total-steps", "64", "--no-progress", "--out", str(out)]
    if script == "pasta.py":
        common += ["--n-epochs", "1", "--hidden-sizes", "16", "--env-kwargs", '{"race": {"duration": 2.0}}']
    else:
        common += ["--batch-size", "64", "--n-epochs", "1", "--save-every", "0"]
    failed = _run(script, *common, *bad)
    assert failed.returncode != 0 and error in failed.stderr, failed.stderr[-3000:]
    assert not out.exists(), sorted(p.name for p in out.rglob("*"))  # nothing written
    corrected = _run(script, *common, *fixed)  # no --force needed
    assert corrected.returncode == 0, corrected.stderr[-3000:]
    assert (out / ("pasta_final.json" if script == "pasta.py" else "ppo_final.zip")).is_file()


def test_a_run_stopped_in_its_first_rollout_writes_no_final_checkpoint(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """In-process, on the synthetic stand-in: an interrupt during the first rollout."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("train_pasta_first_reset", ROOT / "train" / "pasta.py")
    script = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = script
    spec.loader.exec_module(script)
    from sofar_agents.pasta import agent as agent_module

    def interrupted(self, vec_env, n_steps=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(agent_module.PASTA, "collect", interrupted)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        script.main(["--env-id", "synthetic_envs:SOfARTest/SyntheticRace-v0", "--n-steps", "16", "--total-steps",
                     "32", "--no-progress", "--out", str(out), "--hidden-sizes", "8"])
    assert not (out / "pasta_final.json").exists()
    monkeypatch.undo()
    script.main(["--env-id", "synthetic_envs:SOfARTest/SyntheticRace-v0", "--n-steps", "16", "--total-steps",
                 "32", "--no-progress", "--out", str(out), "--hidden-sizes", "8"])  # not refused
    assert (out / "pasta_final.json").is_file()
