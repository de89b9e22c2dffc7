"""Training resumed from a checkpoint is bit-identical to training that was not interrupted: the checkpoint holds
the agent's generators (exploration noise, minibatch order, preferences) and every env's running episode, which
the resumed run replays. Checked on the in-process vector envs, the worker-process pool and train/pasta.py."""

from __future__ import annotations

import functools
import json
import logging
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import pytest
import torch

from pool_runs import assert_identical
from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta.process_rollout import ProcessEnvPool
from sofar_agents.pasta.rollout import make_training_env

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
SYNTHETIC = "synthetic_envs:SOfARTest/SyntheticRace-v0"


def _fns(n: int, max_steps: int) -> list:
    return [functools.partial(make_training_env, SYNTHETIC, {"max_steps": max_steps}, 0.1, 0.8)] * n


def _sync(n: int, max_steps: int) -> gym.vector.SyncVectorEnv:
    return gym.vector.SyncVectorEnv(_fns(n, max_steps), autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)


def _async(n: int, max_steps: int) -> gym.vector.AsyncVectorEnv:
    return gym.vector.AsyncVectorEnv(_fns(n, max_steps), autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
                                     context="fork")


def _processes(n: int, max_steps: int) -> ProcessEnvPool:
    return ProcessEnvPool(_fns(n, max_steps), num_workers=2, pin_workers=False, chunk_steps=5)


def _state(path: Path) -> tuple[dict, dict]:
    meta = json.loads(path.read_text())
    meta["state"].pop("train_time_s")
    return torch.load(path.with_suffix(".pt"), weights_only=True), {k: meta.get(k) for k in ("state", "rollout")}


# (id, vector env factory, envs, episode cap, steps per rollout, updates, resumed after this many updates)
CASES: list[tuple[str, Callable, int, int, int, int, int]] = [
    ("one-env-mid-episode", _sync, 1, 23, 32, 3, 1),
    ("two-envs-late-split", _sync, 2, 23, 32, 3, 2),
    ("episodes-begun-by-the-seeded-reset", _sync, 2, 400, 8, 2, 1),
    ("checkpoint-before-any-rollout", _sync, 2, 23, 16, 2, 0),
    ("async-vector-env", _async, 2, 23, 16, 2, 1),
    ("worker-processes", _processes, 3, 23, 16, 2, 1),
]


@pytest.mark.parametrize(("name", "make", "n_envs", "max_steps", "n_steps", "updates", "split"), CASES,
                         ids=[c[0] for c in CASES])
def test_a_resumed_run_is_bit_identical_to_an_uninterrupted_one(tmp_path: Path, name: str, make: Callable,
                                                                n_envs: int, max_steps: int, n_steps: int,
                                                                updates: int, split: int) -> None:
    torch.set_num_threads(1)
    config = PASTAConfig(n_steps=n_steps, n_epochs=2, batch_size=16, hidden_sizes=(16, 16), critic_head_hidden=8,
                         pcgrad=True)
    per_update = n_steps * n_envs

    def agent() -> PASTA:
        return PASTA(12, 5, [0.05], [1.0], config, seed=5)

    whole, venv = agent(), make(n_envs, max_steps)
    whole.learn(venv, updates * per_update)
    venv.close()
    expected = whole.save(tmp_path / "uninterrupted")

    first, venv = agent(), make(n_envs, max_steps)
    first.learn(venv, split * per_update)
    venv.close()
    stopped = first.save(tmp_path / "stopped")

    resumed, venv = PASTA.load(stopped), make(n_envs, max_steps)
    resumed.learn(venv, (updates - split) * per_update)
    venv.close()
    assert_identical(_state(resumed.save(tmp_path / "resumed")), _state(expected))


def test_other_envs_are_refused_with_a_warning_and_training_goes_on(tmp_path: Path,
                                                                     caplog: pytest.LogCaptureFixture) -> None:
    config = PASTAConfig(n_steps=16, n_epochs=1, hidden_sizes=(16,), critic_head_hidden=0)
    agent, venv = PASTA(12, 5, [0.05], [1.0], config, seed=5), _sync(2, 23)
    agent.learn(venv, 32)
    venv.close()
    path = agent.save(tmp_path / "two_envs")
    resumed, venv = PASTA.load(path), _sync(3, 23)
    with caplog.at_level(logging.WARNING, logger="sofar_agents.pasta.rollout"):
        resumed.learn(venv, 48)
    venv.close()
    assert "2 envs, the vector env has 3" in caplog.text and "not bit-identical" in caplog.text
    assert resumed.num_timesteps == 80


def test_the_training_script_resumes_bit_identically(tmp_path: Path) -> None:
    """train/pasta.py on the SOfAR env (3.7 s episodes, so that the checkpoint falls inside episodes begun by
    an automatic reset) or, without it, the synthetic stand-in."""
    import sofar_env  # noqa: F401  (registers the SOfAR ids)

    real = "SOfAR-LagunaSeca-v0" in gym.registry
    env = ["--env-id", "SOfAR-LagunaSeca-v0", "--env-kwargs", json.dumps({"race": {"duration": 3.7}})] if real \
        else ["--env-id", SYNTHETIC]
    run = [*env, "--n-envs", "1", "--seed", "3", "--no-progress", "--save-every", "0"]
    new = ["--n-steps", "64", "--n-epochs", "2", "--hidden-sizes", "16", "16", "--mu-decay-steps", "192"]

    def train(*args: str) -> None:
        proc = subprocess.run([sys.executable, "train/pasta.py", *run, *args], cwd=ROOT, capture_output=True,
                              text=True, timeout=600, env={**os.environ, "PYTHONPATH": os.pathsep.join(
                                  p for p in (str(HERE), os.environ.get("PYTHONPATH")) if p)})
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert "not bit-identical" not in proc.stderr, proc.stderr[-3000:]

    train(*new, "--total-steps", "192", "--out", str(tmp_path / "whole"))
    train(*new, "--total-steps", "128", "--out", str(tmp_path / "part"))
    train("--total-steps", "192", "--resume", str(tmp_path / "part" / "pasta_final.json"))
    assert_identical(_state(tmp_path / "part" / "pasta_final.json"), _state(tmp_path / "whole" / "pasta_final.json"))
